"""Design with Q(v): self-consistent deflection, required voltage, optimisation, propagation."""

import numpy as np
import pytest

from workflow.damping.laws import ConstantQ, QuadraticLoss, quadratic_law_through
from workflow.damping.posterior import DampingPosterior
from workflow.models import analytical, materials
from workflow.models.analytical import beam_response
from workflow.models.plate import ORIGINAL_PLATE, Plate
from workflow.optimise.damped import (
    DampedFemModel,
    damped_beam_model,
    damped_deflection,
    damped_maps,
    design_with_damping,
    required_voltage,
)
from workflow.optimise.problem import DesignProblem, maximise_deflection, optimise_analytical

LAW = QuadraticLoss(q0=150.0, alpha=0.25)
GRID = Plate(
    wavelength=np.linspace(15e-3, 40e-3, 9)[:, None],
    resonator_thickness=np.linspace(0.5e-3, 3e-3, 7)[None, :],
    ceramic_thickness=1e-3,
)


def test_constant_q_gives_the_beam_model():
    w = damped_deflection(beam_response(GRID, 15.0), ConstantQ(materials.PLATE_Q))
    assert np.allclose(w, analytical.dynamic_deflection(GRID, 15.0, materials.PLATE_Q), rtol=1e-10)


def test_original_plate_keeps_its_deflection_when_q_of_v_passes_through_54_there():
    w_constant = analytical.dynamic_deflection(ORIGINAL_PLATE, 15.0, 54.0)
    v_work = 2 * np.pi * analytical.resonance_frequency(ORIGINAL_PLATE) * w_constant
    law = quadratic_law_through(150.0, 54.0, float(v_work))
    assert damped_deflection(beam_response(ORIGINAL_PLATE, 15.0), law) == pytest.approx(w_constant, rel=1e-9)


def test_required_voltage_inverts_the_deflection():
    voltage = required_voltage(beam_response(GRID, 15.0), LAW)
    assert np.allclose(damped_deflection(beam_response(GRID, voltage), LAW), materials.TARGET_DEFLECTION, rtol=1e-8)


def test_one_q_of_v_path_for_every_model_gives_the_beam_models_closed_forms():
    """The beam model through the model-independent functions: the single-mode harmonic solve of the beam's own
    amplitude, the closed-form V* = w* / (Q(v*) k) whatever voltage the response was taken at, and a response
    scaled to another voltage equal to the response at that voltage (every model is linear in V)."""
    from workflow.damping.harmonic import self_consistent_amplitude
    from workflow.models.response import ScaledResponse

    frequency = analytical.resonance_frequency(GRID)
    per_volt = analytical.deflection_per_volt_per_q(GRID)
    single_mode = self_consistent_amplitude(per_volt * 15.0, frequency, frequency, LAW.quality_factor)
    assert np.allclose(damped_deflection(beam_response(GRID, 15.0), LAW), single_mode, rtol=1e-11)
    closed = materials.TARGET_DEFLECTION / (LAW.quality_factor(2 * np.pi * frequency * materials.TARGET_DEFLECTION) * per_volt)
    for voltage in (1.0, 15.0, 200.0):
        assert np.allclose(required_voltage(beam_response(GRID, voltage), LAW), closed, rtol=1e-13)
    scaled = ScaledResponse(beam_response(GRID, 15.0), 2.0)
    assert scaled.voltage == 30.0 and scaled.error is None
    assert np.allclose(damped_deflection(scaled, LAW), damped_deflection(beam_response(GRID, 30.0), LAW), rtol=1e-13)


def test_more_voltage_more_deflection_more_loss_less_deflection():
    voltages = np.linspace(1.0, 40.0, 30)
    w = damped_deflection(beam_response(ORIGINAL_PLATE, voltages), LAW)
    assert np.all(np.diff(w) > 0)
    alphas = np.linspace(0.0, 1.0, 11)
    w_alpha = damped_deflection(beam_response(ORIGINAL_PLATE, 15.0), QuadraticLoss(150.0, alphas))
    assert np.all(np.diff(w_alpha) < 0)
    # a voltage-dependent Q saturates the response: doubling V less than doubles w
    assert damped_deflection(beam_response(ORIGINAL_PLATE, 30.0), LAW) < 2 * damped_deflection(beam_response(ORIGINAL_PLATE, 15.0), LAW)


def test_damped_beam_model_drives_the_optimiser():
    problem = DesignProblem(ceramic_thickness=1e-3)
    constant = maximise_deflection(damped_beam_model(ConstantQ(materials.PLATE_Q)), problem)
    reference = optimise_analytical(problem)
    assert constant.deflection == pytest.approx(reference.deflection, rel=1e-6)
    damped = maximise_deflection(damped_beam_model(LAW), problem)
    assert damped.frequency >= problem.min_frequency * (1 - 1e-6)
    # the optimum geometry barely moves (the paper, docs/damping.md)
    assert float(damped.plate.wavelength) == pytest.approx(float(reference.plate.wavelength), rel=0.02)
    assert damped.deflection == pytest.approx(float(damped_deflection(beam_response(damped.plate, problem.voltage), LAW)), rel=1e-9)


