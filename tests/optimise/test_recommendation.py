"""The recommended design: its computation on synthetic FEM results and its rendering."""

from dataclasses import dataclass, replace

import numpy as np
import pytest

from workflow.damping.laws import ConstantQ
from workflow.models import analytical
from workflow.models.fem import ModeResult
from workflow.models.fem.accuracy import ErrorEstimate
from workflow.models.plate import ORIGINAL_PLATE
from workflow.optimise.problem import DesignProblem
from workflow.pipeline.recommendation import (
    Recommendation,
    beam_recommendation,
    fem_recommendation,
    nearest_transverse_mode,
)
from workflow.pipeline.report import recommendation_section
from workflow.units import MM, UM

TARGET = 1.15 * UM
PROBLEM = DesignProblem(ceramic_thickness=1 * MM)
DRAWS = ConstantQ(q0=np.array([50.0, 54.0, 58.0]))
"""Three posterior draws of a constant Q: the quantiles are known in closed form."""


@dataclass(frozen=True)
class LinearFemResult:
    """A FEM result whose best mode deflects ``per_q`` times Q at ``voltage`` [m]."""

    modes: tuple
    best_index: int
    per_q: float
    voltage: float = PROBLEM.voltage
    error: object = None

    @property
    def best(self):
        return self.modes[self.best_index]

    @property
    def frequency(self):
        return self.best.frequency

    def deflection_at_q(self, q):
        return self.per_q * np.asarray(q)


def needing(voltage: float, modes=None, best_index: int = 0, error: float | None = 1e-5) -> LinearFemResult:
    """A synthetic result that needs ``voltage`` for the target at Q = 54, its frequency ``error`` estimated
    (None: a fixed mesh)."""
    modes = modes or (ModeResult(25_010.0, 1e-6, 0.05),)
    result = LinearFemResult(modes, best_index, per_q=TARGET * PROBLEM.voltage / voltage / 54.0)
    return result if error is None else _with_error(result, error)


def test_required_voltage_and_deflection_come_from_the_draws():
    design = fem_recommendation(needing(12.0), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)
    assert design.required_voltage[1] == pytest.approx(12.0)
    assert design.required_voltage[0] < 12.0 < design.required_voltage[2]  # higher Q needs less voltage
    assert design.deflection[1] == pytest.approx(TARGET * 15.0 / 12.0)
    assert design.frequency_margin == pytest.approx(10.0)


def test_a_design_needing_18_v_is_flagged_and_one_at_12_v_is_not():
    low, high = (fem_recommendation(needing(v), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET) for v in (12.0, 18.0))
    assert low.meets_goal and not high.meets_goal
    text = recommendation_section(Recommendation({0.5 * MM: low, 2 * MM: high}, None, "constant", 3))
    assert text.startswith("## Recommended design")
    assert "Met with h_p = 0.5 mm." in text
    assert "**Not met with h_p = 2 mm: it needs 18.0 V for 1.15 µm" in text
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    assert rows["0.5"].rstrip(" |").endswith("yes")
    assert "**NO**: it needs 18.0 V" in rows["2"]


def test_a_design_below_the_frequency_limit_misses_the_goal_one_on_it_does_not():
    below, on = (
        fem_recommendation(needing(12.0, (ModeResult(f, 1e-6, 0.05),)), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)
        for f in (24_990.0, 25_000.0 * (1 - 1e-7))  # the optimiser's constraint slack
    )
    assert below.reaches_target and not below.meets_goal and on.meets_goal
    text = recommendation_section(Recommendation({1 * MM: below, 2 * MM: on}, None, "constant", 3))
    assert "10 Hz below 25 kHz" in text and "| +0 Hz (within the mesh error) |" in text


def test_the_nearest_transverse_mode_is_reported_with_its_distance():
    modes = (
        ModeResult(24_500.0, 0.1e-6, 0.9),  # transverse, 600 Hz below
        ModeResult(25_100.0, 1.0e-6, 0.05),  # the working mode
        ModeResult(25_200.0, 0.5e-6, 0.4),  # transverse, 100 Hz above: the nearest
        ModeResult(25_150.0, 0.2e-6, 0.1),  # nearer but longitudinal
    )
    design = fem_recommendation(needing(12.0, modes, best_index=1), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)
    assert design.nearest_transverse is modes[2]
    assert design.transverse_distance == pytest.approx(100.0)
    assert not design.working_mode_mixed
    text = recommendation_section(Recommendation({1 * MM: design}, None, "constant", 3))
    assert "+100 Hz (25.200 kHz, indicator 0.40)" in text


