"""What a built plate's logs measure besides its resonance: the scanned mode shape.

(The deflection per volt from a sweep's top is :func:`workflow.resonance.lorentzian_top`.)

Scan shape: a scan's complex velocities are turned into a real signed pattern (rotated by the
phase that makes them most nearly real) normalised to a root mean square of 1.  Plate and FEM
are symmetric in x and y, so the scatter between mirror-image points estimates the noise of
the pattern (vibrometer noise and whatever asymmetry the model lacks).
"""

from dataclasses import dataclass

import numpy as np

MIRROR_TOLERANCE = 5e-5
"""Scan points whose |x| and |y| agree within this are mirror images of each other [m]."""


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
