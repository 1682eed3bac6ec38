"""Space mapping recovers a known fine optimum from few fine evaluations."""

import numpy as np
import pytest

from workflow.fem import FemSettings
from workflow.fem_evaluations import FemModel
from workflow.fem_optimum import optimise_fem
from workflow.optimize import DesignProblem, analytical_model, maximise_deflection
from workflow.space_mapping import space_mapping_optimum
from workflow.units import MM

COARSE = analytical_model()


def synthetic_fine(plate):
    """A 'fine' model: the beam on a shifted geometry, rescaled, with a lambda- and h_i-dependent drift."""
    wavelength, thickness = np.asarray(plate.wavelength), np.asarray(plate.resonator_thickness)
    ceramic = np.asarray(plate.ceramic_thickness)
    deflection, frequency = COARSE(plate.with_(wavelength=0.98 * wavelength + 0.3 * MM, resonator_thickness=1.05 * thickness))
    return 1.08 * deflection * (1 - 0.01 * (wavelength / MM - 20)), 0.97 * frequency * (1 + 0.01 * (thickness / ceramic - 0.7))


def design(optimum):
    return np.array([optimum.plate.wavelength, optimum.plate.resonator_thickness])


@pytest.mark.parametrize("ceramic_thickness", [0.5e-3, 1e-3, 2e-3])
def test_space_mapping_recovers_the_fine_optimum(ceramic_thickness):
    problem = DesignProblem(ceramic_thickness)
    direct = maximise_deflection(synthetic_fine, problem)
    result = space_mapping_optimum(synthetic_fine, COARSE, problem)
    assert result.converged
    assert result.fine_evaluations <= 6
    assert np.max(np.abs(design(result.optimum) - design(direct))) < 0.1 * MM
    # the coarse optimum itself is not the answer: space mapping moved to the fine one
    assert np.max(np.abs(design(result.coarse_optimum) - design(direct))) > 0.01 * MM
    assert result.optimum.frequency >= problem.min_frequency * (1 - 1e-4)
    assert result.optimum.deflection == pytest.approx(direct.deflection, rel=5e-4)
    assert len(result.trajectory) == result.fine_evaluations
    assert result.coarse_evaluations > 100 * result.fine_evaluations


def test_space_mapping_keeps_an_active_bound():
    problem = DesignProblem(0.5e-3)
    result = space_mapping_optimum(synthetic_fine, COARSE, problem)
    assert result.optimum.plate.resonator_thickness == pytest.approx(problem.min_resonator_thickness, abs=1e-9)
    assert result.optimum.constraint_active


def test_identical_models_need_one_fine_evaluation_per_unexplored_direction():
    problem = DesignProblem(1e-3)
    result = space_mapping_optimum(COARSE, COARSE, problem)
    assert np.max(np.abs(design(result.optimum) - design(result.coarse_optimum))) < 0.01 * MM
    assert result.fine_evaluations <= 3


@pytest.mark.slow
def test_space_mapping_on_the_fem_matches_the_direct_run(tmp_path):
    from workflow.evaluation_cache import EvaluationCache

    problem = DesignProblem(1e-3)
    model = FemModel(settings=FemSettings(), cache=EvaluationCache(tmp_path), scheduler="synchronous")
    direct = optimise_fem(problem, model, "nlopt")
    mapped = optimise_fem(problem, model, "space-mapping")
    assert mapped.fine_evaluations < direct.fine_evaluations / 3
    assert np.max(np.abs(design(mapped.optimum) - design(direct.optimum))) < 0.1 * MM
    assert mapped.optimum.deflection == pytest.approx(direct.optimum.deflection, rel=1e-3)
