"""Space-mapping optimisation from the fine responses only: the FEM optimum from a few FEM evaluations (docs/fem.md).

With the FEM's design sensitivities, :mod:`workflow.gradient_space_mapping` needs fewer
(``optimise_fem`` uses it for the plain FEM); this search serves fine models without them
(the FEM with Q(v)) and holds what both share (parameter extraction, results, counting).

The coarse model (the beam) is cheap, the fine model (the FEM) is not.  Both are plate
models; the design variables are x = (lambda, h_i).

Where the optimum is.  The deflection grows with lambda at fixed h_i (a longer, softer
plate), so the constrained optimum lies on the fine model's resonance curve
f_f(lambda, h_i) = f_min (or on the lambda bound), and the search is one-dimensional along
that curve, parametrised by h_i.

What is mapped.  For every fine point x_k = (lambda_k, h_k) the **parameter extraction**
finds the coarse wavelength with the same frequency at the same thickness,
f_c(lambda^_k, h_k) = f_f(x_k), a 1-D root solve on the coarse model.  The input mapping
P(lambda, h_i) = (m(h_i) lambda, h_i) is described by the wavelength ratio
m_k = lambda^_k / lambda_k, and what the mapping leaves unexplained by the deflection ratio
rho_k = w_f(x_k) / w_c(lambda^_k, h_k).  The surrogate is the coarse model seen through the
mapping: its f_min curve is lambda_s(h) = lambda_c(h; f_min) / m(h) and its deflection along
that curve rho(h) w_c(lambda_c(h; f_min), h).

How the mapping is updated.  ln m and ln rho are quadratics in h_i (plus a slope in
ln(f / f_min) for points off the curve, about -0.7 for rho on the FEM) fitted by weighted
least squares to all fine points, centred on the anchor: the best feasible clean point, or
while there is none the clean point nearest the f_min curve (below the curve a point deflects
more only because its frequency is lower).  With two points this is the
Broyden (secant) update of the mapping; from three on it is a local quadratic, because
the deflection ratio bends along the curve as much as the beam's deflection does or more
(FEM, h_p = 1 mm: d2 ln rho/dh2 = -0.9 /mm2 against -0.3 /mm2 for the beam; near a
transverse mode far more), so a Broyden-updated linear mapping cannot place the peak.
Weights fall with the distance from the centre (:data:`LOCALITY`), with the distance
from the curve and with mode mixing.  Beyond the thicknesses seen, ln m and ln rho continue
along their tangent: a fitted curvature is not extrapolated.  The wavelength of each new
point comes from ln m refitted around its own thickness, so fine points there count most
(two at the same h_i make a secant in frequency).

Why not the textbook iteration.  Aggressive space mapping solves P(x) = z* for the coarse
optimum z*.  With the frequency constraint active, P(x) = z* only puts x on the right
curve; where along it the fine deflection peaks is fine-model information (the deflection
ratio above) that P(x) = z* ignores.

Transverse modes.  Where the working mode mixes with a transverse one (indicator above
:data:`TRANSVERSE_THRESHOLD`), the fine deflection dips in a narrow band of h_i that no smooth
correction describes.  Such points still count as evaluations and as candidates, but they
do not shape the mapping, and once the mapping is determined the surrogate proposes no
point within :data:`NEAR_FRACTION` of the range of them (unless nothing else is within
reach); the search steps past them (for h_p = 2 mm the beam optimum lies in such a band
and the FEM optimum 0.8 mm beyond it).

Steps.  The first fine point is the coarse optimum z*.  Each next point maximises the
surrogate within a trust interval of h_i around the anchor; while fewer than
three thicknesses determine the mapping and that maximiser falls next to a point already
evaluated, an exploring point :data:`SPREAD_FRACTION` of the h_i range away is taken
instead.  When the surrogate promises less than ``gain_tolerance`` over the best feasible
fine point, or only a step shorter than ``tolerance``, the search ends once fine points
near the curve bracket the answer within :data:`LOCAL_FRACTION` of the range on each side
(else it evaluates the missing bracket): transverse modes bend the FEM deflection on a
0.1 mm scale, and only nearby fine points show it.  The answer is always a fine point.

Measured (``python bench/bench_space_mapping.py 0.5 1 2 [--width-mm B]``, b = 40, 49, 55, 70 mm):
6 to 12 FEM evaluations against 12 to 54 for the direct run, within 0.1 mm of its optimum.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workflow.errors import InfeasibleError
from workflow.optimise.maps import TRANSVERSE_THRESHOLD
from workflow.optimise.problem import DesignProblem, Optimum, maximise_deflection
from workflow.units import MM

SPREAD_FRACTION = 0.16
"""Exploring step in h_i, as a fraction of its range (0.4 mm of 0.5-3 mm) [-]."""
TRUST_FRACTION = 0.32
"""Largest move in h_i from the best clean point once the mapping's curvature is known, as a
fraction of its range [-]; halved after each surrogate step that brings no gain (before, the
reach is :data:`SPREAD_FRACTION`)."""
NEAR_FRACTION = 0.04
"""Proposals closer than this fraction of the h_i range to an evaluated point add little [-]."""
LOCAL_FRACTION = 0.024
"""Half-width, as a fraction of the h_i range, of the bracket of fine points an optimum needs (0.06 mm) [-]."""
BRACKET_WINDOW = (0.25, 1.5)
"""Distances, in units of the bracket half-width, at which a fine point brackets an optimum [-]."""
NEAR_CURVE = 5e-3
"""Relative distance of f from f_min within which a fine point brackets the optimum [-]."""
CURVE_POINTS = 1001
"""h_i grid on which the surrogate is maximised [-] (2.5 um steps on 0.5-3 mm)."""
BISECTION_STEPS = 48
"""Bisection steps of the coarse wavelength at a given frequency [-] (1e-12 m)."""
FREQUENCY_TOLERANCE = 2e-4
"""Relative shortfall of f below f_min accepted at a fine point [-] (5 Hz at 25 kHz)."""
MAPPING_DEGREE = 2
"""Highest degree of the polynomials ln m(h_i), ln rho(h_i) [-]."""
MAPPING_NOISE = 1e-4
"""Scatter of ln m, ln rho about their smooth trends at a clean point on the curve [-]."""
MIXING_DEPRESSION = 10.0
"""ln rho lies about this times t^2 below its trend at a mode of transverse indicator t [-]
(FEM, h_p = 2 mm: t = 0.047, 0.061, 0.091 -> 0.5 %, 2.2 %, 8 %)."""
LOCALITY = 10.0
"""Growth of the quadratic's error with the cube of the distance from its centre [1/mm^3]: transverse
modes bend the deflection ratio on a scale of 0.1 mm (FEM, h_p = 0.5 mm: ln rho rises 0.3 % from
h_i = 0.5 to 0.53 mm and falls 3 % by 0.6 mm)."""
OFF_CURVE_SLOPE_PRIOR = 1.0
"""Prior scale of d ln rho / d ln(f / f_min) at fixed h_i [-] (fitted: -0.7 on the FEM at h_p = 0.5 and 2 mm)."""
OFF_CURVE_NOISE = 0.2
"""Scatter of ln m, ln rho about their trends per unit of |ln(f / f_min)| [-]: both are modelled as
functions of h_i alone, which holds along the f_min curve; points off it (the coarse optimum) count less."""

FineModel = Callable
"""fine(plate) -> (deflection [m], frequency [Hz]) or (deflection, frequency, transverse indicator [-])."""


@dataclass(frozen=True)
class SpaceMappingStep:
    """One fine evaluation and its parameter extraction.

    Attributes
    ----------
    design : ndarray
        (lambda, h_i) [m].
    deflection, frequency : float
        Fine response [m], [Hz].
    transverse_indicator : float
        Of the fine model's working mode [-] (0 when the fine model does not report it).
    extracted_wavelength : float
        Coarse lambda with the fine frequency at the same h_i [m].
    coarse_deflection : float
        Coarse deflection at (extracted_wavelength, h_i) [m].
    """

    design: np.ndarray
    deflection: float
    frequency: float
    transverse_indicator: float
    extracted_wavelength: float
    coarse_deflection: float

    @property
    def thickness_mm(self) -> float:
        return float(self.design[1] / MM)

    @property
    def wavelength_ratio(self) -> float:
        """m = extracted / fine wavelength [-]."""
        return float(self.extracted_wavelength / self.design[0])

    @property
    def deflection_ratio(self) -> float:
        """rho = fine / coarse deflection at the extracted point [-]."""
        return float(self.deflection / self.coarse_deflection)

    @property
    def mixed(self) -> bool:
        return self.transverse_indicator > TRANSVERSE_THRESHOLD


@dataclass(frozen=True)
class CurveMapping:
    """ln m and ln rho as polynomials in (h_i - centre) / scale.

    Attributes
    ----------
    wavelength_coefficients, deflection_coefficients : ndarray
        Ascending powers [-].
    centre_mm, scale_mm : float
        Of the polynomial variable [mm].
    span_mm : tuple of float
        h_i range of the fitted steps [mm]; beyond it ln m and ln rho continue along their
        tangent at its edge (a fitted curvature is not extrapolated).
    """

    wavelength_coefficients: np.ndarray
    deflection_coefficients: np.ndarray
    centre_mm: float
    scale_mm: float
    span_mm: tuple = (-np.inf, np.inf)

    def _logarithm(self, thickness_mm, coefficients) -> np.ndarray:
        """The polynomial inside the span, its tangent at the nearer edge outside [-]."""
        thickness_mm = np.asarray(thickness_mm, dtype=float)
        edge = (np.clip(thickness_mm, *self.span_mm) - self.centre_mm) / self.scale_mm
        beyond = (thickness_mm - self.centre_mm) / self.scale_mm - edge
        polynomial = np.polynomial.polynomial
        return polynomial.polyval(edge, coefficients) + beyond * polynomial.polyval(edge, polynomial.polyder(coefficients))

    def wavelength_ratio(self, thickness_mm) -> np.ndarray:
        """m(h_i) [-]."""
        return np.exp(self._logarithm(thickness_mm, self.wavelength_coefficients))

    def deflection_ratio(self, thickness_mm) -> np.ndarray:
        """rho(h_i) [-]."""
        return np.exp(self._logarithm(thickness_mm, self.deflection_coefficients))

    @property
    def determined(self) -> int:
        """Degree of the deflection ratio [-] (2: its curvature is known)."""
        return len(self.deflection_coefficients) - 1


@dataclass(frozen=True)
class SpaceMappingResult:
    """Outcome of :func:`space_mapping_optimum`.

    Attributes
    ----------
    optimum : Optimum
        The best feasible fine point with its fine response (``evaluations`` = fine evaluations).
    coarse_optimum : Optimum
        The coarse model's optimum z*, the first fine point.
    trajectory : tuple of SpaceMappingStep
        Every fine evaluation in order (:class:`~workflow.gradient_space_mapping.GradientStep`
        for the search with sensitivities).
    fine_evaluations, coarse_evaluations : int
        Geometries evaluated by each model.
    mapping : CurveMapping or None
        The last fitted mapping (None for the search with sensitivities).
    converged : bool
        Whether the surrogate, fully determined, promised no further gain.
    """

    optimum: Optimum
    coarse_optimum: Optimum
    trajectory: tuple[SpaceMappingStep, ...]
    fine_evaluations: int
    coarse_evaluations: int
    mapping: CurveMapping | None
    converged: bool


class CountedModel:
    """A plate model that counts the geometries it evaluates."""

    def __init__(self, model):
        self.model, self.evaluations = model, 0

    def __call__(self, plate):
        self.evaluations += int(np.prod(plate.batch_shape, dtype=int))
        return self.model(plate)


def search_result(
    steps, answer, problem: DesignProblem, fine, coarse, coarse_optimum, status: str, mapping, converged: bool, what="design"
) -> SpaceMappingResult:
    """The :class:`SpaceMappingResult` of a search whose answer is the fine step ``answer``.

    ``fine`` and ``coarse`` are the :class:`CountedModel` wrappers; ``what`` names the kind of
    design looked for in the error.

    Raises
    ------
    InfeasibleError
        When ``answer`` is None (no fine point reached f_min).
    """
    if answer is None:
        closest = max(steps, key=lambda s: s.frequency)
        raise InfeasibleError(
            f"space mapping found no {what} with f_r >= {problem.min_frequency / 1e3:g} kHz in "
            f"{fine.evaluations} fine evaluations (highest {closest.frequency / 1e3:.3f} kHz at lambda "
            f"{closest.design[0] / MM:.3f} mm, h_i {closest.thickness_mm:.3f} mm); widen the bounds or lower f_min"
        )
    optimum = Optimum(
        plate=problem.plate(float(answer.design[0]), float(answer.design[1])),
        deflection=answer.deflection,
        frequency=answer.frequency,
        evaluations=fine.evaluations,
        constraint_active=bool(abs(answer.frequency / problem.min_frequency - 1) <= FREQUENCY_TOLERANCE),
        status=status,
    )
    return SpaceMappingResult(
        optimum, coarse_optimum, tuple(steps), fine.evaluations, coarse.evaluations, mapping, converged
    )


def coarse_wavelength(coarse, problem: DesignProblem, thickness, frequency) -> np.ndarray:
    """Wavelength [m] at which the coarse f_r equals ``frequency`` [Hz] at each h_i [m].

    Bisection on a wide bracket (f_r falls as lambda grows), vectorised over the inputs.
    """
    thickness, frequency = np.broadcast_arrays(np.asarray(thickness, dtype=float), np.asarray(frequency, dtype=float))
    low = np.full(thickness.shape, problem.wavelength_range[0] / 2)
    high = np.full(thickness.shape, problem.wavelength_range[1] * 2)
    for _ in range(BISECTION_STEPS):
        middle = 0.5 * (low + high)
        _, found = coarse(problem.plate(middle, thickness))
        above = found > frequency
        low, high = np.where(above, middle, low), np.where(above, high, middle)
    return 0.5 * (low + high)


def _evaluate(fine, coarse, problem: DesignProblem, design: np.ndarray) -> SpaceMappingStep:
    """One fine evaluation at (lambda, h_i) [m] and its parameter extraction."""
    plate = problem.plate(np.atleast_1d(design[0]), np.atleast_1d(design[1]))
    response = [float(np.ravel(a)[0]) for a in fine(plate)]
    deflection, frequency = response[:2]
    indicator = response[2] if len(response) > 2 else 0.0
    extracted = float(coarse_wavelength(coarse, problem, design[1], frequency))
    coarse_deflection, _ = coarse(problem.plate(np.atleast_1d(extracted), np.atleast_1d(design[1])))
    return SpaceMappingStep(np.asarray(design, float), deflection, frequency, indicator, extracted, float(np.ravel(coarse_deflection)[0]))


def fit_mapping(
    steps, problem: DesignProblem, anchor: SpaceMappingStep, scale_mm: float, centre_mm: float | None = None
) -> CurveMapping:
    """ln m and ln rho fitted to the clean steps (all when none is) by weighted least squares around ``centre_mm``.

    The degree is at most the number of distinct h_i less one.  A point counts less the
    more its mode mixes beyond the anchor's (:data:`MIXING_DEPRESSION`), the farther it
    lies off the f_min curve (:data:`OFF_CURVE_NOISE`) and the farther from the centre
    (``centre_mm``, default the anchor's h_i) in h_i (:data:`LOCALITY`: a quadratic
    describes the ratios only locally).
    """
    centre_mm = anchor.thickness_mm if centre_mm is None else centre_mm
    steps = [s for s in steps if not s.mixed] or list(steps)
    thickness = np.array([s.thickness_mm for s in steps])
    distinct = len(np.unique(np.round(thickness / scale_mm, 3)))
    degree = min(MAPPING_DEGREE, distinct - 1)
    offset = np.log([s.frequency / problem.min_frequency for s in steps])
    scatter = np.array(
        [
            MAPPING_NOISE
            + MIXING_DEPRESSION * max(0.0, s.transverse_indicator**2 - anchor.transverse_indicator**2)
            + OFF_CURVE_NOISE * abs(v)
            + LOCALITY * abs(s.thickness_mm - centre_mm) ** 3
            for s, v in zip(steps, offset)
        ]
    )
    # columns 1, u, ..., u^degree, then ln(f / f_min); one prior row keeps the off-curve slope near 0
    basis = np.column_stack([np.vander((thickness - centre_mm) / scale_mm, degree + 1, increasing=True), offset])
    prior = np.zeros(degree + 2)
    prior[-1] = 1 / OFF_CURVE_SLOPE_PRIOR

    def fit(values):
        rows = np.vstack([basis / scatter[:, None], prior])
        solution, *_ = np.linalg.lstsq(rows, np.append(values / scatter, 0.0), rcond=None)
        return solution[:-1]

    return CurveMapping(
        fit(np.log([s.wavelength_ratio for s in steps])),
        fit(np.log([s.deflection_ratio for s in steps])),
        centre_mm,
        scale_mm,
        (float(thickness.min()), float(thickness.max())),
    )


@dataclass(frozen=True)
class _CoarseCurve:
    """The coarse f_min curve on the h_i grid: thickness [mm], wavelength [m]."""

    thickness_mm: np.ndarray
    wavelength: np.ndarray

    def fine_wavelength(self, mapping: CurveMapping, thickness_mm) -> np.ndarray:
        """lambda_c(h_i; f_min) / m(h_i): the surrogate's f_min curve at ``thickness_mm`` [m] (not clipped to the bounds)."""
        return np.interp(thickness_mm, self.thickness_mm, self.wavelength) / mapping.wavelength_ratio(thickness_mm)

    def predicted_deflection(self, coarse, problem: DesignProblem, mapping: CurveMapping) -> np.ndarray:
        """The surrogate's deflection [m] along its f_min curve on the grid; NaN where lambda is below its bound."""
        ratio = mapping.wavelength_ratio(self.thickness_mm)
        fine_wavelength = self.fine_wavelength(mapping, self.thickness_mm)
        feasible = fine_wavelength >= problem.wavelength_range[0]
        fine_wavelength = np.clip(fine_wavelength, *problem.wavelength_range)
        deflection, _ = coarse(problem.plate(fine_wavelength * ratio, self.thickness_mm * MM))
        return np.where(feasible, deflection * mapping.deflection_ratio(self.thickness_mm), np.nan)


