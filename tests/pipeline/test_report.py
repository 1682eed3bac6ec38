"""Report sections read the steps' typed results (issue 28, item 2)."""

from types import SimpleNamespace

import numpy as np

from workflow.damping.posterior import DampingPosterior
from workflow.optimise.damped import design_with_damping
from workflow.optimise.problem import DesignProblem
from workflow.pipeline.report import _damped_design


def test_the_reports_design_with_damping_reads_the_design_in_display_units():
    rng = np.random.default_rng(0)
    posterior = DampingPosterior("quadratic", {"q0": rng.normal(150, 3, 40), "alpha": rng.normal(0.25, 0.005, 40)})
    design = design_with_damping(posterior, [DesignProblem(ceramic_thickness=1e-3)], draws=4, scheduler="synchronous")
    (optimum,) = design.optima.values()
    assert 15e-3 <= optimum.damped.plate.wavelength <= 40e-3 and optimum.damped.frequency >= 25e3 * (1 - 1e-6)
    p05, _, p95 = optimum.interval("required_voltage")
    assert p05 <= p95
    context = SimpleNamespace(figures_of=lambda step: [])
    section = _damped_design(context, (design, {}))
    row = next(line for line in section.splitlines() if line.startswith("| 1 |"))
    assert f"| {optimum.damped.frequency / 1e3:.2f} |" in row and f"{optimum.constant_q.deflection * 1e6:.3f}" in row
    assert f"over {len(design.original_deflection)} posterior draws" in section
