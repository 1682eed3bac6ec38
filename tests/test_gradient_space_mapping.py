"""Space mapping with fine gradients: synthetic fine models (finite-difference gradients) and the FEM."""

import numpy as np
import pytest
from test_space_mapping import (
    COARSE,
    DIP_CENTRE,
    DIP_WIDTH,
    best_along_the_fine_curve,
    design,
    mixing_fine,
    synthetic_fine,
)

from workflow.models.fem import FemSettings
from workflow.optimise.fem_model import FemModel
from workflow.optimise.fem_optimum import optimise_fem
from workflow.optimise.gradient_space_mapping import (
    FIRST_ORDER_GAIN,
    MIXED_EXCLUSION_MM,
    TRUST_MM,
    GradientStep,
    _MappingData,
    _near_mixed_points,
    _surrogate,
    finite_difference_gradients,
    gradient_space_mapping_optimum,
)
from workflow.optimise.problem import DesignProblem, maximise_deflection
from workflow.optimise.space_mapping import FREQUENCY_TOLERANCE, coarse_wavelength
from workflow.units import MM


@pytest.mark.parametrize("ceramic_thickness", [0.5e-3, 1e-3, 2e-3])
def test_recovers_the_synthetic_fine_optimum(ceramic_thickness):
    problem = DesignProblem(ceramic_thickness)
    direct = maximise_deflection(synthetic_fine, problem)
    result = gradient_space_mapping_optimum(finite_difference_gradients(synthetic_fine), COARSE, problem)
    assert result.converged
    assert result.fine_evaluations <= 4
    assert np.max(np.abs(design(result.coarse_optimum) - design(direct))) > 0.01 * MM  # it had somewhere to go
    assert result.optimum.frequency >= problem.min_frequency * (1 - FREQUENCY_TOLERANCE)
    # the search stops when the surrogate promises < 1e-4 more; on these flat peaks 1e-4 of
    # deflection spans about 0.1 mm of lambda (h_p = 2 mm: 0.11 mm, 1.0e-4)
    assert result.optimum.deflection == pytest.approx(direct.deflection, rel=1.5e-4)
    assert np.max(np.abs(design(result.optimum) - design(direct))) < 0.15 * MM
    assert len(result.trajectory) == result.fine_evaluations


def test_identical_models_stay_at_the_coarse_optimum():
    problem = DesignProblem(1e-3)
    result = gradient_space_mapping_optimum(finite_difference_gradients(COARSE), COARSE, problem)
    assert result.converged
    assert result.fine_evaluations == 1
    assert np.max(np.abs(design(result.optimum) - design(result.coarse_optimum))) == 0


def test_leaves_a_transverse_dip_for_the_best_clean_point():
    problem = DesignProblem(2e-3)
    result = gradient_space_mapping_optimum(finite_difference_gradients(mixing_fine), COARSE, problem)
    assert result.trajectory[0].mixed  # the beam optimum sits in the dip
    thickness = np.linspace(problem.min_resonator_thickness, problem.max_resonator_thickness, 2501)
    target, deflection = best_along_the_fine_curve(problem, mixing_fine, thickness)
    assert abs(target[1] - DIP_CENTRE) > 2 * DIP_WIDTH  # the best clean point is out of the dip
    assert result.converged
    assert not result.trajectory[-1].mixed
    assert np.max(np.abs(design(result.optimum) - target)) < 0.1 * MM
    assert result.optimum.deflection == pytest.approx(deflection, rel=2e-4)
    assert result.fine_evaluations <= 10  # the dip's tail shapes the peak: a hard case


def bent_fine(plate):
    """Like the FEM at h_p = 0.5 mm: the deflection ratio rises at the beam optimum (the h_i = 0.5 mm
    bound) at 0.8 /mm, peaks 0.05 mm on, and a transverse mode at h_i = 0.75 mm takes 40 % away."""
    deflection, frequency = synthetic_fine(plate)
    thickness = np.asarray(plate.resonator_thickness) / MM
    offset = thickness - 0.5
    mixing = 0.4 * np.exp(-(((thickness - 0.75) / 0.08) ** 2))
    return deflection * np.exp(0.8 * offset - 8 * offset**2) * (1 - mixing), frequency * (1 - 0.02 * mixing), mixing


