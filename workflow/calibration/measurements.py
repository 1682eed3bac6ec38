"""What a built plate's logs measure besides its resonance: deflection per volt per Q, and the scanned mode shape.

Deflection per volt (docs/calibration.md, "The likelihood"): near a resonance the velocity of a
single mode with quality factor Q is the Lorentzian v = A / sqrt(1 + Q^2 u^2), u = f/f_0 - f_0/f,
with A = 2 pi f_0 Q g V its peak and g the quasi-static deflection per volt.  Written for c = A / Q
= 2 pi f_0 g V, every point obeys

    (c / v)^2 = u^2 + (1 / Q(v))^2,

also when Q depends on the velocity, as a glued plate's does.  With the quadratic loss
1/Q(v) = a + b v^2 (b >= 0; b = 0 is the plain Lorentzian, which a top of fewer than
:data:`MIN_POINTS_VELOCITY_DEPENDENCE` points is held to) a least-squares fit of c, a, b over
the sweep's top (the points above :data:`TOP_LEVEL` of the peak, at least three) gives
g = c / (2 pi f_0 V): the peak amplitude per volt divided by the Q at the peak, independent of
the damping.  A plain Lorentzian would read the flattened top of an amplitude-dependent
resonance as a broader one (8 % too large a g at the simulator's 2 V search).

Scan shape: a scan's complex velocities are turned into a real signed pattern (rotated by the
phase that makes them most nearly real) normalised to a root mean square of 1.  Plate and FEM
are symmetric in x and y, so the scatter between mirror-image points estimates the noise of
the pattern (vibrometer noise and whatever asymmetry the model lacks).
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

TOP_LEVEL = 0.5
"""Points of a sweep above this share of its peak velocity enter the Lorentzian fit [-]."""
MIN_POINTS_VELOCITY_DEPENDENCE = 5
"""With fewer top points the fit holds b = 0 (a plain Lorentzian) [-]."""
MIRROR_TOLERANCE = 5e-5
"""Scan points whose |x| and |y| agree within this are mirror images of each other [m]."""


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


def peak_frequency(frequency: np.ndarray, velocity: np.ndarray) -> float | None:
    """Frequency of the velocity maximum, refined by a parabola through ln v at it and its neighbours [Hz].

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
    f0 = peak_frequency(f, v)
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


def real_pattern(phasors) -> np.ndarray:
    """A complex shape as a real signed pattern of root mean square 1 [-].

    The shape is rotated by the angle that maximises the sum of its squared real parts (the
    principal direction of the points in the complex plane), then its real part is taken.  The
    overall sign is arbitrary; compare patterns up to sign.
    """
    z = np.ravel(np.asarray(phasors, dtype=complex))
    angle = 0.5 * np.angle(np.sum(z**2))
    real = (z * np.exp(-1j * angle)).real
    return real / np.sqrt(np.mean(real**2))


@dataclass(frozen=True)
class ScanShape:
    """The measured mode shape of a scan, ready for the likelihood.

    Attributes
    ----------
    x, y : tuple of float
        Scan points from the plate's centre [m].
    pattern : tuple of float
        :func:`real_pattern` of the measured velocities [-].
    noise : float
        Standard deviation of a pattern value: the floor and the mirror-image scatter in quadrature [-].
    mirror_scatter : float or None
        The scatter between mirror-image points alone [-] (None: no point has a mirror image).
    source : str
        The scan log.
    """

    x: tuple
    y: tuple
    pattern: tuple
    noise: float
    mirror_scatter: float | None
    source: str

    def __post_init__(self):
        values = self.x + self.y + self.pattern + (self.noise, 0.0 if self.mirror_scatter is None else self.mirror_scatter)
        if not (len(self.x) == len(self.y) == len(self.pattern) > 0 and np.all(np.isfinite(values)) and self.noise > 0):
            raise ValueError("a scan shape needs finite points and pattern values of one length, and a positive noise")

    def to_dict(self) -> dict:
        return {"x": list(self.x), "y": list(self.y), "pattern": list(self.pattern), "noise": self.noise,
                "mirror_scatter": self.mirror_scatter, "source": self.source}

    @classmethod
    def from_dict(cls, data: dict) -> "ScanShape":
        scatter = data["mirror_scatter"]
        return cls(tuple(float(v) for v in data["x"]), tuple(float(v) for v in data["y"]),
                   tuple(float(v) for v in data["pattern"]), float(data["noise"]),
                   None if scatter is None else float(scatter), str(data["source"]))


def mirror_scatter(x: np.ndarray, y: np.ndarray, pattern: np.ndarray) -> float | None:
    """Pooled standard deviation of ``pattern`` within groups of mirror-image points (equal |x|, |y|) [-]."""
    keys = np.round(np.column_stack([np.abs(x), np.abs(y)]) / MIRROR_TOLERANCE).astype(np.int64)
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = np.ravel(group)
    counts = np.bincount(group)
    freedom = int(np.sum(counts - 1))
    if freedom == 0:
        return None
    means = np.bincount(group, weights=pattern) / counts
    return float(np.sqrt(np.sum((pattern - means[group]) ** 2) / freedom))


def scan_shape(x, y, phasors, floor: float, source: str) -> ScanShape:
    """The :class:`ScanShape` of measured complex velocities ``phasors`` [m/s] at points (``x``, ``y``) [m].

    Parameters
    ----------
    floor : float
        Smallest noise of a pattern value [-] (the configured ``shape_sigma``).
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    pattern = real_pattern(phasors)
    scatter = mirror_scatter(x, y, pattern)
    noise = float(np.hypot(floor, scatter or 0.0))
    return ScanShape(tuple(x.tolist()), tuple(y.tolist()), tuple(pattern.tolist()), noise, scatter, source)


def aligned_misfit(measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """measured - s predicted with s = +-1 the sign of their inner product (patterns are defined up to sign) [-].

    ``predicted`` may have leading axes (..., n_points).
    """
    sign = np.sign(np.sum(predicted * measured, axis=-1, keepdims=True))
    return measured - np.where(sign == 0, 1.0, sign) * predicted