def _placed(steps, problem: DesignProblem, anchor, curve: _CoarseCurve, thickness_mm: float, scale_mm: float) -> np.ndarray:
    """The design (lambda, h_i) [m] on the surrogate's f_min curve at ``thickness_mm``.

    The wavelength ratio is fitted around that thickness, so the fine steps there (a secant
    in frequency when one sits at the same h_i) count most.
    """
    mapping = fit_mapping(steps, problem, anchor, scale_mm, thickness_mm)
    wavelength = float(np.clip(curve.fine_wavelength(mapping, thickness_mm), *problem.wavelength_range))
    return np.array([wavelength, thickness_mm * MM])


def reaches_min_frequency(step, problem: DesignProblem) -> bool:
    """Whether a fine step reached f_min within :data:`FREQUENCY_TOLERANCE` [-]."""
    return step.frequency >= problem.min_frequency * (1 - FREQUENCY_TOLERANCE)


def _best(steps, problem: DesignProblem) -> SpaceMappingStep | None:
    """The feasible clean step of largest deflection (feasible mixed steps when none is clean)."""
    feasible = [s for s in steps if reaches_min_frequency(s, problem)]
    pool = [s for s in feasible if not s.mixed] or feasible
    return max(pool, key=lambda s: s.deflection) if pool else None


