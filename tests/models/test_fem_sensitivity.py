"""Design sensitivities of the FEM against finite differences of full evaluations (coarse meshes)."""

import json
import pickle

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from workflow.damping.laws import quadratic_law_through
from workflow.errors import TactileError
from workflow.execution.cache import EvaluationCache, content_key
from workflow.models.fem import FemResult, FemSettings, evaluate_fem
from workflow.models.fem.evaluate import discretise, working_modes
from workflow.models.fem.mesh import quarter_plate_mesh
from workflow.models.fem.probes import mean_deflection
from workflow.models.fem.sensitivity import (
    DESIGN_PARAMETERS,
    TopologyError,
    _mode_tangent,
    best_mode_gradients,
    check_same_topology,
    complement_solve,
    evaluate_fem_with_tangents,
    gradient,
    result_gradient,
    system_tangent,
)
from workflow.models.plate import ORIGINAL_PLATE
from workflow.optimise.damped import damped_deflection
from workflow.optimise.fem_model import FemModel, FemTask, describe_fem_task
from workflow.optimise.problem import DesignProblem
from workflow.units import MM

COARSE = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=3)
"""A mesh for fast tests (not for accuracy)."""
STEP = 1e-3 * MM
"""Central-difference step of the full evaluations [m] (in the plateau: errors ~1e-6)."""
PLATES = [ORIGINAL_PLATE, DesignProblem(0.5 * MM).plate(15.94 * MM, 0.51 * MM)]


def _central_difference(function, plate, name, step=STEP):
    """(function(plate + step) - function(plate - step)) / (2 step) of full evaluations along a plate field."""
    value = float(getattr(plate, name))
    plus, minus = (evaluate_fem(plate.with_(**{name: value + s}), 54.0, 15.0, COARSE) for s in (step, -step))
    return (np.asarray(function(plus)) - function(minus)) / (2 * step)


@pytest.mark.parametrize("plate", PLATES, ids=["original", "hp0.5"])
def test_best_mode_gradients_match_central_differences_of_full_evaluations(plate):
    result = evaluate_fem_with_tangents(plate, 54.0, 15.0, COARSE)
    plain = evaluate_fem(plate, 54.0, 15.0, COARSE)
    assert result.frequency == plain.frequency and result.deflection == plain.deflection
    best = result.best_index

    def best_values(other):
        """Frequency and deflections at Q 54 and 20 of the mode with the best index (held fixed)."""
        frequency = other.modes[best].frequency
        return [frequency] + [float(mean_deflection(other.probe_model.response(frequency, q))) for q in (54.0, 20.0)]

    gradients = [best_mode_gradients(result)] + [best_mode_gradients(result, q) for q in (54.0, 20.0)]
    for k, name in enumerate(DESIGN_PARAMETERS):
        expected = _central_difference(best_values, plate, name)
        for frequency_gradient, _ in gradients:
            assert frequency_gradient[k] == pytest.approx(expected[0], rel=1e-4)
        for (_, deflection_gradient), expected_deflection in zip(gradients, expected[[1, 1, 2]]):
            assert deflection_gradient[k] == pytest.approx(expected_deflection, rel=1e-3)


def test_gradient_of_a_self_consistent_deflection_with_q_of_v():
    """Any function of a result differentiates along the tangents: here the deflection with Q(v)."""
    law = quadratic_law_through(q_low=80.0, q_work=54.0, v_work=0.2)
    result = evaluate_fem_with_tangents(ORIGINAL_PLATE, 54.0, 15.0, COARSE)
    computed = result_gradient(lambda moved: damped_deflection(moved, law), result)
    for k, name in enumerate(DESIGN_PARAMETERS):
        expected = _central_difference(lambda other: damped_deflection(other, law), ORIGINAL_PLATE, name)
        assert computed[k] == pytest.approx(expected, rel=1e-3)


def test_every_tangent_field_matches_central_differences():
    """Per mode, with a smaller step: two modes 0.8 % apart veer, so their shapes curve fast."""
    plate = ORIGINAL_PLATE
    result = evaluate_fem_with_tangents(plate, 54.0, 15.0, COARSE)
    reference = result.probe_model
    fields = ("eigenvalues", "modal_forces", "probe_shapes", "residual")

    def flat_fields(other):
        """The probe model's fields, mode signs aligned on the reference's (eigenvector signs are arbitrary)."""
        model = other.probe_model
        signs = np.sign(np.einsum("pm,pm->m", model.probe_shapes, reference.probe_shapes))
        values = (model.eigenvalues, model.modal_forces * signs, model.probe_shapes * signs, model.residual)
        return np.concatenate([np.ravel(value) for value in values])

    sizes = np.cumsum([getattr(reference, field).size for field in fields])[:-1]
    for name in DESIGN_PARAMETERS:
        expected = np.split(_central_difference(flat_fields, plate, name, step=STEP / 10), sizes)
        for field, expected_field in zip(fields, expected):
            computed = np.ravel(getattr(result.tangents[name], field))
            error = np.max(np.abs(computed - expected_field)) / np.max(np.abs(expected_field))
            assert error < 1e-4, (name, field, error)


