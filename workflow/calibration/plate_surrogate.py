"""The FEM of one plate geometry as a fast function of the calibration parameters.

A design of FEM evaluations (Latin hypercube over the parameters' box) gives a response
surface of log f_r and of log w (the best mode's frequency and mean probe deflection), of
log g (the quasi-static deflection per volt at the centre, |w(0, 0)| / (V Q) at resonance,
what a resonance sweep measures) and, when a scan is to be compared, one surface per scan
point of the FEM's mode pattern there (:func:`~workflow.calibration.measurements.real_pattern`
of the response at resonance, signs aligned to the design's centre point).  Their errors,
used as extra variances in the likelihood, are the leave-one-out residuals of the fits (and,
for f_r, the FEM's own discretisation-error estimate).

A design is evaluated to the FEM accuracy at every point or, in a two-level design (:class:`DesignFem`), on one
coarse mesh level at every point and to the accuracy at two anchors that set the outputs' level: a third to a fifth
of the time for the same accuracy (docs/calibration.md, "Two-level designs").
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
    coarse_level : int or None
        The level of a two-level design's points (:class:`DesignFem`), None when every point was evaluated to the
        accuracy.
    """

    names: tuple
    log_frequency: ResponseSurface
    log_deflection: ResponseSurface
    fem_error: float
    evaluations: int
    log_point_deflection: ResponseSurface | None = None
    shape: ShapeSurrogate | None = None
    coarse_level: int | None = None

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
            "coarse_level": self.coarse_level,
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
            coarse_level=None if data.get("coarse_level") is None else int(data["coarse_level"]),
        )


def point_deflection_per_volt(result) -> float:
    """g = |w(0, 0)| / (V Q) of a FemResult driven at its best mode's frequency [m/V]."""
    return float(abs(result.probe_model.response(result.frequency, result.q)[CENTRE_PROBE]) / (result.voltage * result.q))


def fem_pattern(result, surface, x, y) -> np.ndarray:
    """:func:`real_pattern` of the FEM's response at its resonance at points (``x``, ``y``) [m] [-]."""
    return real_pattern(surface.deflection(np.asarray(x), np.asarray(y), result.frequency, result.q))


def design_patterns(results: list, surfaces: list, scan_points: tuple,
                    references: np.ndarray | None = None) -> np.ndarray:
    """(n_design, n_scan) FEM patterns at ``scan_points`` (x, y) [m] of the design's FemResults and SurfaceModes, each
    signed to agree with its row of ``references`` (n_design, n_scan) (default: every one with the first pattern, the
    box centre's)."""
    patterns = np.array([fem_pattern(r, s, *scan_points) for r, s in zip(results, surfaces)])
    references = patterns[:1] if references is None else references
    return patterns * np.where(np.sum(patterns * references, axis=1) < 0, -1.0, 1.0)[:, None]


def evaluate_together(evaluate: Callable[[list], list], groups: Sequence[list]) -> list:
    """``[evaluate(group) for group in groups]`` from one call on all their plates (one batch keeps a pool's workers
    busy across the groups); no call when there is no plate."""
    plates = [plate for group in groups for plate in group]
    results = iter(evaluate(plates) if plates else ())
    return [[next(results) for _ in group] for group in groups]


@dataclass(frozen=True)
class SurrogateDesign:
    """The FEM design of one surrogate.

    Attributes
    ----------
    points : numpy.ndarray
        (n, k) Latin hypercube in ``bounds``, the box centre first [SI].
    bounds : numpy.ndarray
        (k, 2) box [SI].
    plates : tuple of Plate
        The plate at each point [m].
    scan_points : tuple or None
        (x, y) arrays [m] where a mode pattern is wanted (a plate with a scan), else None.
    """

    points: np.ndarray
    bounds: np.ndarray
    plates: tuple
    scan_points: tuple | None = None


def surrogate_design(plate: Plate, names: Sequence[str], bounds: np.ndarray, n_points: int, seed: int,
                     scan_points: tuple | None = None) -> SurrogateDesign:
    """The Latin hypercube of ``n_points`` in ``bounds`` (n, 2) [SI] and the nominal ``plate`` deviated to each point
    (:func:`~workflow.calibration.parameters.deviated_plate`)."""
    points = latin_hypercube(n_points, bounds, seed)
    plates = tuple(deviated_plate(plate, names, theta) for theta in points)
    return SurrogateDesign(points, np.asarray(bounds, dtype=float), plates, scan_points)


