"""What a built plate's logs measure besides its resonance: deflection per volt per Q, and the scanned mode shape.

Deflection per volt (docs/calibration.md, "The likelihood"): near a resonance the velocity of a
single mode is the Lorentzian

    v(f) = A / sqrt(1 + Q^2 u^2),   u = f / f_0 - f_0 / f,

with A = 2 pi f_0 Q g V the peak velocity, g the quasi-static deflection per volt.  So
1 / v^2 = (1 + Q^2 u^2) / A^2 is a parabola in u: a least-squares line of 1/v^2 against u^2 over
the sweep's top (the points above :data:`TOP_LEVEL` of the peak) gives A and Q, and
g = A / (2 pi f_0 Q V) does not depend on the damping.  The top alone is used because the plate's Q
depends on its velocity: the points near the peak see the peak's Q.

Scan shape: a scan's complex velocities are turned into a real signed pattern (rotated by the
phase that makes them most nearly real) normalised to a root mean square of 1.  Plate and FEM
are symmetric in x and y, so the scatter between mirror-image points estimates the noise of
the pattern (vibrometer noise and whatever asymmetry the model lacks).
"""

from dataclasses import dataclass

import numpy as np

TOP_LEVEL = 0.7
"""Points of a sweep above this share of its peak velocity enter the Lorentzian fit [-]."""
MIRROR_TOLERANCE = 5e-5
"""Scan points whose |x| and |y| agree within this are mirror images of each other [m]."""


@dataclass(frozen=True)
class ResonanceFit:
    """A Lorentzian through the top of one resonance sweep.

    Attributes
    ----------
    frequency : float
        f_0 [Hz].
    peak_velocity : float
        A [m/s].
    quality_factor : float
        Q of the velocity curve's top [-].
    points : int
        Sweep points in the fit [-].
    """

    frequency: float
    peak_velocity: float
    quality_factor: float
    points: int

    def deflection_per_volt(self, voltage: float) -> float:
        """g = A / (2 pi f_0 Q V): quasi-static deflection per volt at the measurement point [m/V]."""
        return self.peak_velocity / (2 * np.pi * self.frequency * self.quality_factor * voltage)


def lorentzian_top(frequency: np.ndarray, velocity: np.ndarray) -> ResonanceFit | None:
    """Fit :class:`ResonanceFit` to a sweep's points above :data:`TOP_LEVEL` of its peak.

    f_0 is refined by a parabola through ln v at the highest point and its neighbours; then
    1/v^2 = a + b u^2 by least squares gives A = a^-1/2 and Q = (b/a)^1/2.  None when the peak is at
    an end of the sweep or fewer than three points are above the level (the sweep does not
    resolve the resonance's width).

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
    if k == 0 or k == len(f) - 1 or np.any(v[k - 1:k + 2] <= 0):
        return None
    a, b, _ = np.polyfit(f[k - 1:k + 2] - f[k], np.log(v[k - 1:k + 2]), 2)
    f0 = float(f[k] - b / (2 * a)) if a < 0 else float(f[k])
    top = v >= TOP_LEVEL * v[k]
    if np.count_nonzero(top) < 3:
        return None
    u2 = (f[top] / f0 - f0 / f[top]) ** 2
    slope, intercept = np.polyfit(u2, 1 / v[top] ** 2, 1)
    if intercept <= 0 or slope <= 0:
        return None
    return ResonanceFit(f0, float(intercept ** -0.5), float(np.sqrt(slope / intercept)), int(np.count_nonzero(top)))


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
