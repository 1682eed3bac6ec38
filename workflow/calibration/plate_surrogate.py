"""The FEM of one plate geometry as a fast function of the calibration parameters.

A design of FEM evaluations (Latin hypercube over the parameters' box) gives a response
surface of log f_r and of log w (the best mode's frequency and mean probe deflection), of
log g (the quasi-static deflection per volt at the centre, |w(0, 0)| / (V Q) at resonance,
what a resonance sweep measures) and, when a scan is to be compared, one surface per scan
point of the FEM's mode pattern there (:func:`~workflow.calibration.measurements.real_pattern`
of the response at resonance, signs aligned to the design's centre point).  Their errors,
used as extra variances in the likelihood, are the leave-one-out residuals of the fits (and,
for f_r, the FEM's own discretisation-error estimate).
"""

from dataclasses import dataclass
from functools import cached_property
from typing import Callable, Sequence

import numpy as np

from workflow.calibration.measurements import real_pattern
from workflow.calibration.parameters import deviated_plate
from workflow.calibration.surrogate import ResponseSurface, fit_response_surface, latin_hypercube
from workflow.models.plate import Plate

Evaluate = Callable[[Sequence[Plate]], list]
"""Plates -> FemResults (the caller binds Q, voltage, accuracy, cache)."""
EvaluateSurfaces = Callable[[Sequence[Plate]], tuple]
"""Plates -> (their FemResults, their :class:`~workflow.models.fem.surface.SurfaceModes`), from one evaluation each
(the caller binds the rest)."""
CENTRE_PROBE = 0
"""Index of the probe at the plate's centre (x = 0, y = 0) among the FEM's 44 [-]."""


@dataclass(frozen=True)
class ShapeSurrogate:
    """The FEM's mode pattern at a scan's points over the calibration parameters.

    Attributes
    ----------
    x, y : tuple of float
        The points [m].
    surfaces : tuple of ResponseSurface
        One per point: the pattern value there [-]; all on the same box and degree (one design).
    """

    x: tuple
    y: tuple
    surfaces: tuple

    def __post_init__(self):
        if not (len(self.x) == len(self.y) == len(self.surfaces) > 0 and np.all(np.isfinite(self.x + self.y))):
            raise ValueError("a shape surrogate needs one finite point (x, y) per surface")
        if len({(s.bounds, s.degree) for s in self.surfaces}) != 1:
            raise ValueError("a shape surrogate's surfaces must share one box and degree")

    @cached_property
    def _coefficients(self) -> np.ndarray:
        """The points' coefficients side by side, shape (n_coefficients, n_points)."""
        return np.column_stack([surface.coefficients for surface in self.surfaces])

    def __call__(self, theta) -> np.ndarray:
        """Pattern at parameter values ``theta`` (..., n), shape (..., n_points) [-] (one basis for every point)."""
        return self.surfaces[0].basis(theta) @ self._coefficients

    @property
    def errors(self) -> np.ndarray:
        """Leave-one-out error of each point's surface [-]."""
        return np.array([surface.loo_rms for surface in self.surfaces])

    def to_dict(self) -> dict:
        return {"x": list(self.x), "y": list(self.y), "surfaces": [s.to_dict() for s in self.surfaces]}

    @classmethod
    def from_dict(cls, data: dict) -> "ShapeSurrogate":
        return cls(tuple(float(v) for v in data["x"]), tuple(float(v) for v in data["y"]),
                   tuple(ResponseSurface.from_dict(s) for s in data["surfaces"]))