def test_a_first_order_mapping_is_not_extrapolated_into_a_transverse_mode(monkeypatch):
    problem = DesignProblem(0.5e-3)
    thickness = np.linspace(problem.min_resonator_thickness, problem.max_resonator_thickness, 2501)
    target, deflection = best_along_the_fine_curve(problem, bent_fine, thickness)
    fine = finite_difference_gradients(bent_fine)
    result = gradient_space_mapping_optimum(fine, COARSE, problem)
    first_step = result.trajectory[1].thickness_mm - result.trajectory[0].thickness_mm
    assert 0 < first_step < TRUST_MM / 2  # the promise, not the trust interval, ended the first step
    assert result.converged
    assert result.fine_evaluations <= 3
    assert np.max(np.abs(design(result.optimum) - target)) < 0.05 * MM
    assert result.optimum.deflection == pytest.approx(deflection, rel=1e-4)
    # extrapolated over the whole trust interval, the slope leads into the mode and back
    monkeypatch.setattr("workflow.optimise.gradient_space_mapping.FIRST_ORDER_GAIN", np.inf)
    unbounded = gradient_space_mapping_optimum(fine, COARSE, problem)
    assert unbounded.trajectory[1].thickness_mm - unbounded.trajectory[0].thickness_mm == pytest.approx(TRUST_MM)
    assert unbounded.fine_evaluations > result.fine_evaluations
    assert FIRST_ORDER_GAIN < 0.1


def evaluated_step(fine, problem, wavelength_mm, thickness_mm) -> GradientStep:
    """The fine model with gradients evaluated at (lambda, h_i) [mm]."""
    design_m = np.array([wavelength_mm, thickness_mm]) * MM
    return GradientStep(design_m, *fine(problem.plate(*design_m)))


def test_the_mapping_fitted_around_a_fine_point_passes_through_it():
    """The wavelength of a new point comes from ln m fitted around its own h_i, where a fine point weighs most."""
    problem = DesignProblem(1e-3)

    def wavy_fine(plate):  # ln m is not a quadratic in h_i
        deflection, frequency = synthetic_fine(plate)
        return deflection, frequency * (1 + 0.003 * np.sin(np.asarray(plate.resonator_thickness) / (0.05 * MM)))

    fine = finite_difference_gradients(wavy_fine)
    steps = [evaluated_step(fine, problem, 22.0, h) for h in (0.8, 1.0, 1.2)]
    grid = np.linspace(0.5, 3.0, 2501)
    coarse_curve = np.log(coarse_wavelength(COARSE, problem, grid * MM, problem.min_frequency))
    mapping = _MappingData.of(steps, steps[0], COARSE, problem, grid, coarse_curve, np.gradient(coarse_curve, grid))
    for thickness, log_ratio in zip(mapping.thickness_mm, mapping.log_ratio):
        assert mapping.fit(thickness)[0][0] == pytest.approx(log_ratio, abs=2e-5)
    far = mapping.fit(0.8)[0]  # centred on the first point, the quadratic misses the third
    assert abs(np.polynomial.polynomial.polyval(0.4, far) - mapping.log_ratio[2]) > 1e-4


def test_a_steep_mapping_does_not_leave_the_wavelength_bounds():
    """A surrogate curve far below the shortest wavelength (FEM, b = 60 mm, h_p = 1 mm, once stopped
    the search with a geometry error) is clipped for the coarse model and never proposed."""
    problem = DesignProblem(1e-3)
    grid = np.linspace(0.5, 3.0, 2501)
    coarse_curve = np.log(coarse_wavelength(COARSE, problem, grid * MM, problem.min_frequency))
    step = evaluated_step(finite_difference_gradients(synthetic_fine), problem, 20.5, 0.7)
    steep = _MappingData(np.array([0.7]), np.zeros(1), np.array([3.0]), np.zeros(1), np.zeros(1), np.zeros(1))
    curve, predicted = _surrogate(steep, step, COARSE, problem, grid, coarse_curve)
    assert np.exp(curve.min()) < problem.wavelength_range[0] / 100  # ln m = 3 (u - 0.7 mm) reaches 6.9
    assert np.all(np.isfinite(predicted))


