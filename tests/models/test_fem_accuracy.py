"""Accuracy control of the FEM: meshes that follow the geometry and error estimates that hold."""

from dataclasses import dataclass

import numpy as np
import pytest

from workflow.errors import TactileError
from workflow.models.fem import evaluate_fem
from workflow.models.fem.accuracy import (
    LEVELS,
    RICHARDSON_RATE,
    ErrorEstimate,
    FemAccuracy,
    estimate_error,
    evaluate_to_accuracy,
    extrapolated_limit,
    mesh_for_level,
    next_level,
    richardson_error,
)
from workflow.models.plate import ORIGINAL_PLATE, Plate

SMALL_THIN = Plate(16e-3, 0.5e-3, 0.5e-3, 30e-3, n_ceramics=1)
"""A thin one-ceramic plate: cheap enough to converge in the default suite, thin like the designs."""


def test_richardson_error_and_the_extrapolated_limit_are_exact_for_a_pure_power_law():
    converged, constant, rate = 31e3, 4e4, 2.0
    value = {k: converged + constant * k**-rate for k in (3, 4, 5)}
    assert richardson_error(value[4], value[3], 4 / 3, rate) == pytest.approx(value[4] - converged, rel=1e-12)
    limit, fitted = extrapolated_limit([value[k] for k in (3, 4, 5)], (3, 4, 5))
    assert limit == pytest.approx(converged, rel=1e-12) and fitted == pytest.approx(rate, rel=1e-9)
    with pytest.raises(TactileError, match="monotonically"):
        extrapolated_limit([1.0, 2.0, 1.5], (3, 4, 5))


def test_the_mesh_follows_the_geometry():
    thick, thin = mesh_for_level(ORIGINAL_PLATE, 4), mesh_for_level(Plate(15.66e-3, 0.5e-3, 0.5e-3, 49e-3), 4)
    # the same elements per ceramic, but the short wavelength needs more elements across the same width
    assert thick.elements_per_ceramic == thin.elements_per_ceramic
    assert thin.elements_across_half_width > thick.elements_across_half_width
    wide = mesh_for_level(ORIGINAL_PLATE.with_(width=98e-3), 4)
    assert wide.elements_across_half_width >= 2 * thick.elements_across_half_width - 1
    # higher levels raise the degree in every direction on the same cells
    low, high = mesh_for_level(ORIGINAL_PLATE, 3), mesh_for_level(ORIGINAL_PLATE, 5)
    assert (low.element, high.element) == ("spectral-3-3-3", "spectral-5-5-5")
    counts = ("elements_per_ceramic", "elements_per_gap", "elements_per_layer", "elements_across_half_width")
    assert all(getattr(low, name) == getattr(high, name) for name in counts)


def test_next_level_is_higher_and_capped():
    assert next_level(4, 0.0021, 0.002, 6) == 5
    assert next_level(4, 0.02, 0.002, 6) == 6
    assert next_level(3, 0.0025, 0.002, 5) == 4
    assert all(level in LEVELS for level in (next_level(3, e, 1e-3, 6) for e in (1e-3, 1e-2, 1e-1)))


def test_accuracy_targets_outside_the_range_are_refused():
    for target in (0.0, -1e-3, 0.5, float("nan")):
        with pytest.raises(TactileError, match="accuracy"):
            FemAccuracy(target=target)
    with pytest.raises(TactileError, match="max_level"):
        FemAccuracy(max_level=7)


def _ladder(levels):
    return {level: evaluate_fem(SMALL_THIN, 54.0, 15.0, mesh_for_level(SMALL_THIN, level)) for level in levels}


@pytest.fixture(scope="module")
def small_thin_ladder():
    return _ladder((2, 3, 4, 5))


def _check_estimates(ladder, estimated_levels, reference_levels):
    converged, rate = extrapolated_limit([ladder[k].frequency for k in reference_levels], reference_levels)
    assert rate >= RICHARDSON_RATE, "the estimate's assumed rate must not exceed the observed one"
    for level in estimated_levels:
        estimate = estimate_error(ladder[level], ladder[level - 1], level, level - 1)
        true = ladder[level].frequency / converged - 1
        assert true > 0
        assert 0.9 * true <= estimate.frequency <= 3.0 * true, (level, estimate.frequency, true)
        assert estimate.mode_match > 0.75  # the same mode (this short, wide plate's probe lines lie off its antinodes)


def test_frequency_converges_from_above_as_the_degree_rises(small_thin_ladder):
    frequencies = [small_thin_ladder[level].frequency for level in (2, 3, 4, 5)]
    assert np.all(np.diff(frequencies) < 0)
    steps = -np.diff(frequencies)
    assert np.all(steps[1:] < steps[:-1] * 0.6)


def test_error_estimate_is_conservative_against_the_converged_frequency(small_thin_ladder):
    """Validation: the estimate of level 4 (from 3) against the limit extrapolated from levels 3, 4, 5."""
    _check_estimates(small_thin_ladder, (4,), (3, 4, 5))