def test_a_mixed_working_mode_is_said_so_and_a_lonely_mode_has_no_partner():
    mixed = (ModeResult(25_100.0, 1.0e-6, 0.3),)
    design = fem_recommendation(needing(12.0, mixed), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)
    assert design.working_mode_mixed and nearest_transverse_mode(mixed, mixed[0]) is None
    text = recommendation_section(Recommendation({1 * MM: design}, None, "constant", 3))
    assert "0.30 (mixed)" in text and "none among the 1 computed modes" in text
    meaning = text.split("What these intervals contain:")[1]  # issue 29: what the table's intervals hold and not
    assert "law's shape" in meaning and "do not contain" in meaning and "manufacturing tolerances" in meaning


def _with_error(result, relative: float):
    estimate = ErrorEstimate(relative, 0.01, 8, 6, result.frequency, 1e-6, 1.0, 0.002)
    return replace(result, error=estimate)


def test_a_margin_within_the_estimated_error_is_flagged_only_for_the_fem():
    fem = fem_recommendation(needing(12.0, error=0.0012), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)  # +10 Hz
    beam = beam_recommendation(ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)
    text = recommendation_section(Recommendation({1 * MM: fem, 2 * MM: beam}, None, "constant", 3))
    assert "+10 Hz (within the mesh error)" in text and "25.010 (±0.12 %)" in text
    assert "the estimates, mesh value over converged value − 1, are: h_p 1 mm +0.12 %" in text
    assert "the margins of h_p = 1 mm are within their error" in text
    assert "not computed (beam model)" in text and "| beam model |" in text
    # the deflection goal is met, the frequency is not promised
    assert "deflection yes; 25 kHz **not assured** (mesh error)" in text
    assert "**Deflection met with h_p = 1 mm, but 25 kHz is not assured**" in text and "Met with" not in text


def test_a_margin_beyond_the_estimated_error_is_met_and_a_fixed_mesh_is_not_trusted():
    assured = fem_recommendation(needing(12.0, error=0.0002), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)
    text = recommendation_section(Recommendation({1 * MM: assured}, None, "constant", 3))
    assert "every FEM margin above exceeds its error" in text and "Met with h_p = 1 mm" in text
    fixed = fem_recommendation(needing(12.0, error=None), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET)
    text = recommendation_section(Recommendation({1 * MM: fixed}, None, "constant", 3))
    assert "ran on a fixed mesh" in text and "not assured" in text


def test_the_beam_recommendation_of_the_original_plate_needs_more_than_15_v_at_q_54():
    # The beam model is linear in V at constant Q: 1.15 um needs 15 V * 1.15 um / w(15 V).
    design = beam_recommendation(ORIGINAL_PLATE, PROBLEM, ConstantQ(q0=np.array([54.0])), TARGET)
    deflection = float(analytical.dynamic_deflection(ORIGINAL_PLATE, 15.0, 54.0))
    assert design.deflection[1] == pytest.approx(deflection)
    assert design.required_voltage[1] == pytest.approx(15.0 * TARGET / deflection)
    assert not design.meets_goal


def test_the_beam_and_fem_ratio_sentence_lists_the_ratios():
    designs = {
        hp * MM: fem_recommendation(needing(12.0), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET, ratio)
        for hp, ratio in ((0.5, 1.746), (2.0, 1.447))
    }
    text = recommendation_section(Recommendation(designs, None, "constant", 3))
    assert "the FEM deflects ×1.75 / ×1.45 as much as the beam model (h_p = 0.5 / 2 mm)" in text


def test_a_design_that_meets_the_goal_only_with_the_fem_is_flagged():
    designs = {
        hp * MM: fem_recommendation(needing(12.0), ORIGINAL_PLATE, PROBLEM, DRAWS, TARGET, beam_required_voltage=beam)
        for hp, beam in ((1.0, 9.4), (2.0, 18.7))
    }
    text = recommendation_section(Recommendation(designs, None, "constant", 3))
    assert "**h_p = 2 mm reaches the deflection only with the FEM: the beam model needs 18.7 V at its own optimum.**" in text
    assert "h_p = 1 mm meets it only" not in text