def test_no_proposals_next_to_a_mixed_point_but_up_to_halfway_to_a_clean_one():
    problem = DesignProblem(1e-3)
    fine = finite_difference_gradients(mixing_fine)

    def step(thickness_mm):
        return evaluated_step(fine, problem, 22.0, thickness_mm)

    edge = DIP_CENTRE / MM + 0.15  # the dip's indicator: 0.15 here, 0.08 at 0.04 mm beyond
    mixed, clean = step(edge), step(edge + 0.04)
    assert mixed.mixed and not clean.mixed
    grid = np.linspace(0.5, 3.0, 2501)
    alone = grid[_near_mixed_points(grid, [mixed])]
    assert alone.min() == pytest.approx(edge - MIXED_EXCLUSION_MM, abs=2e-3)
    assert alone.max() == pytest.approx(edge + MIXED_EXCLUSION_MM, abs=2e-3)
    beside = grid[_near_mixed_points(grid, [mixed, clean])]
    assert beside.min() == pytest.approx(edge - 0.02, abs=2e-3)
    assert beside.max() == pytest.approx(edge + 0.02, abs=2e-3)


def test_finite_difference_gradients_of_the_beam():
    problem = DesignProblem(1e-3)
    plate = problem.plate(22 * MM, 1.2 * MM)
    deflection, frequency, indicator, deflection_gradient, frequency_gradient = finite_difference_gradients(COARSE)(
        plate
    )
    assert indicator == 0
    # the beam: f ~ 1/lambda^2, w ~ lambda^2 at fixed h_i
    assert frequency_gradient[0] == pytest.approx(-2 * frequency / (22 * MM), rel=1e-6)
    assert deflection_gradient[0] == pytest.approx(2 * deflection / (22 * MM), rel=1e-6)


def test_fem_responses_with_gradients_match_the_plain_evaluation():
    settings = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=2)
    model = FemModel(settings=settings, scheduler="synchronous")
    plate = DesignProblem(1e-3).plate(24 * MM, 2 * MM)
    with_gradients = model.responses_with_gradients(plate)
    plain = model.responses(plate)
    for a, b in zip(with_gradients[:3], plain):
        assert float(a) == pytest.approx(float(b), rel=1e-9, abs=1e-12)
    deflection_gradient, frequency_gradient = model.gradients(plate)
    np.testing.assert_allclose(with_gradients[3], deflection_gradient)
    np.testing.assert_allclose(with_gradients[4], frequency_gradient)
    assert frequency_gradient[0] < 0  # a longer wavelength lowers the frequency


@pytest.mark.slow
@pytest.mark.parametrize(
    ("ceramic_thickness", "width_mm"), [(0.5e-3, 49), (1e-3, 49), (2e-3, 49), (2e-3, 40), (2e-3, 55), (2e-3, 70)]
)
def test_space_mapping_on_the_fem_matches_the_direct_run(tmp_path, ceramic_thickness, width_mm):
    """The paper's figure (docs/fem.md): at most 4 FEM evaluations, within 0.1 mm of the direct run, on
    the original plate (b = 49 mm) and at h_p = 2 mm for other widths, where transverse modes move the most with the
    width (at 55 mm the responses-only search once never reached f_min)."""
    from workflow.execution.cache import EvaluationCache

    problem = DesignProblem(ceramic_thickness, width=width_mm * MM)
    model = FemModel(settings=FemSettings(), cache=EvaluationCache(tmp_path), scheduler="synchronous")
    direct = optimise_fem(problem, model, "nlopt")
    mapped = optimise_fem(problem, model, "space-mapping")
    assert mapped.optimum.status == "converged"
    assert mapped.fine_evaluations <= 4
    assert np.max(np.abs(design(mapped.optimum) - design(direct.optimum))) < 0.1 * MM
    assert mapped.optimum.deflection == pytest.approx(direct.optimum.deflection, rel=1e-3)