@pytest.mark.slow
def test_error_estimates_are_conservative_up_to_level_six(small_thin_ladder):
    """The estimates of levels 4 to 6 against the limit of levels 4, 5, 6 (degree 6: 18 000 dofs, seconds)."""
    ladder = {**small_thin_ladder, **_ladder((6,))}
    _check_estimates(ladder, (4, 5, 6), (4, 5, 6))


def test_evaluate_to_accuracy_refines_until_the_estimate_meets_the_target(small_thin_ladder):
    asked = []

    def evaluate_mesh(mesh, trial):
        level = int(mesh.element.split("-")[1])
        asked.append(level)
        return small_thin_ladder[level]

    loose = evaluate_to_accuracy(SMALL_THIN, FemAccuracy(target=0.02), evaluate_mesh)
    assert asked == [2, 3] and loose.error.level == 3 and loose.error.met
    asked.clear()
    tight = evaluate_to_accuracy(SMALL_THIN, FemAccuracy(target=0.002), evaluate_mesh)
    assert asked[:2] == [3, 4] and tight.error.level > 4 and tight.error.met
    assert abs(tight.error.frequency) <= 0.002
    assert tight.frequency == small_thin_ladder[tight.error.level].frequency


@dataclass(frozen=True)
class _Level:
    """What evaluate_to_accuracy reads of a level's result when the estimate is given."""

    solution: object = None
    error: object = None


def test_an_estimate_against_degree_2_steps_one_level_and_later_ones_jump(monkeypatch):
    """Degree 2 is not asymptotic: a miss of degree 3 against it goes to degree 4 (not to the degree its estimate
    predicts, 6 here), and a miss of degree 4 against 3 jumps as far as its estimate says (6)."""
    from workflow.models.fem import accuracy

    estimates = {(3, 2): 0.03, (4, 3): 0.004}
    monkeypatch.setattr(accuracy, "estimate_error", lambda fine, coarse, level, coarse_level, target: ErrorEstimate(
        estimates[level, coarse_level], 0.0, level, coarse_level, 0.0, 0.0, 1.0, target))
    asked = []

    def evaluate_mesh(mesh, trial):
        asked.append(int(mesh.element.split("-")[1]))
        return _Level()

    survey = evaluate_to_accuracy(SMALL_THIN, FemAccuracy(target=0.005, max_level=6), evaluate_mesh)
    assert next_level(3, 0.03, 0.005, 6) == 6 and asked == [2, 3, 4] and survey.error.level == 4
    asked.clear()
    estimates[4, 3], estimates[6, 4] = 0.02, 0.001
    evaluate_to_accuracy(SMALL_THIN, FemAccuracy(target=0.002, max_level=6), evaluate_mesh)
    assert asked == [3, 4, 6]


def test_an_unmet_accuracy_says_so(small_thin_ladder):
    result = evaluate_to_accuracy(
        SMALL_THIN, FemAccuracy(target=1e-4, max_level=5),
        lambda mesh, trial: small_thin_ladder[int(mesh.element.split("-")[1])]
    )
    assert result.error.level == 5 and not result.error.met


def test_a_level_starts_its_eigen_solve_from_the_level_below_and_finds_the_same_modes(small_thin_ladder):
    """The warm start (the lower level's modes interpolated) changes how ARPACK gets there, not where (the ladder's
    levels 3 and 4 are the cold solves)."""
    from workflow.models.fem.evaluate import discretise
    from workflow.models.fem.prolongation import node_interpolation

    low, high = mesh_for_level(SMALL_THIN, 3), mesh_for_level(SMALL_THIN, 4)
    coarse, cold = small_thin_ladder[3], small_thin_ladder[4]
    warm = evaluate_fem(SMALL_THIN, 54.0, 15.0, high, coarse.solution)
    np.testing.assert_allclose(warm.probe_model.eigenvalues, cold.probe_model.eigenvalues, rtol=1e-12)
    assert warm.deflection == pytest.approx(cold.deflection, rel=1e-9)
    # the interpolation is exact on the coarse space: a coarse-level polynomial is reproduced at the fine nodes
    coarse_mesh, fine_mesh = discretise(SMALL_THIN, 15.0, low)[0], discretise(SMALL_THIN, 15.0, high)[0]
    polynomial = lambda points: points[:, 0] ** 3 - 2e2 * points[:, 1] ** 2 * points[:, 2] + 7.0  # noqa: E731
    interpolated = node_interpolation(coarse_mesh, fine_mesh) @ polynomial(coarse_mesh.coordinates)
    np.testing.assert_allclose(interpolated, polynomial(fine_mesh.coordinates), rtol=1e-10, atol=1e-12)


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
    """Optima that hold, cheaply: the search on level 2 corrected by the accurate levels (3 against 2) at 3 %."""
    from workflow.optimise import fem_optimum

    assert fem_optimum.search_level(FemAccuracy(target=0.03)) == 2
    assert fem_optimum.search_level(FemAccuracy(target=0.002)) == 3
    problem, found, refined = _optimum_and_refined(tmp_path, 0.03, 1)
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
