"""Accuracy control of the FEM: meshes that follow the geometry and error estimates that hold."""

import numpy as np
import pytest

from workflow.errors import TactileError
from workflow.models.fem import evaluate_fem
from workflow.models.fem.accuracy import (
    LEVELS,
    FemAccuracy,
    estimate_error,
    evaluate_to_accuracy,
    mesh_for_level,
    next_level,
    richardson_error,
)
from workflow.models.plate import ORIGINAL_PLATE, Plate

SMALL_THIN = Plate(16e-3, 0.5e-3, 0.5e-3, 30e-3, n_ceramics=1)
"""A thin one-ceramic plate: cheap enough to converge in the default suite, thin like the designs."""


def test_richardson_error_is_exact_for_a_pure_power_law():
    converged, constant, rate = 31e3, 4e4, 2.0
    value = {n: converged + constant * (1 / n) ** rate for n in (6, 8)}
    assert richardson_error(value[8], value[6], 8 / 6, rate) == pytest.approx(value[8] - converged, rel=1e-12)


def test_the_mesh_follows_the_geometry():
    thick, thin = mesh_for_level(ORIGINAL_PLATE, 8), mesh_for_level(Plate(15.66e-3, 0.5e-3, 0.5e-3, 49e-3), 8)
    # the same elements per ceramic, but the short wavelength needs more elements across the same width
    assert thick.elements_per_ceramic == thin.elements_per_ceramic == 8
    assert thin.elements_across_half_width > thick.elements_across_half_width
    wide = mesh_for_level(ORIGINAL_PLATE.with_(width=98e-3), 8)
    assert wide.elements_across_half_width >= 2 * thick.elements_across_half_width - 1
    # finer levels refine every direction
    coarse, fine = mesh_for_level(ORIGINAL_PLATE, 6), mesh_for_level(ORIGINAL_PLATE, 12)
    assert fine.elements_per_layer > coarse.elements_per_layer
    assert fine.elements_per_gap > coarse.elements_per_gap
    assert fine.elements_across_half_width > coarse.elements_across_half_width


def test_next_level_is_finer_and_capped():
    assert next_level(8, 0.0021, 0.002, 12) == 10
    assert next_level(8, 0.02, 0.002, 12) == 12
    assert next_level(6, 0.0025, 0.002, 16) == 8
    assert all(level in LEVELS for level in (next_level(4, e, 1e-3, 16) for e in (1e-3, 1e-2, 1e-1)))


def test_accuracy_targets_outside_the_range_are_refused():
    for target in (0.0, -1e-3, 0.5, float("nan")):
        with pytest.raises(TactileError, match="accuracy"):
            FemAccuracy(target=target)
    with pytest.raises(TactileError, match="max_level"):
        FemAccuracy(max_level=7)


@pytest.fixture(scope="module")
def small_thin_ladder():
    return {level: evaluate_fem(SMALL_THIN, 54.0, 15.0, mesh_for_level(SMALL_THIN, level)) for level in (4, 6, 8, 10, 12)}


def test_frequency_converges_from_above_with_refinement(small_thin_ladder):
    frequencies = [small_thin_ladder[level].frequency for level in (6, 8, 10, 12)]
    assert np.all(np.diff(frequencies) < 0)
    steps = -np.diff(frequencies)
    assert np.all(steps[1:] < steps[:-1] * 1.5)  # shrinking (per level ratio, not per element size)


def test_error_estimate_is_conservative_against_the_converged_frequency(small_thin_ladder):
    """Validation: the estimate from levels 6/8 against the Richardson limit of levels 10/12 (the converged value)."""
    finest = estimate_error(small_thin_ladder[12], small_thin_ladder[10], 12, 10)
    converged = small_thin_ladder[12].frequency / (1 + finest.frequency)
    for coarse, fine in ((6, 8), (8, 10)):
        estimate = estimate_error(small_thin_ladder[fine], small_thin_ladder[coarse], fine, coarse)
        true = small_thin_ladder[fine].frequency / converged - 1
        assert true > 0
        assert 0.8 * true <= estimate.frequency <= 3.0 * true, (coarse, fine, estimate.frequency, true)
        assert estimate.mode_match > 0.99


def test_evaluate_to_accuracy_refines_until_the_estimate_meets_the_target(small_thin_ladder):
    asked = []

    def evaluate_mesh(mesh):
        asked.append(mesh.elements_per_ceramic)
        return small_thin_ladder[mesh.elements_per_ceramic]

    loose = evaluate_to_accuracy(SMALL_THIN, FemAccuracy(target=0.01), evaluate_mesh)
    assert asked == [4, 6] and loose.error.level == 6 and loose.error.met
    asked.clear()
    tight = evaluate_to_accuracy(SMALL_THIN, FemAccuracy(target=0.004, max_level=12), evaluate_mesh)
    assert asked[:2] == [6, 8] and tight.error.level > 8 and tight.error.met
    assert abs(tight.error.frequency) <= 0.004
    assert tight.frequency == small_thin_ladder[tight.error.level].frequency


def test_an_unmet_accuracy_says_so(small_thin_ladder):
    result = evaluate_to_accuracy(
        SMALL_THIN, FemAccuracy(target=1e-4, max_level=10), lambda mesh: small_thin_ladder[mesh.elements_per_ceramic]
    )
    assert result.error.level == 10 and not result.error.met


def _optimum_and_refined(tmp_path, target: float, refine_by: int):
    from workflow.execution.cache import EvaluationCache
    from workflow.optimise.fem_model import FemModel
    from workflow.optimise.fem_optimum import optimise_fem
    from workflow.optimise.problem import DesignProblem

    problem = DesignProblem(ceramic_thickness=1e-3, width=30e-3)
    model = FemModel(settings=FemAccuracy(target=target), cache=EvaluationCache(tmp_path), scheduler="synchronous")
    found = optimise_fem(problem, model, "space-mapping")
    plate = found.optimum.plate
    refined = evaluate_fem(plate, 54.0, 15.0, mesh_for_level(plate, LEVELS[LEVELS.index(found.error.level) + refine_by]))
    return problem, found, refined


def test_the_optimum_of_a_coarse_search_clears_the_limit_on_a_finer_mesh(tmp_path):
    """Optima that hold, cheaply: the search on level 4 corrected by the accurate levels (6 against 4) at 3 %."""
    from workflow.optimise import fem_optimum

    assert fem_optimum.search_level(FemAccuracy(target=0.03)) == 4
    assert fem_optimum.search_level(FemAccuracy(target=0.002)) == 6
    problem, found, refined = _optimum_and_refined(tmp_path, 0.03, 2)
    assert found.verified and found.error.met and found.verification_evaluations >= 2
    margin = fem_optimum.margin_frequency(problem.min_frequency, found.error.frequency)
    assert margin * (1 - 1e-4) <= found.optimum.frequency <= margin * (1 + 5e-4)
    assert refined.frequency >= problem.min_frequency


@pytest.mark.slow
def test_the_fem_optimum_clears_the_limit_on_a_refined_mesh(tmp_path):
    """Optima that hold: the space-mapping optimum at 1 % accuracy, re-evaluated two levels finer, is above 25 kHz."""
    problem, found, refined = _optimum_and_refined(tmp_path, 0.01, 2)
    assert found.verified and found.error.met
    assert refined.frequency >= problem.min_frequency
    assert found.optimum.frequency == pytest.approx(refined.frequency, rel=0.01)
