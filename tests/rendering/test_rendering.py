"""Textures, the drive synthesis and its metrics: the pre-compensated drive beats plain switching, the error falls
with the period, and bad textures are refused with a clear reason."""

import numpy as np
import pytest

from instruments.simulator.physics import default_law
from workflow.damping.envelope import LIMITED_RISE, EnvelopeModel
from workflow.damping.laws import ConstantQ
from workflow.models import analytical
from workflow.models.plate import ORIGINAL_PLATE
from workflow.rendering.metrics import contrast_per_period, envelope_error, transition_times
from workflow.rendering.synthesis import render, search_periods, tuned_carrier
from workflow.rendering.textures import (
    ConstantSpeed,
    FrictionCurve,
    Grating,
    Profile,
    TextureError,
    Trace,
    loop_duration,
    wanted_deflection,
)
from workflow.units import MM, UM

DESIGN = ORIGINAL_PLATE.with_(wavelength=20.5354 * MM, resonator_thickness=0.7124 * MM)
"""The beam model's optimum for h_p = 1 mm (README)."""
GRATING = Grating(2 * MM, 0.5, 0.3 * UM, 1.15 * UM)


@pytest.fixture(scope="module")
def design_model():
    """The h_p = 1 mm design with the simulator's Q(v) and a softening resonance."""
    return EnvelopeModel(float(analytical.resonance_frequency(DESIGN)), float(analytical.deflection_per_volt_per_q(DESIGN)),
                         default_law(DESIGN), softening=0.08)


@pytest.fixture(scope="module")
def grating_rendering(design_model):
    return render(design_model, GRATING, ConstantSpeed(0.1), 30.0, max_points=512)


def test_a_grating_loops_one_period_and_a_profile_its_stroke():
    assert loop_duration(GRATING, ConstantSpeed(0.1)) == pytest.approx(0.02)
    profile = Profile(np.array([1.0, 4.0, 9.0]) * MM, np.array([0.3, 1.0, 0.5]) * UM)
    assert loop_duration(profile, ConstantSpeed(0.05)) == pytest.approx(0.16)
    assert wanted_deflection(profile, ConstantSpeed(0.05), np.array([0.0, 0.03, 0.16])) == pytest.approx(
        np.array([0.3, 0.65, 0.5]) * UM)
    assert wanted_deflection(GRATING, ConstantSpeed(0.1), np.array([0.0, 0.0099, 0.01, 0.0199])) == pytest.approx(
        np.array([1.15, 1.15, 0.3, 0.3]) * UM)
    trace = Trace(np.array([0.0, 0.01, 0.02]), np.array([0.0, 1.0, 0.5]) * MM)
    assert loop_duration(GRATING, trace) == pytest.approx(0.02) and trace.typical_speed == pytest.approx(0.075)
    with pytest.raises(TextureError, match="leaves the profile"):
        wanted_deflection(profile, trace, np.array([0.0, 0.01]))


@pytest.mark.parametrize("make, message", [
    (lambda: Grating(-2 * MM, 0.5, 0.0, 1e-6), "period must be positive"),
    (lambda: Grating(2 * MM, 1.0, 0.0, 1e-6), "duty cycle"),
    (lambda: Grating(2 * MM, 0.5, 1e-6, 0.5e-6), "0 <= low < high"),
    (lambda: Profile(np.array([0.0, 2.0, 1.0]), np.ones(3) * UM), "increase strictly"),
    (lambda: FrictionCurve(np.array([0.0, 1.0, 2.0]) * UM, np.array([1.0, 0.6, 0.7])), "strictly monotonic"),
    (lambda: FrictionCurve(np.array([]), np.array([])), "at least two"),
    (lambda: Trace(np.array([0.0, 0.02, 0.01]), np.zeros(3)), "backwards in time"),
    (lambda: ConstantSpeed(0.0), "speed must be positive"),
])
def test_bad_textures_are_refused_with_the_reason(make, message):
    with pytest.raises(TextureError, match=message):
        make()