@dataclass(frozen=True)
class PlateSurrogate:
    """log f_r and log w of one nominal plate over the calibration parameters.

    Attributes
    ----------
    names : tuple of str
        Parameters, in the order of the inputs.
    log_frequency, log_deflection : ResponseSurface
        ln(f_r / Hz) and ln(w / m) of the best mode [-].
    fem_error : float
        Root mean square of the FEM's relative frequency-error estimates over the design [-]
        (0 when the evaluations carry none).
    evaluations : int
        FEM evaluations of the design [-].
    log_point_deflection : ResponseSurface or None
        ln(g / (m/V)), g the centre's quasi-static deflection per volt (None in older files).
    shape : ShapeSurrogate or None
        The mode pattern at a scan's points (built only for a plate with a scan).
    """

    names: tuple
    log_frequency: ResponseSurface
    log_deflection: ResponseSurface
    fem_error: float
    evaluations: int
    log_point_deflection: ResponseSurface | None = None
    shape: ShapeSurrogate | None = None

    def __post_init__(self):
        surfaces = [self.log_frequency, self.log_deflection, self.log_point_deflection]
        surfaces += [] if self.shape is None else [self.shape.surfaces[0]]
        if any(len(surface.bounds) != len(self.names) for surface in surfaces if surface is not None):
            raise ValueError(f"a plate surrogate's surfaces must take its {len(self.names)} parameters")
        if not (np.isfinite(self.fem_error) and self.fem_error >= 0 and self.evaluations >= 0):
            raise ValueError("a plate surrogate's fem_error and evaluations must be finite and >= 0")

    @property
    def frequency_sigma(self) -> float:
        """Relative standard deviation of a surrogate frequency: fit and FEM errors in quadrature [-]."""
        return float(np.hypot(self.log_frequency.loo_rms, self.fem_error))

    def frequency(self, theta) -> np.ndarray:
        """f_r at parameter values ``theta`` (..., n) [Hz]."""
        return np.exp(self.log_frequency(theta))

    def deflection(self, theta) -> np.ndarray:
        """Best mode's mean probe deflection at ``theta`` (..., n) [m]."""
        return np.exp(self.log_deflection(theta))

    def to_dict(self) -> dict:
        return {
            "names": list(self.names),
            "log_frequency": self.log_frequency.to_dict(),
            "log_deflection": self.log_deflection.to_dict(),
            "fem_error": self.fem_error,
            "evaluations": self.evaluations,
            "log_point_deflection": None if self.log_point_deflection is None else self.log_point_deflection.to_dict(),
            "shape": None if self.shape is None else self.shape.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: dict) -> "PlateSurrogate":
        point, shape = data.get("log_point_deflection"), data.get("shape")
        return cls(
            names=tuple(data["names"]),
            log_frequency=ResponseSurface.from_dict(data["log_frequency"]),
            log_deflection=ResponseSurface.from_dict(data["log_deflection"]),
            fem_error=float(data["fem_error"]),
            evaluations=int(data["evaluations"]),
            log_point_deflection=None if point is None else ResponseSurface.from_dict(point),
            shape=None if shape is None else ShapeSurrogate.from_dict(shape),
        )


def point_deflection_per_volt(result) -> float:
    """g = |w(0, 0)| / (V Q) of a FemResult driven at its best mode's frequency [m/V]."""
    return float(abs(result.probe_model.response(result.frequency, result.q)[CENTRE_PROBE]) / (result.voltage * result.q))


def fem_pattern(result, surface, x, y) -> np.ndarray:
    """:func:`real_pattern` of the FEM's response at its resonance at points (``x``, ``y``) [m] [-]."""
    return real_pattern(surface.deflection(np.asarray(x), np.asarray(y), result.frequency, result.q))


def design_results(results: list) -> tuple:
    """What the design's FemResults give: (log f, log w, log g, relative f errors)."""
    log_f = np.log([r.frequency for r in results])
    log_w = np.log([r.deflection for r in results])
    log_g = np.log([point_deflection_per_volt(r) for r in results])
    errors = np.array([0.0 if r.error is None else r.error.frequency for r in results])
    return log_f, log_w, log_g, errors