@dataclass(frozen=True)
class DesignValues:
    """What a design's FEM evaluations give at its points.

    Attributes
    ----------
    log_frequency, log_deflection, log_point_deflection : numpy.ndarray
        (n,) ln f_r, ln w and ln g (:func:`point_deflection_per_volt`) [-].
    patterns : numpy.ndarray or None
        (n, n_scan) mode patterns at the scan points (signs aligned to the centre's) [-].
    fem_error : float
        Relative frequency error of the values [-]: the root mean square of the accurate evaluations' error estimates,
        in a two-level design in quadrature with the spread of the anchors' corrections (:class:`DesignFem`).
    evaluations : int
        FEM evaluations of the design, both levels [-].
    coarse_level : int or None
        The level every point was evaluated on in a two-level design, else None.
    """

    log_frequency: np.ndarray
    log_deflection: np.ndarray
    log_point_deflection: np.ndarray
    patterns: np.ndarray | None
    fem_error: float
    evaluations: int
    coarse_level: int | None = None


def _columns(results: list, surfaces: list | None, scan_points: tuple | None, references=None) -> tuple:
    """(outputs (n, 3 [+ n_scan]): ln f, ln w, ln g [, pattern signed as :func:`design_patterns` with ``references``],
    the relative frequency-error estimates (n,))."""
    columns = [np.log([r.frequency for r in results]), np.log([r.deflection for r in results]),
               np.log([point_deflection_per_volt(r) for r in results])]
    outputs = np.column_stack(columns)
    if scan_points is not None:
        outputs = np.hstack([outputs, design_patterns(results, surfaces, scan_points, references)])
    errors = np.array([0.0 if r.error is None else r.error.frequency for r in results])
    return outputs, errors


def _design_values(outputs: np.ndarray, fem_error: float, evaluations: int, coarse_level: int | None = None
                   ) -> DesignValues:
    """:class:`DesignValues` from the columns of :func:`_columns` (patterns where there are more than three)."""
    return DesignValues(outputs[:, 0], outputs[:, 1], outputs[:, 2], outputs[:, 3:] if outputs.shape[1] > 3 else None,
                        float(fem_error), evaluations, coarse_level)


def anchor_indices(points: np.ndarray, bounds: np.ndarray, count: int) -> list:
    """The anchors of a design: its first point (a Latin hypercube's box centre), then the points farthest from it in
    the box's unit coordinates, ``count`` in all."""
    unit = (np.asarray(points) - bounds[:, 0]) / (bounds[:, 1] - bounds[:, 0])
    distance = np.sum((unit - unit[0]) ** 2, axis=1)
    farthest = [int(k) for k in np.argsort(-distance, kind="stable") if k != 0]
    return [0, *farthest][:min(count, len(points))]


TWO_LEVEL_COARSE = 3
"""Level (polynomial degree) every point of a two-level design is evaluated on [-]; docs/calibration.md, "Two-level
designs", gives its measured error and how little that error varies over a surrogate's box."""
ANCHORS = 2
"""Points of a two-level design also evaluated to the accuracy: the box centre and the point farthest from it [-]."""


@dataclass(frozen=True)
class DesignFem:
    """How surrogate designs are evaluated (docs/calibration.md, "Two-level designs").

    With ``coarse`` (a two-level design) every point is evaluated on one fixed low level of the geometry-following
    mesh and :data:`ANCHORS` of them (the centre and the point farthest from it) also to the accuracy; each output is
    the coarse value plus the anchors' mean difference (an anchor's pattern signed to agree with its own coarse one).
    A surrogate needs the outputs' variation over its box, which the coarse level gives to a small fraction of its own
    error (that error varies little over a box), and their level, which the anchors give; the frequency differences'
    standard deviation s enters the design's error as s sqrt(1 + 1/m) (a point's error about the mean of m anchors).
    Without ``coarse`` every point is evaluated to the accuracy.

    Attributes
    ----------
    accurate : Evaluate
        Plates -> FemResults to the accuracy wanted.
    accurate_surfaces : EvaluateSurfaces or None
        The same with the top-face modes (needed for a design with scan points).
    coarse, coarse_surfaces : Evaluate, EvaluateSurfaces or None
        The same on the coarse level.
    coarse_level : int or None
        That level [-].
    """

    accurate: Evaluate
    accurate_surfaces: EvaluateSurfaces | None = None
    coarse: Evaluate | None = None
    coarse_surfaces: EvaluateSurfaces | None = None
    coarse_level: int | None = None

    def values(self, designs: Sequence[SurrogateDesign]) -> list:
        """The :class:`DesignValues` of each design, every level's evaluations of all designs in one batch."""
        designs = list(designs)
        everything = [None] * len(designs)
        if self.coarse is None:
            found = _evaluate(self.accurate, self.accurate_surfaces, designs, everything)
            return [_one_level(d, *pair) for d, pair in zip(designs, found)]
        anchors = [anchor_indices(d.points, d.bounds, ANCHORS) for d in designs]
        rough = _evaluate(self.coarse, self.coarse_surfaces, designs, everything)
        fine = _evaluate(self.accurate, self.accurate_surfaces, designs, anchors)
        return [self._two_level(d, k, r, f) for d, k, r, f in zip(designs, anchors, rough, fine)]

    def _two_level(self, design: SurrogateDesign, anchors: list, rough: tuple, fine: tuple) -> DesignValues:
        coarse, _ = _columns(*rough, design.scan_points)
        references = None if design.scan_points is None else coarse[anchors, 3:]
        accurate, errors = _columns(*fine, design.scan_points, references)
        corrections = accurate - coarse[anchors]
        spread = float(np.std(corrections[:, 0], ddof=1)) if len(anchors) > 1 else 0.0
        fem_error = np.hypot(np.sqrt(np.mean(errors**2)), spread * np.sqrt(1 + 1 / len(anchors)))
        return _design_values(coarse + corrections.mean(axis=0), fem_error, len(design.plates) + len(anchors),
                              self.coarse_level)


