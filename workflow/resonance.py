"""Model-free readings of a sampled resonance curve: its peak, its half-power bandwidth and a Lorentzian through its top.

Pure functions of (frequency [Hz], velocity amplitude [m/s]) arrays sorted by frequency, shared by the bench
procedures (the resonance search and the Q campaign), the damping fit's per-sweep estimates and the calibration's
measurements (docs/calibration.md, "The likelihood").

Lorentzian top: near a resonance the velocity of a single mode with quality factor Q is
v = A / sqrt(1 + Q^2 u^2), u = f/f_0 - f_0/f, with A = 2 pi f_0 Q g V its peak and g the quasi-static deflection
per volt.  Written for c = A / Q = 2 pi f_0 g V, every point obeys

    (c / v)^2 = u^2 + (1 / Q(v))^2,

also when Q depends on the velocity, as a glued plate's does.  With the quadratic loss 1/Q(v) = a + b v^2
(b >= 0; b = 0 is the plain Lorentzian, which a top of fewer than :data:`MIN_POINTS_VELOCITY_DEPENDENCE` points is
held to) a least-squares fit of c, a, b over the sweep's top (the points above :data:`TOP_LEVEL` of the peak, at
least three) gives g = c / (2 pi f_0 V): the peak amplitude per volt divided by the Q at the peak, independent of the
damping.  A plain Lorentzian would read the flattened top of an amplitude-dependent resonance as a broader one
(8 % too large a g at the simulator's 2 V search).
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

HALF_POWER = 1 / np.sqrt(2)
"""Velocity share of the peak at the half-power points [-]."""
TOP_LEVEL = 0.5
"""Points of a sweep above this share of its peak velocity enter the Lorentzian fit [-]."""
MIN_POINTS_VELOCITY_DEPENDENCE = 5
"""With fewer top points the fit holds b = 0 (a plain Lorentzian) [-]."""


def parabolic_peak(frequency: np.ndarray, velocity: np.ndarray) -> tuple[float, float]:
    """Peak of a sampled resonance curve by a parabola through the largest sample and its neighbours.

    The vertex is kept between the neighbours; a curve that is not concave there gives the largest sample.

    Returns
    -------
    (frequency [Hz], velocity [m/s])
    """
    i = int(np.clip(np.argmax(velocity), 1, len(velocity) - 2))
    f, v = frequency[i - 1 : i + 2], velocity[i - 1 : i + 2]
    a, b, c = np.polyfit(f - f[1], v, 2)
    if a >= 0:
        j = int(np.argmax(velocity))
        return float(frequency[j]), float(velocity[j])
    shift = float(np.clip(-b / (2 * a), f[0] - f[1], f[2] - f[1]))
    return float(f[1] + shift), float(c + b * shift + a * shift**2)


def log_parabolic_peak_frequency(frequency: np.ndarray, velocity: np.ndarray) -> float | None:
    """Frequency of the velocity maximum, refined by a parabola through ln v at it and its neighbours [Hz]
    (exact for a Gaussian top, closer to a Lorentzian's than the parabola in v).

    None when the maximum lies at either end of the swept range (the peak was not bracketed).
    """
    order = np.argsort(frequency)
    f, v = frequency[order], velocity[order]
    k = int(np.argmax(v))
    if k == 0 or k == len(f) - 1:
        return None
    if np.any(v[k - 1:k + 2] <= 0):
        return float(f[k])
    a, b, _ = np.polyfit(f[k - 1:k + 2] - f[k], np.log(v[k - 1:k + 2]), 2)
    return float(f[k] - b / (2 * a)) if a < 0 else float(f[k])


def half_power_bandwidth(frequency: np.ndarray, velocity: np.ndarray, peak_velocity: float | None = None) -> float:
    """Width between the half-power crossings around the largest sample [Hz].

    From the largest sample, v is walked outwards on each side to the first sample below
    ``peak_velocity`` / sqrt(2) and the crossing is interpolated linearly.  A sweep that ends before one
    crossing gives twice the width on the side it has (a resonance is symmetric to first order near its
    peak); one that misses both gives NaN.

    Parameters
    ----------
    frequency : array
        Drive frequencies, ascending [Hz].
    velocity : array
        Velocity amplitudes [m/s].
    peak_velocity : float, optional
        Peak velocity whose half-power level is sought [m/s]; the largest sample by default.
    """
    peak = int(np.argmax(velocity))
    level = HALF_POWER * (velocity[peak] if peak_velocity is None else peak_velocity)
    left = _crossing(frequency[: peak + 1][::-1], velocity[: peak + 1][::-1], level)
    right = _crossing(frequency[peak:], velocity[peak:], level)
    if np.isfinite(left) and np.isfinite(right):
        return float(right - left)
    if np.isfinite(left) or np.isfinite(right):
        return float(2 * np.nanmin([frequency[peak] - left, right - frequency[peak]]))
    return np.nan


def _crossing(f: np.ndarray, v: np.ndarray, level: float) -> float:
    """Frequency where v, walked from the peak outwards, first drops below ``level`` (interpolated); NaN if never."""
    below = np.nonzero(v < level)[0]
    if below.size == 0:
        return np.nan
    j = below[0]
    return float(f[j - 1] + (level - v[j - 1]) * (f[j] - f[j - 1]) / (v[j] - v[j - 1]))


@dataclass(frozen=True)
class ResonanceFit:
    """A Lorentzian with velocity-dependent damping through the top of one resonance sweep.

    Attributes
    ----------
    frequency : float
        f_0 [Hz].
    peak_velocity : float
        Largest measured velocity of the sweep [m/s].
    quality_factor : float
        Q at that velocity, 1 / (a + b v^2) [-].
    low_velocity_quality_factor : float
        1 / a [-].
    points : int
        Sweep points in the fit [-].
    """

    frequency: float
    peak_velocity: float
    quality_factor: float
    low_velocity_quality_factor: float
    points: int

    def deflection_per_volt(self, voltage: float) -> float:
        """g = A / (2 pi f_0 Q V): quasi-static deflection per volt at the measurement point [m/V]."""
        return self.peak_velocity / (2 * np.pi * self.frequency * self.quality_factor * voltage)


LOSS_RANGE = (1e-6, 1.0)
"""Loss factors 1/Q the Lorentzian of a sweep's top may take [-]: a top whose plain Lorentzian lies outside (Q below
1: a sweep too coarse for its peak, issue 29's coverage study met one) is not a resonance it resolves."""


def lorentzian_top(frequency: np.ndarray, velocity: np.ndarray) -> ResonanceFit | None:
    """Fit :class:`ResonanceFit` to a sweep's top (the module's equation).

    f_0 is refined by a parabola through ln v at the highest point and its neighbours; then c, a
    and b are fitted by least squares on the relative residual of (c/v)^2 = u^2 + (a + b v^2)^2,
    starting from the plain Lorentzian of the top points.  None when the peak is at an end of the
    sweep or the top is not a peak.

    Parameters
    ----------
    frequency : array
        Drive frequencies [Hz].
    velocity : array
        Velocity amplitudes [m/s].
    """
    order = np.argsort(frequency)
    f, v = np.asarray(frequency, float)[order], np.asarray(velocity, float)[order]
    k = int(np.argmax(v))
    f0 = log_parabolic_peak_frequency(f, v)
    if f0 is None or np.any(v[k - 1:k + 2] <= 0):
        return None
    top = v >= TOP_LEVEL * v[k]
    top[k - 1:k + 2] = True
    u2, vt = (f[top] / f0 - f0 / f[top]) ** 2, v[top]
    slope, intercept = np.polyfit(u2, 1 / vt**2, 1)
    if intercept <= 0 or slope <= 0:
        return None
    peak = v[k]
    loss = np.sqrt(intercept / slope)
    if not LOSS_RANGE[0] < loss < LOSS_RANGE[1]:
        return None
    start = np.array([loss, 1e-3 * loss, 1 / (np.sqrt(slope) * peak)])

    def residual(p):
        loss, stiffening, c = p[0], p[1], p[2] * peak
        return (c / vt) ** 2 / (u2 + (loss + stiffening * (vt / peak) ** 2) ** 2) - 1

    free = len(vt) >= MIN_POINTS_VELOCITY_DEPENDENCE
    fit = least_squares(residual, start, bounds=([LOSS_RANGE[0], 0.0, 1e-9], [LOSS_RANGE[1], 1.0 if free else 2e-3 * loss, np.inf]),
                        x_scale="jac")
    loss, stiffening, c = fit.x[0], fit.x[1], fit.x[2] * peak
    q_peak = 1 / (loss + stiffening)
    return ResonanceFit(f0, float(c * q_peak), float(q_peak), float(1 / loss), int(np.count_nonzero(top)))
