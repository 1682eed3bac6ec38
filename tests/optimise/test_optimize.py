"""NLopt optimisation of the beam model (docs/model.md)."""

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from workflow.errors import InfeasibleError
from workflow.models import analytical, materials
from workflow.models.plate import Plate
from workflow.optimise.problem import (
    DesignProblem,
    analytical_model,
    maximise_deflection,
    optimise_analytical,
)


def _best_on_the_constraint(problem):
    """Independent solution: on f_r = f_min, lambda follows from h_i in closed form (f ~ 1/lambda^2)."""

    def wavelength_on_constraint(h_i):
        unit = Plate(1.0, h_i, problem.ceramic_thickness)  # f_r * lambda^2 does not depend on lambda
        return np.sqrt(analytical.resonance_frequency(unit) / problem.min_frequency)

    def negative_deflection(h_i):
        plate = Plate(wavelength_on_constraint(h_i), h_i, problem.ceramic_thickness)
        return -analytical.dynamic_deflection(plate, problem.voltage, materials.PLATE_Q)

    found = minimize_scalar(
        negative_deflection,
        bounds=(problem.min_resonator_thickness, problem.max_resonator_thickness),
        method="bounded",
        options={"xatol": 1e-12},
    )
    return wavelength_on_constraint(found.x), found.x, -found.fun


@pytest.mark.parametrize("ceramic_thickness", materials.CERAMIC_THICKNESSES)
def test_optimum_lies_on_the_frequency_constraint_and_matches_an_independent_solution(ceramic_thickness):
    problem = DesignProblem(ceramic_thickness)
    optimum = optimise_analytical(problem)
    assert optimum.constraint_active
    assert optimum.frequency == pytest.approx(materials.MIN_FREQUENCY, rel=1e-6)
    wavelength, thickness, deflection = _best_on_the_constraint(problem)
    assert optimum.deflection == pytest.approx(deflection, rel=1e-6)
    assert optimum.plate.wavelength == pytest.approx(wavelength, rel=1e-4)
    assert optimum.plate.resonator_thickness == pytest.approx(thickness, rel=1e-4)


@pytest.mark.parametrize("ceramic_thickness", materials.CERAMIC_THICKNESSES)
def test_no_feasible_neighbour_is_better(ceramic_thickness):
    problem = DesignProblem(ceramic_thickness)
    optimum = optimise_analytical(problem)
    rng = np.random.default_rng(0)
    centre = np.array([optimum.plate.wavelength, optimum.plate.resonator_thickness])
    points = centre + rng.normal(scale=0.02 * centre, size=(20000, 2))
    points = np.clip(points, problem.lower, problem.upper)
    w, f = analytical_model()(problem.plate(points[:, 0], points[:, 1]))
    feasible = f >= problem.min_frequency
    assert feasible.sum() > 1000
    assert np.max(w[feasible]) <= optimum.deflection * (1 + 1e-9)


def test_thin_ceramic_optimum_sits_on_the_practical_minimum_thickness():
    problem = DesignProblem(0.5e-3)
    optimum = optimise_analytical(problem)
    assert optimum.plate.resonator_thickness == pytest.approx(problem.min_resonator_thickness, rel=1e-9)
    relaxed = optimise_analytical(DesignProblem(0.5e-3, min_resonator_thickness=0.2e-3))
    assert relaxed.deflection > optimum.deflection


def test_a_problem_without_feasible_point_says_so():
    problem = DesignProblem(1e-3, min_frequency=500e3)
    with pytest.raises(InfeasibleError, match="no feasible design"):
        optimise_analytical(problem)


def test_forward_differences_reach_the_same_optimum():
    problem = DesignProblem(1e-3)
    central = optimise_analytical(problem)
    forward = maximise_deflection(analytical_model(), problem, difference="forward")
    assert forward.deflection == pytest.approx(central.deflection, rel=1e-5)