def design_patterns(results: list, surfaces: list, scan_points: tuple) -> np.ndarray:
    """(n_design, n_scan) FEM patterns at ``scan_points`` (x, y) [m] of the design's FemResults and SurfaceModes, each
    signed to agree with the first (the box centre)."""
    patterns = np.array([fem_pattern(r, s, *scan_points) for r, s in zip(results, surfaces)])
    return patterns * np.where(patterns @ patterns[0] < 0, -1.0, 1.0)[:, None]


def evaluate_together(evaluate: Callable[[list], list], groups: Sequence[list]) -> list:
    """``[evaluate(group) for group in groups]`` from one call on all their plates (one batch keeps a pool's workers
    busy across the groups); no call when there is no plate."""
    plates = [plate for group in groups for plate in group]
    results = iter(evaluate(plates) if plates else ())
    return [[next(results) for _ in group] for group in groups]


def surrogate_design(plate: Plate, names: Sequence[str], bounds: np.ndarray, n_points: int, seed: int) -> tuple:
    """(points, plates): the Latin hypercube of ``n_points`` in ``bounds`` (n, 2) [SI] and the nominal ``plate``
    deviated to each point (:func:`~workflow.calibration.parameters.deviated_plate`)."""
    points = latin_hypercube(n_points, bounds, seed)
    return points, [deviated_plate(plate, names, theta) for theta in points]


def fit_plate_surrogate(names: Sequence[str], bounds: np.ndarray, degree: int, points: np.ndarray, results: list,
                        surfaces: list | None = None, scan_points: tuple | None = None) -> PlateSurrogate:
    """The response surfaces of degree ``degree`` through the FemResults of the design ``points`` (and, with the
    SurfaceModes ``surfaces`` and ``scan_points`` ((x, y) arrays [m]), a :class:`ShapeSurrogate`)."""
    log_f, log_w, log_g, errors = design_results(results)
    shape = None
    if scan_points is not None:
        patterns = design_patterns(results, surfaces, scan_points)
        shape = ShapeSurrogate(tuple(float(v) for v in scan_points[0]), tuple(float(v) for v in scan_points[1]),
                               tuple(fit_response_surface(points, column, bounds, degree) for column in patterns.T))
    return PlateSurrogate(
        names=tuple(names),
        log_frequency=fit_response_surface(points, log_f, bounds, degree),
        log_deflection=fit_response_surface(points, log_w, bounds, degree),
        fem_error=float(np.sqrt(np.mean(errors**2))),
        evaluations=len(points),
        log_point_deflection=fit_response_surface(points, log_g, bounds, degree),
        shape=shape,
    )


def build_plate_surrogate(
    plate: Plate, names: Sequence[str], bounds: np.ndarray, evaluate: Evaluate, n_points: int, degree: int, seed: int,
    evaluate_surfaces: EvaluateSurfaces | None = None, scan_points: tuple | None = None,
) -> PlateSurrogate:
    """Response surfaces of the nominal ``plate`` over ``bounds`` from ``n_points`` FEM evaluations.

    Parameters
    ----------
    plate : Plate
        Nominal geometry and materials [m].
    names : sequence of str
        Calibration parameters (:func:`~workflow.calibration.parameters.deviated_plate`).
    bounds : array (n, 2)
        Box of the design [SI].
    evaluate : callable
        Plates -> FemResults.
    n_points, degree, seed : int
        Design size, polynomial degree (1 or 2), Latin hypercube seed.
    evaluate_surfaces : callable, optional
        Plates -> (FemResults, SurfaceModes); with ``scan_points`` ((x, y) arrays [m]) the design is evaluated with
        it instead of ``evaluate`` and a :class:`ShapeSurrogate` is built too.
    """
    points, plates = surrogate_design(plate, names, bounds, n_points, seed)
    results, surfaces = (evaluate(plates), None) if scan_points is None else evaluate_surfaces(plates)
    return fit_plate_surrogate(names, bounds, degree, points, results, surfaces, scan_points)