def _anchor(steps, problem: DesignProblem) -> SpaceMappingStep:
    """Where the mapping is centred: the best feasible clean step, else the clean step nearest the f_min curve, else the first.

    Deflections of steps below the curve are not compared: the lower their frequency, the
    longer and softer the plate and the larger the deflection.
    """
    clean = [s for s in steps if not s.mixed]
    best = _best(clean, problem)
    if best is not None:
        return best
    return min(clean, key=lambda s: abs(np.log(s.frequency / problem.min_frequency))) if clean else steps[0]


def _exploring_thickness(steps, anchor_mm: float, spread_mm: float, near_mm: float, bounds_mm, feasible) -> float | None:
    """h_i [mm] a spread (else half, a quarter of one) from the anchor, at least ``near_mm`` from every point evaluated.

    The side towards mid-range is tried first (the surrogate cannot tell the sides apart yet:
    the anchor is the coarse optimum, or the mapping has no slope); thicknesses where
    ``feasible(h_i)`` is False are skipped; None when no candidate is left.
    """
    evaluated = np.array([s.thickness_mm for s in steps])
    sign = 1 if anchor_mm <= np.mean(bounds_mm) else -1
    for fraction in (1, 0.5, 0.25):
        for side in (sign, -sign):
            thickness = anchor_mm + side * fraction * spread_mm
            if (
                bounds_mm[0] <= thickness <= bounds_mm[1]
                and np.min(np.abs(evaluated - thickness)) >= 0.999 * near_mm
                and feasible(thickness)
            ):
                return float(thickness)
    return None