def test_a_friction_curve_gives_back_its_amplitudes_monotonically():
    curve = FrictionCurve(np.array([0.0, 0.4, 0.8, 1.2]) * UM, np.array([1.0, 0.85, 0.6, 0.5]))
    assert curve.amplitude_for(np.array([1.0, 0.6, 0.5])) == pytest.approx(np.array([0.0, 0.8, 1.2]) * UM)
    between = curve.amplitude_for(np.linspace(0.5, 1.0, 50))
    assert np.all(np.diff(between) < 0)
    with pytest.raises(TextureError, match="outside the friction curve's range") as error:
        curve.amplitude_for(np.array([0.7, 0.4]))
    assert error.value.index == 1


def test_the_carrier_is_the_resonance_at_the_highest_amplitude(design_model):
    carrier = tuned_carrier(design_model, 1.15 * UM)
    velocity = 2 * np.pi * carrier * 1.15 * UM
    assert carrier == pytest.approx(design_model.resonance_frequency * (1 - 0.08 * velocity**2), rel=1e-10)


def test_precompensation_beats_plain_switching_within_the_limit(grating_rendering):
    r = grating_rendering
    assert r.error < 0.8 * r.plain_error
    assert np.all((r.drive >= 0) & (r.drive <= 30.0)) and np.max(r.drive) == pytest.approx(30.0)
    assert np.max(r.plain_drive) < 30.0
    assert LIMITED_RISE in r.flags and 0 < r.limited_rise_share < 0.1
    assert r.error == pytest.approx(envelope_error(r.envelope, r.wanted))


def test_the_error_falls_as_the_grating_period_grows(design_model):
    model = EnvelopeModel(design_model.resonance_frequency, design_model.gain, ConstantQ(80.0))
    search = search_periods(model, 0.3 * UM, 1.15 * UM, 30.0, points=5)
    assert np.all(np.diff(search.error) < 0) and np.all(np.diff(search.plain_error) < 0)
    assert np.all(search.error[1:] < search.plain_error[1:]) and search.error[-1] < 0.6 * search.plain_error[-1]
    pre, how = search.smallest_period(0.1)
    plain, _ = search.smallest_period(0.1, plain=True)
    assert how != "at most" and 0.5 * MM < pre < 2 * plain / 3
    assert search.smallest_period(0.2)[0] == pytest.approx(2 * pre)


def test_an_amplitude_the_plate_cannot_reach_is_refused(design_model):
    with pytest.raises(TextureError, match=r"above the .* µm this plate reaches at the voltage limit 5 V"):
        render(design_model, GRATING, ConstantSpeed(0.1), 5.0)


def test_metrics_of_a_first_order_step():
    time = np.linspace(0, 0.04, 4001)
    wanted = np.where((time >= 0.01) & (time < 0.03), 1.0, 0.2)
    tau = 1e-3
    achieved = np.where(time < 0.01, 0.2, np.where(time < 0.03, 1 - 0.8 * np.exp(-(time - 0.01) / tau),
                                                   0.2 + 0.8 * np.exp(-(time - 0.03) / tau)))
    times = transition_times(time, achieved, wanted)
    assert times["rise"][0] == pytest.approx(tau * np.log(9), rel=1e-2)
    assert times["fall"][0] == pytest.approx(tau * np.log(9), rel=1e-2)
    assert contrast_per_period(time, wanted, 0.02) == pytest.approx([2 / 3, 2 / 3])
    assert envelope_error(achieved, wanted) == pytest.approx(np.sqrt(2 * tau / 2 * 0.8**2 / 0.04) / 0.8, rel=2e-2)


def test_a_constant_q_model_keeps_its_time_constant():
    model = EnvelopeModel(25e3, 2e-9, ConstantQ(54.0))
    assert float(model.time_constant(0.1)) == pytest.approx(54 / (np.pi * 25e3))