def test_complement_solve_matches_a_direct_bordered_solve():
    plate = ORIGINAL_PLATE
    mesh, system, _ = discretise(plate, 15.0, COARSE)
    modes = working_modes(plate, system, COARSE)
    tangent = system_tangent(plate, "resonator_thickness", 15.0, COARSE, mesh)
    _, _, rhs = _mode_tangent(system, modes, tangent)
    default = complement_solve(system, modes, rhs, modes.eigenvalues)
    converged = complement_solve(system, modes, rhs, modes.eigenvalues, n_blocks=10)
    mass_vectors = system.mass @ modes.vectors
    for j, eigenvalue in enumerate(modes.eigenvalues):
        bordered = sp.bmat([[system.stiffness - eigenvalue * system.mass, mass_vectors], [mass_vectors.T, None]])
        exact = sla.spsolve(bordered.tocsc(), np.concatenate([rhs[:, j], np.zeros(COARSE.n_modes)]))[: len(rhs)]
        assert np.linalg.norm(default[:, j] - exact) < 1e-3 * np.linalg.norm(exact)
        assert np.linalg.norm(converged[:, j] - exact) < 1e-8 * np.linalg.norm(exact)


def test_topology_change_is_refused():
    """Near lambda = 6 mm the coarse mesh's free end gains an element: no derivative across that."""
    near_threshold = ORIGINAL_PLATE.with_(wavelength=5.99 * MM)
    with pytest.raises(TopologyError, match="element edges"):
        system_tangent(near_threshold, "wavelength", 15.0, COARSE, quarter_plate_mesh(near_threshold, COARSE), 0.01)
    mesh = quarter_plate_mesh(ORIGINAL_PLATE, COARSE)
    system_tangent(ORIGINAL_PLATE, "wavelength", 15.0, COARSE, mesh, relative_step=0.01)
    check_same_topology(mesh, quarter_plate_mesh(ORIGINAL_PLATE.with_(resonator_thickness=0.3 * MM), COARSE))
    with pytest.raises(TopologyError):
        check_same_topology(mesh, quarter_plate_mesh(ORIGINAL_PLATE, FemSettings(elements_per_ceramic=2)))


def test_gradient_helpers_are_linear_along_tangents_and_need_tangents():
    result = evaluate_fem_with_tangents(ORIGINAL_PLATE, 54.0, 15.0, COARSE)
    tangents = list(result.tangents.values())
    model = result.probe_model
    assert np.array_equal(model.moved(tangents[0], 0.0).residual, model.residual)
    linear = gradient(lambda moved: moved.eigenvalues, model, tangents)
    assert linear.shape == (2, COARSE.n_modes)
    np.testing.assert_allclose(linear, [t.eigenvalues for t in tangents], rtol=1e-6)
    # the best mode's frequency gradient is d sqrt(lam) / (2 pi) of its eigenvalue's
    frequency_gradient, _ = best_mode_gradients(result)
    best = result.best_index
    expected = [t.eigenvalues[best] / (4 * np.pi * np.sqrt(model.eigenvalues[best])) for t in tangents]
    np.testing.assert_allclose(frequency_gradient, expected, rtol=1e-6)
    with pytest.raises(TactileError, match="no tangents"):
        result_gradient(lambda moved: moved.frequency, evaluate_fem(ORIGINAL_PLATE, 54.0, 15.0, COARSE))


def test_results_with_tangents_round_trip_and_old_results_still_load():
    result = evaluate_fem_with_tangents(ORIGINAL_PLATE, 54.0, 15.0, COARSE)
    again = FemResult.from_dict(json.loads(json.dumps(result.to_dict())))
    assert again.q == result.q and list(again.tangents) == list(DESIGN_PARAMETERS)
    for name, tangent in result.tangents.items():
        for field in ("eigenvalues", "modal_forces", "probe_shapes", "residual"):
            np.testing.assert_array_equal(getattr(again.tangents[name], field), getattr(tangent, field))
    np.testing.assert_array_equal(best_mode_gradients(again), best_mode_gradients(result))
    # a dict and a pickle from before the q and tangents fields
    old = result.to_dict()
    del old["q"], old["tangents"]
    loaded = FemResult.from_dict(old)
    assert loaded.q is None and loaded.tangents is None and loaded.deflection == result.deflection
    plain = evaluate_fem(ORIGINAL_PLATE, 54.0, 15.0, COARSE)
    assert plain.tangents is None and "tangents" not in plain.to_dict()
    for name in ("q", "tangents"):
        object.__delattr__(plain, name)
    unpickled = pickle.loads(pickle.dumps(plain))
    assert unpickled.tangents is None and unpickled.q is None and unpickled.deflection == plain.deflection


def test_fem_model_gradients_are_cached_apart_from_plain_results(tmp_path):
    plates = ORIGINAL_PLATE.with_(wavelength=np.array([23e-3, 24e-3]))
    first = FemModel(settings=COARSE, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    deflection_gradient, frequency_gradient = first.gradients(plates)
    assert deflection_gradient.shape == frequency_gradient.shape == (2, 2)
    assert np.all(frequency_gradient[:, 0] < 0) and np.all(frequency_gradient[:, 1] > 0)
    assert first.cache.misses == 2
    second = FemModel(settings=COARSE, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    again = second.gradients(plates)
    assert second.cache.hits == 2 and second.cache.misses == 0
    np.testing.assert_array_equal(again[0], deflection_gradient)
    np.testing.assert_array_equal(again[1], frequency_gradient)
    plain = second.results(plates)
    assert second.cache.misses == 2 and all(result.tangents is None for result in plain)
    with_tangents = second.results(plates, with_tangents=True)
    assert second.cache.hits == 4 and all(result.tangents is not None for result in with_tangents)
    task = FemTask(ORIGINAL_PLATE, 54.0, 15.0, COARSE)
    assert content_key(describe_fem_task(task)) != content_key(
        describe_fem_task(FemTask(ORIGINAL_PLATE, 54.0, 15.0, COARSE, tangents=True))
    )
    single = second.gradients(ORIGINAL_PLATE)[0]  # a scalar plate: shape (2,), from the cache
    assert single.shape == (2,) and np.array_equal(single, deflection_gradient[1])
