"""The model-free readings of a resonance curve (workflow.resonance) against a sampled Lorentzian of known f_0 and Q."""

import numpy as np
import pytest

from workflow.resonance import half_power_bandwidth, log_parabolic_peak_frequency, lorentzian_top, parabolic_peak

F0, Q = 25_013.0, 400.0


def lorentzian(f, f0=F0, q=Q, peak=0.2):
    """Velocity amplitude of one mode [m/s]."""
    return peak / np.sqrt(1 + (q * (f / f0 - f0 / f)) ** 2)


def test_the_half_power_bandwidth_of_a_lorentzian_is_f0_over_q():
    f = np.linspace(F0 - 300, F0 + 300, 601)
    assert F0 / half_power_bandwidth(f, lorentzian(f)) == pytest.approx(Q, rel=2e-3)


def test_a_sweep_missing_one_crossing_doubles_the_side_it_has():
    f = np.linspace(F0 - 300, F0 + 20, 321)
    assert F0 / half_power_bandwidth(f, lorentzian(f)) == pytest.approx(Q, rel=5e-3)
    f = np.linspace(F0 - 10, F0 + 300, 311)
    assert F0 / half_power_bandwidth(f, lorentzian(f)) == pytest.approx(Q, rel=5e-3)


def test_a_sweep_missing_both_crossings_has_no_bandwidth():
    f = np.linspace(F0 - 10, F0 + 10, 21)
    assert np.isnan(half_power_bandwidth(f, lorentzian(f)))


def test_a_given_peak_sets_the_level():
    """With the true peak given, a coarse sweep's level is the true half-power level, not that of its best sample
    (which lies below the peak and so widens the band)."""
    f = np.linspace(F0 - 293, F0 + 307, 61)
    exact, sampled = (F0 / half_power_bandwidth(f, lorentzian(f), peak) for peak in (0.2, None))
    assert exact == pytest.approx(Q, rel=0.006)
    assert sampled < exact - 2


@pytest.mark.parametrize("offset", [-7.0, 0.0, 11.0])
def test_both_peaks_are_found_between_the_samples(offset):
    f = np.linspace(F0 - 200, F0 + 200, 41) + offset
    v = lorentzian(f)
    frequency, velocity = parabolic_peak(f, v)
    assert frequency == pytest.approx(F0, abs=2.0) and velocity == pytest.approx(0.2, rel=0.01)
    assert log_parabolic_peak_frequency(f, v) == pytest.approx(F0, abs=2.0)


def test_the_lorentzian_top_reads_q_and_the_peak():
    f = np.linspace(F0 - 200, F0 + 200, 41)
    fit = lorentzian_top(f, lorentzian(f))
    assert fit.frequency == pytest.approx(F0, abs=2.0)
    assert fit.quality_factor == pytest.approx(Q, rel=0.01)
    assert fit.deflection_per_volt(10.0) == pytest.approx(0.2 / (2 * np.pi * F0 * Q * 10.0), rel=0.02)
