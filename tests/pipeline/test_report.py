"""Report sections read the steps' typed results (issue 28, item 2)."""

from types import SimpleNamespace

import numpy as np
import pytest

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


def test_the_electrical_load_is_the_admittance_at_the_working_amplitude():
    """Y = G + i omega C at the resonance: current |Y| V, power G V^2 / 2, apparent power |Y| V^2 / 2, and the peak
    current of a rise to the limit bounded by the blocked part at the limit plus the rest at the working voltage."""
    from workflow.damping.laws import QuadraticLoss
    from workflow.pipeline.design_rendering import electrical_load

    conductance, capacitance, frequency = 2e-3, 40e-9, 25e3
    omega = 2 * np.pi * frequency
    result = SimpleNamespace(frequency=frequency, clamped_capacitance=capacitance, charge_residual=0.0,
                             admittance=lambda f, q: conductance * q / 50 + 1j * 2 * np.pi * f * capacitance)
    law = QuadraticLoss(q0=150.0, alpha=0.25)
    load = electrical_load(result, law, deflection=1.15e-6, voltage=10.0, voltage_limit=30.0)
    q = float(law.quality_factor(omega * 1.15e-6))
    y = complex(conductance * q / 50, omega * capacitance)
    assert load.q == pytest.approx(q, rel=1e-12) and load.admittance == pytest.approx(abs(y), rel=1e-12)
    assert load.current == pytest.approx(abs(y) * 10.0, rel=1e-12)
    assert load.power == pytest.approx(y.real * 100 / 2, rel=1e-12)
    assert load.apparent_power == pytest.approx(abs(y) * 50, rel=1e-12)
    assert load.peak_current == pytest.approx(omega * capacitance * 30.0 + conductance * q / 50 * 10.0, rel=1e-12)
