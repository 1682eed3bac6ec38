"""A response surface of the FEM over a box of parameters: a low-order polynomial fitted to a design.

The inputs are mapped linearly from their box [low, high] to [-1, 1]; the basis is 1, the
inputs, and (degree 2) their squares and pairwise products.  The fit is least squares; its
error is the leave-one-out residual (hat-matrix formula), which the calibration adds to the
likelihood's variance.
"""

from dataclasses import dataclass
from itertools import combinations_with_replacement

import numpy as np

from workflow.errors import TactileError


def latin_hypercube(n_points: int, bounds: np.ndarray, seed: int) -> np.ndarray:
    """A Latin hypercube of ``n_points`` in the box ``bounds`` (n_dim, 2), centre point first.

    Each input's range is cut into ``n_points - 1`` strata, one point per stratum, plus the
    centre of the box (the nominal of a symmetric prior).
    """
    bounds = np.asarray(bounds, dtype=float)
    rng = np.random.default_rng(seed)
    n_dim, n_random = len(bounds), n_points - 1
    strata = np.stack([rng.permutation(n_random) for _ in range(n_dim)], axis=1)
    unit = (strata + rng.uniform(size=(n_random, n_dim))) / n_random
    points = np.vstack([np.full((1, n_dim), 0.5), unit])
    return bounds[:, 0] + points * (bounds[:, 1] - bounds[:, 0])


def n_coefficients(n_dim: int, degree: int) -> int:
    """Terms of the polynomial basis [-]."""
    return 1 + n_dim + (n_dim * (n_dim + 1) // 2 if degree == 2 else 0)


def _basis(unit: np.ndarray, degree: int) -> np.ndarray:
    """Basis columns of points already mapped to [-1, 1]^n, shape (..., n_coefficients)."""
    columns = [np.ones(unit.shape[:-1]), *np.moveaxis(unit, -1, 0)]
    if degree == 2:
        columns += [unit[..., i] * unit[..., j] for i, j in combinations_with_replacement(range(unit.shape[-1]), 2)]
    return np.stack(columns, axis=-1)


@dataclass(frozen=True)
class ResponseSurface:
    """A polynomial of ``degree`` over a box, with its leave-one-out error.

    Attributes
    ----------
    bounds : tuple of (low, high)
        The box the inputs are mapped from [input units].
    degree : int
        1 (linear) or 2 (quadratic with products).
    coefficients : tuple of float
    loo_rms : float
        Root mean square leave-one-out residual of the fit [output units].
    max_residual : float
        Largest absolute leave-one-out residual [output units].
    """

    bounds: tuple
    degree: int
    coefficients: tuple
    loo_rms: float
    max_residual: float

    def __post_init__(self):
        bounds = np.asarray(self.bounds, dtype=float)
        if bounds.ndim != 2 or bounds.shape[1] != 2 or not len(bounds) or not np.all(bounds[:, 0] < bounds[:, 1]):
            raise ValueError(f"a response surface's bounds must be (low, high) pairs with low < high, got {self.bounds!r}")
        if self.degree not in (1, 2):
            raise ValueError(f"a response surface's degree must be 1 or 2, got {self.degree!r}")
        if len(self.coefficients) != n_coefficients(len(bounds), self.degree):
            raise ValueError(f"a degree-{self.degree} surface over {len(bounds)} parameters has "
                             f"{n_coefficients(len(bounds), self.degree)} coefficients, not {len(self.coefficients)}")
        if not (np.all(np.isfinite(self.coefficients)) and self.loo_rms >= 0 and self.max_residual >= 0
                and np.isfinite([self.loo_rms, self.max_residual]).all()):
            raise ValueError("a response surface's coefficients and errors must be finite (errors >= 0)")

    def __call__(self, points) -> np.ndarray:
        """Values at ``points`` (..., n_dim) [input units]."""
        return self.basis(points) @ np.asarray(self.coefficients)

    def basis(self, points) -> np.ndarray:
        """The polynomial's basis columns at ``points`` (..., n_dim), shape (..., n_coefficients) [-]."""
        bounds = np.asarray(self.bounds)
        unit = 2 * (np.asarray(points, dtype=float) - bounds[:, 0]) / (bounds[:, 1] - bounds[:, 0]) - 1
        return _basis(unit, self.degree)

    def to_dict(self) -> dict:
        return {
            "bounds": [list(pair) for pair in self.bounds],
            "degree": self.degree,
            "coefficients": list(self.coefficients),
            "loo_rms": self.loo_rms,
            "max_residual": self.max_residual,
        }

    @classmethod
    def from_dict(cls, data: dict) -> "ResponseSurface":
        return cls(
            bounds=tuple(tuple(float(x) for x in pair) for pair in data["bounds"]),
            degree=int(data["degree"]),
            coefficients=tuple(float(c) for c in data["coefficients"]),
            loo_rms=float(data["loo_rms"]),
            max_residual=float(data["max_residual"]),
        )


def fit_response_surface(points: np.ndarray, values: np.ndarray, bounds: np.ndarray, degree: int) -> ResponseSurface:
    """Least-squares polynomial through ``values`` at ``points`` (n, n_dim) in the box ``bounds``.

    Raises
    ------
    TactileError
        With fewer points than the basis has terms plus two (no leave-one-out error then).
    """
    points, values, bounds = np.asarray(points, float), np.asarray(values, float), np.asarray(bounds, float)
    needed = n_coefficients(points.shape[1], degree) + 2
    if len(points) < needed:
        raise TactileError(f"a degree-{degree} surrogate over {points.shape[1]} parameters needs at least {needed} points, got {len(points)}")
    unit = 2 * (points - bounds[:, 0]) / (bounds[:, 1] - bounds[:, 0]) - 1
    design = _basis(unit, degree)
    coefficients, *_ = np.linalg.lstsq(design, values, rcond=None)
    hat = np.einsum("ij,ji->i", design, np.linalg.pinv(design))
    loo = (values - design @ coefficients) / np.clip(1 - hat, 1e-9, None)
    return ResponseSurface(
        bounds=tuple(tuple(float(x) for x in pair) for pair in bounds),
        degree=degree,
        coefficients=tuple(float(c) for c in coefficients),
        loo_rms=float(np.sqrt(np.mean(loo**2))),
        max_residual=float(np.max(np.abs(loo))),
    )
