"""The driven envelope equation: its two special cases are the fit's own equations, and its inversion tracks."""

import numpy as np
import pytest

from workflow.damping.envelope import (
    LIMITED_FALL,
    LIMITED_RISE,
    REACHED,
    EnvelopeModel,
    envelope_at,
    invert,
    periodic_inversion,
    periodic_play,
    play,
)
from workflow.damping.harmonic import self_consistent_amplitude, softened_amplitudes
from workflow.damping.laws import LinearLoss, MonotoneSpline, QuadraticLoss
from workflow.damping.ringdown import decay_velocity

F_R, GAIN = 25_000.0, 2.4e-9
QUADRATIC = QuadraticLoss(q0=150.0, alpha=0.25)
SOFT = EnvelopeModel(F_R, GAIN, QUADRATIC, softening=0.08)


@pytest.mark.parametrize("law", [QUADRATIC, LinearLoss(q0=120.0, alpha=2.0),
                                 MonotoneSpline(1 / (1 / 150 - 0), 1e-3, 2e-3, 1e-3, 0.0, 3e-3, 1e-3, 1e-3, 2e-3, 0.3)])
def test_without_drive_the_envelope_rings_down_as_the_fit_decays(law):
    model = EnvelopeModel(F_R, GAIN, law)
    dt = 40e-6
    envelope = play(model, np.zeros(150), dt, start=0.3 + 0.1j)
    expected = decay_velocity(law, F_R, abs(0.3 + 0.1j), dt * np.arange(151))
    assert np.max(np.abs(np.abs(envelope) / expected - 1)) < 1e-4


def test_a_held_drive_settles_on_the_harmonic_solution():
    plain = EnvelopeModel(F_R, GAIN, QUADRATIC)
    steady = abs(play(plain, np.full(600, 10.0), 50e-6)[-1])
    assert steady == pytest.approx(2 * np.pi * F_R * self_consistent_amplitude(GAIN * 10.0, F_R, F_R, QUADRATIC.quality_factor),
                                   rel=1e-8)
    detuned = SOFT.with_carrier(F_R * (1 - 0.08 * 0.1**2))
    steady = abs(periodic_play(detuned, np.full(50, 8.0), 50e-6)[-1])
    harmonic = softened_amplitudes(np.array([GAIN * 8.0]), np.array([detuned.carrier]), np.array([F_R]), 0.08,
                                   QUADRATIC.quality_factor)[0]
    assert steady == pytest.approx(2 * np.pi * detuned.carrier * harmonic, rel=1e-8)
    assert detuned.steady_voltage(steady) == pytest.approx(8.0, rel=1e-9)


def test_the_periodic_state_is_what_long_repetition_reaches():
    drive = np.where(np.arange(64) < 32, 20.0, 2.0)
    periodic = periodic_play(SOFT, drive, 60e-6)
    repeated = play(SOFT, np.tile(drive, 40), 60e-6)[-65:]
    assert np.max(np.abs(periodic - repeated)) < 1e-9 * np.max(np.abs(periodic))


def test_the_inverted_drive_reproduces_the_wanted_envelope_where_it_is_reachable():
    frequency = SOFT.resonance(0.15)
    model = SOFT.with_carrier(frequency)
    samples = 120
    wanted = np.where(np.arange(samples) < samples / 2, 0.15, 0.04)
    result = periodic_inversion(model, wanted, 80e-6, 30.0)
    assert np.all((result.voltage >= 0) & (result.voltage <= 30.0))
    reached = result.flags == REACHED
    assert np.max(np.abs(np.abs(result.envelope[1:][reached]) / np.roll(wanted, -1)[reached] - 1)) < 1e-8
    assert LIMITED_RISE in result.flags and LIMITED_FALL in result.flags
    assert np.max(result.voltage) == 30.0
    replay = periodic_play(model, result.voltage, 80e-6)
    assert np.allclose(np.abs(replay), np.abs(result.envelope), rtol=1e-6)


def test_a_rise_within_the_limit_is_met_exactly():
    model = EnvelopeModel(F_R, GAIN, QUADRATIC)
    wanted = np.linspace(0.0, 0.1, 41)
    result = invert(model, wanted, 100e-6, 30.0)
    assert np.all(result.flags == REACHED)
    assert np.allclose(np.abs(result.envelope), wanted, rtol=1e-8, atol=1e-12)


def test_a_lower_limit_holds_the_rise_back_and_is_never_exceeded():
    model = EnvelopeModel(F_R, GAIN, QUADRATIC)
    wanted = np.full(21, 0.2)
    result = invert(model, wanted, 100e-6, 5.0)
    assert np.all(result.voltage <= 5.0) and np.all(result.flags == LIMITED_RISE)
    assert np.all(np.abs(result.envelope[1:]) < 0.2)


def test_the_reachable_amplitude_is_the_steady_one_at_the_limit():
    model = EnvelopeModel(F_R, GAIN, QUADRATIC)
    reachable = model.reachable_velocity(15.0)
    exact = 2 * np.pi * F_R * self_consistent_amplitude(GAIN * 15.0, F_R, F_R, QUADRATIC.quality_factor)
    assert reachable == pytest.approx(exact, rel=2e-3) and reachable <= exact
    assert model.steady_voltage(reachable) <= 15.0


def test_the_envelope_between_samples_continues_the_held_drive():
    model = EnvelopeModel(F_R, GAIN, QUADRATIC)
    drive = np.array([10.0, 0.0, 20.0, 5.0])
    fine = play(model, np.repeat(drive, 4), 25e-6)
    coarse = play(model, drive, 100e-6)
    times = 25e-6 * np.arange(17)
    assert np.allclose(envelope_at(model, drive, 100e-6, coarse, times), fine, rtol=1e-5)