class _LinearFemResult:
    """A stand-in FEM result: deflection proportional to Q, as one mode at resonance."""

    def __init__(self, per_q, frequency, voltage):
        self.per_q, self.frequency, self.voltage = per_q, frequency, voltage

    def deflection_at_q(self, q):
        return self.per_q * np.asarray(q)


def test_fem_path_matches_the_beam_solution_for_a_proportional_response():
    per_q = float(analytical.deflection_per_volt_per_q(ORIGINAL_PLATE)) * 15.0
    frequency = float(analytical.resonance_frequency(ORIGINAL_PLATE))
    result = _LinearFemResult(per_q, frequency, 15.0)
    assert damped_deflection(result, LAW) == pytest.approx(float(damped_deflection(beam_response(ORIGINAL_PLATE, 15.0), LAW)), rel=1e-9)
    assert required_voltage(result, LAW) == pytest.approx(float(required_voltage(beam_response(ORIGINAL_PLATE, 15.0), LAW)), rel=1e-9)


def _posterior(n=40, seed=0):
    rng = np.random.default_rng(seed)
    return DampingPosterior("quadratic", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(0.25, 0.005, n)})


def test_posterior_propagation_gives_ordered_intervals():
    problems = [DesignProblem(ceramic_thickness=h) for h in (1e-3, 2e-3)]
    design = design_with_damping(_posterior(), problems, draws=6, scheduler="synchronous", progress=False)
    for optimum in design.optima.values():
        p05, p50, p95 = optimum.interval("required_voltage")
        assert p05 <= p50 <= p95
        assert p05 <= optimum.required_voltage * 1.05 and optimum.required_voltage <= p95 * 1.05
    low, high = np.quantile(design.original_required_voltage, [0.05, 0.95])
    assert 0 < low <= high


def test_maps_are_consistent_with_the_pointwise_functions():
    problem = DesignProblem(ceramic_thickness=1e-3)
    maps = damped_maps(_posterior(), problem, grid=11, draws=20)
    law = _posterior().median_law()
    plate = problem.plate(maps.wavelength[3], maps.resonator_thickness[5])
    assert maps.deflection[3, 5] == pytest.approx(float(damped_deflection(beam_response(plate, problem.voltage), law)), rel=1e-9)
    assert maps.required_voltage[3, 5] == pytest.approx(float(required_voltage(beam_response(plate, problem.voltage), law)), rel=1e-9)
    p05, p50, p95 = maps.required_voltage_interval
    assert np.all(p05 <= p50) and np.all(p50 <= p95)


def test_damped_fem_model_with_constant_q_is_the_fem():
    from workflow.models.fem import FemSettings
    from workflow.optimise.fem_model import FemModel

    settings = FemSettings(elements_per_ceramic=4, elements_across_half_width=3)
    fem = FemModel(q=materials.PLATE_Q, voltage=10.0, settings=settings)
    plate = ORIGINAL_PLATE
    (result,) = fem.results(plate)
    constant = DampedFemModel(ConstantQ(materials.PLATE_Q), fem, voltage=15.0)
    deflection, frequency = constant(plate)
    assert float(deflection) == pytest.approx(1.5 * result.deflection, rel=1e-9)
    assert float(frequency) == result.frequency
    damped, _ = DampedFemModel(LAW, fem, voltage=15.0)(plate)
    v = 2 * np.pi * result.frequency * float(damped)
    assert float(damped) == pytest.approx(1.5 * float(result.deflection_at_q(LAW.quality_factor(v))), rel=1e-8)


def test_stacked_single_plate_responses_are_the_batched_response():
    """The FEM's maps go through StackedResponse (one response per geometry); on the beam model, stacking the
    scalar responses of a grid must give the vectorised batch's deflections and voltages, draws axis included."""
    from workflow.models.response import StackedResponse
    from workflow.optimise.fem_model import scalar_plates

    problem = DesignProblem(ceramic_thickness=1e-3)
    plate = problem.plate(np.linspace(20e-3, 30e-3, 3)[:, None], np.linspace(0.5e-3, 2e-3, 4)[None, :])
    batch = beam_response(plate, 15.0)
    stacked = StackedResponse(tuple(beam_response(p, 15.0) for p in scalar_plates(plate)), plate.batch_shape)
    law = _posterior().median_law()
    drawn = _posterior().draws(7)
    on_axis = type(drawn)(**{k: np.reshape(v, (-1, 1, 1)) for k, v in vars(drawn).items()})
    np.testing.assert_allclose(stacked.frequency, batch.frequency, rtol=1e-15)
    np.testing.assert_allclose(damped_deflection(stacked, law), damped_deflection(batch, law), rtol=1e-11)
    stacked_voltages = required_voltage(stacked, on_axis)
    assert stacked_voltages.shape == (7, 3, 4)
    np.testing.assert_allclose(stacked_voltages, required_voltage(batch, on_axis), rtol=1e-12)