def _one_level(design: SurrogateDesign, results: list, surfaces: list | None) -> DesignValues:
    """The values of a design evaluated to the accuracy at every point."""
    outputs, errors = _columns(results, surfaces, design.scan_points)
    return _design_values(outputs, np.sqrt(np.mean(errors**2)), len(design.plates))


def _evaluate(evaluate: Evaluate, evaluate_surfaces: EvaluateSurfaces | None, designs: list, subsets: list) -> list:
    """(results, surfaces or None) of each design's plates (those at the indices ``subsets[k]``, all where None): the
    designs without scan points in one batch of ``evaluate``, those with in one of ``evaluate_surfaces``."""
    groups = [list(d.plates) if keep is None else [d.plates[i] for i in keep] for d, keep in zip(designs, subsets)]
    plain = [k for k, d in enumerate(designs) if d.scan_points is None]
    scanned = [k for k, d in enumerate(designs) if d.scan_points is not None]
    found = {k: (results, None) for k, results in zip(plain, evaluate_together(evaluate, [groups[k] for k in plain]))}
    if scanned:
        if evaluate_surfaces is None:
            raise ValueError("a design with scan points needs an evaluation with the top-face modes")
        pairs = evaluate_together(lambda batch: list(zip(*evaluate_surfaces(batch))), [groups[k] for k in scanned])
        found.update((k, tuple(map(list, zip(*pair)))) for k, pair in zip(scanned, pairs))
    return [found[k] for k in range(len(designs))]


def fit_plate_surrogate(names: Sequence[str], design: SurrogateDesign, degree: int,
                        values: DesignValues) -> PlateSurrogate:
    """The response surfaces of degree ``degree`` through a design's values (and, where it has scan points, a
    :class:`ShapeSurrogate`)."""
    points, bounds = design.points, design.bounds
    shape = None
    if values.patterns is not None:
        x, y = design.scan_points
        shape = ShapeSurrogate(tuple(float(v) for v in x), tuple(float(v) for v in y),
                               tuple(fit_response_surface(points, column, bounds, degree)
                                     for column in values.patterns.T))
    return PlateSurrogate(
        names=tuple(names),
        log_frequency=fit_response_surface(points, values.log_frequency, bounds, degree),
        log_deflection=fit_response_surface(points, values.log_deflection, bounds, degree),
        fem_error=values.fem_error,
        evaluations=values.evaluations,
        log_point_deflection=fit_response_surface(points, values.log_point_deflection, bounds, degree),
        shape=shape,
        coarse_level=values.coarse_level,
    )


def build_plate_surrogate(plate: Plate, names: Sequence[str], bounds: np.ndarray, fem: DesignFem, n_points: int,
                          degree: int, seed: int, scan_points: tuple | None = None) -> PlateSurrogate:
    """Response surfaces of the nominal ``plate`` over ``bounds`` from a design of ``n_points``.

    Parameters
    ----------
    plate : Plate
        Nominal geometry and materials [m].
    names : sequence of str
        Calibration parameters (:func:`~workflow.calibration.parameters.deviated_plate`).
    bounds : array (n, 2)
        Box of the design [SI].
    fem : DesignFem
        How the design is evaluated.
    n_points, degree, seed : int
        Design size, polynomial degree (1 or 2), Latin hypercube seed.
    scan_points : tuple, optional
        (x, y) arrays [m]: a :class:`ShapeSurrogate` of the mode pattern there is built too.
    """
    design = surrogate_design(plate, names, bounds, n_points, seed, scan_points)
    (values,) = fem.values([design])
    return fit_plate_surrogate(names, design, degree, values)