def _on_design_curve(step: SpaceMappingStep, problem: DesignProblem) -> bool:
    """Whether a clean step lies on the fine f_min curve (within :data:`NEAR_CURVE`) or on the lambda upper bound."""
    on_bound = step.design[0] >= problem.wavelength_range[1] * (1 - 1e-9)
    return not step.mixed and (on_bound or abs(np.log(step.frequency / problem.min_frequency)) <= NEAR_CURVE)


def _unbracketed_side(steps, problem: DesignProblem, thickness_mm: float, local_mm: float, bounds_mm, feasible) -> int:
    """-1 or +1 for a side of h_i [mm] with no point on the design curve within ``local_mm``, 0 when both have one.

    A bound, or a thickness where ``feasible(h_i)`` is False, counts as a bracket.  The
    surrogate is only trusted where fine points surround it.
    """
    near = [s.thickness_mm - thickness_mm for s in steps if _on_design_curve(s, problem)]
    for side, bound in ((-1, bounds_mm[0]), (1, bounds_mm[1])):
        room = abs(bound - thickness_mm)
        if room < 1e-9 or not feasible(thickness_mm + side * min(local_mm, room)):
            continue
        closest = min(BRACKET_WINDOW[0] * local_mm, room - 1e-9)  # a point on a nearby bound brackets too
        if not any(closest <= side * d <= BRACKET_WINDOW[1] * local_mm for d in near):
            return side
    return 0


def _repeats(design: np.ndarray, steps, tolerance: float) -> bool:
    """Whether a step sits at ``design`` [m]: h_i within ``tolerance``, frequency within :data:`FREQUENCY_TOLERANCE`."""
    return any(
        abs(design[1] - s.design[1]) <= tolerance and abs(design[0] / s.design[0] - 1) <= FREQUENCY_TOLERANCE / 2
        for s in steps
    )


def space_mapping_optimum(
    fine: FineModel,
    coarse,
    problem: DesignProblem,
    tolerance: float = 0.01 * MM,
    max_fine_evaluations: int = 12,
    gain_tolerance: float = 1e-5,
) -> SpaceMappingResult:
    """Maximise the fine deflection subject to the fine f_r >= f_min by space mapping.

    Parameters
    ----------
    fine : FineModel
        Expensive model, called with one geometry at a time; a third output, the working
        mode's transverse indicator, keeps mixed points out of the mapping.
    coarse : PlateModel
        Cheap model of (deflection [m], frequency [Hz]), batched.
    problem : DesignProblem
    tolerance : float
        A proposal within this of an evaluated h_i [m] (and within the frequency tolerance of
        its wavelength) counts as that point: the search then checks the bracket and stops.
    max_fine_evaluations : int
        Upper limit on fine evaluations.
    gain_tolerance : float
        Below this relative gain of deflection promised by the surrogate [-], the search
        checks the bracket and stops.

    Returns
    -------
    SpaceMappingResult

    Raises
    ------
    InfeasibleError
        When no fine point reached f_min.
    """
    fine, coarse = CountedModel(fine), CountedModel(coarse)
    coarse_optimum = maximise_deflection(coarse, problem)
    bounds_mm = (problem.lower[1] / MM, problem.upper[1] / MM)
    span_mm = bounds_mm[1] - bounds_mm[0]
    grid_mm = np.linspace(*bounds_mm, CURVE_POINTS)
    curve = _CoarseCurve(grid_mm, coarse_wavelength(coarse, problem, grid_mm * MM, problem.min_frequency))
    start = np.array([coarse_optimum.plate.wavelength, coarse_optimum.plate.resonator_thickness], float)
    steps = [_evaluate(fine, coarse, problem, start)]
    local_mm = max(LOCAL_FRACTION * span_mm, 2 * tolerance / MM)
    near_mm = NEAR_FRACTION * span_mm
    converged, shrink = False, 1.0
    while True:
        anchor = _anchor(steps, problem)
        mapping = fit_mapping(steps, problem, anchor, SPREAD_FRACTION * span_mm)
        determined = mapping.determined >= 2
        predicted = curve.predicted_deflection(coarse, problem, mapping)

        def feasible(thickness_mm, predicted=predicted):
            return bool(np.isfinite(predicted[int(np.argmin(np.abs(grid_mm - thickness_mm)))]))

        if np.all(np.isnan(predicted)):
            status = "stopped: no thickness reaches f_min on the surrogate"
            break
        reach = max(shrink * TRUST_FRACTION * span_mm, local_mm) if determined else SPREAD_FRACTION * span_mm
        in_reach = (np.abs(grid_mm - anchor.thickness_mm) <= reach + 1e-12) & np.isfinite(predicted)
        allowed = in_reach.copy()
        if determined:  # where a mixed mode was seen, the smooth surrogate does not hold
            for step in steps:
                if step.mixed:
                    allowed &= np.abs(grid_mm - step.thickness_mm) >= near_mm
        allowed = allowed if np.any(allowed) else in_reach
        best = _best(steps, problem)
        thickness_mm = None
        if np.any(allowed):
            index = int(np.nanargmax(np.where(allowed, predicted, np.nan)))
            proposal = _placed(steps, problem, anchor, curve, grid_mm[index], SPREAD_FRACTION * span_mm)
            gain = np.log(predicted[index] / best.deflection) if best is not None else np.inf
        else:  # nothing feasible within reach: nothing to gain there
            index, proposal, gain = None, None, -np.inf
        if best is not None and determined and (proposal is None or _repeats(proposal, steps, tolerance) or gain <= gain_tolerance):
            side = _unbracketed_side(steps, problem, best.thickness_mm, local_mm, bounds_mm, feasible)
            if side == 0:
                converged, status = True, "converged"
                break
            thickness_mm = float(np.clip(best.thickness_mm + side * local_mm, *bounds_mm))
        if fine.evaluations >= max_fine_evaluations:
            status = f"stopped: {max_fine_evaluations} fine evaluations"
            break
        if not determined and (index is None or min(abs(s.thickness_mm - grid_mm[index]) for s in steps) < near_mm):
            thickness_mm = _exploring_thickness(
                steps, anchor.thickness_mm, SPREAD_FRACTION * span_mm, near_mm, bounds_mm, feasible
            )
            if thickness_mm is None:
                status = "stopped: no unexplored thickness within reach"
                break
        surrogate_step = thickness_mm is None
        if not surrogate_step:
            proposal = _placed(steps, problem, anchor, curve, thickness_mm, SPREAD_FRACTION * span_mm)
        if proposal is None:
            status = "stopped: no thickness within reach reaches f_min on the surrogate"
            break
        if _repeats(proposal, steps, tolerance):
            status = "stopped: the next point was evaluated already"
            break
        steps.append(_evaluate(fine, coarse, problem, proposal))
        if determined and surrogate_step and best is not None:  # a surrogate step: did it deliver?
            improved = reaches_min_frequency(steps[-1], problem) and steps[-1].deflection > best.deflection
            shrink = 1.0 if improved else shrink / 2
    return search_result(
        steps, _best(steps, problem), problem, fine, coarse, coarse_optimum, status, mapping, converged
    )
