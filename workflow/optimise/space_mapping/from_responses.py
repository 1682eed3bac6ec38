"""The mapping fitted to the fine responses only (for fine models without sensitivities: the FEM with Q(v)).

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
(two at the same h_i make a secant in frequency).  The mapping is determined once ln rho is
a quadratic (three thicknesses).

Transverse modes.  Where the working mode mixes with a transverse one (indicator above
:data:`TRANSVERSE_THRESHOLD`), the fine deflection dips in a narrow band of h_i that no smooth
correction describes.  Such points still count as evaluations and as candidates, but they
do not shape the mapping, and once the mapping is determined the surrogate proposes no
point within :data:`NEAR_FRACTION` of the range of them (unless nothing else is within
reach); the search steps past them (for h_p = 2 mm the beam optimum lies in such a band
and the FEM optimum 0.8 mm beyond it).

Steps.  The trust interval is :data:`SPREAD_FRACTION` of the h_i range while the mapping is
not determined, then :data:`TRUST_FRACTION`; while the mapping is not determined and the
surrogate's maximiser falls next to a point already evaluated, an exploring point
:data:`SPREAD_FRACTION` of the h_i range away is taken instead.  When the surrogate promises
less than ``gain_tolerance`` over the best feasible fine point, or only a step shorter than
``tolerance``, the search ends once fine points near the curve bracket the answer within
:data:`LOCAL_FRACTION` of the range on each side (else it evaluates the missing bracket):
transverse modes bend the FEM deflection on a 0.1 mm scale, and only nearby fine points show it.

Measured (``python bench/bench_space_mapping.py 0.5 1 2 [--width-mm B]``, b = 40, 49, 55, 70 mm):
6 to 12 FEM evaluations against 12 to 54 for the direct run, within 0.1 mm of its optimum.
"""

from dataclasses import dataclass

import numpy as np

from workflow.optimise.maps import TRANSVERSE_THRESHOLD
from workflow.optimise.problem import DesignProblem
from workflow.optimise.space_mapping.search import Proposal, Surrogate, coarse_wavelength
from workflow.optimise.space_mapping.steps import (
    FREQUENCY_TOLERANCE,
    FineStep,
    best_step,
    nearest_to_curve,
    reaches_min_frequency,
)
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


@dataclass(frozen=True)
class ExtractedStep(FineStep):
    """One fine evaluation and its parameter extraction.

    Attributes
    ----------
    extracted_wavelength : float
        Coarse lambda with the fine frequency at the same h_i [m].
    coarse_deflection : float
        Coarse deflection at (extracted_wavelength, h_i) [m].
    """

    mixing_limit = TRANSVERSE_THRESHOLD

    extracted_wavelength: float
    coarse_deflection: float

    @property
    def wavelength_ratio(self) -> float:
        """m = extracted / fine wavelength [-]."""
        return float(self.extracted_wavelength / self.design[0])

    @property
    def deflection_ratio(self) -> float:
        """rho = fine / coarse deflection at the extracted point [-]."""
        return float(self.deflection / self.coarse_deflection)


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


def fit_mapping(
    steps, problem: DesignProblem, anchor: ExtractedStep, scale_mm: float, centre_mm: float | None = None
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


class ResponseMapping:
    """The mapping fitted to fine responses (a :class:`~.search.Mapping` of ``coarse`` and ``problem``).

    The fine model returns (deflection [m], frequency [Hz]) or (deflection, frequency,
    transverse indicator [-]) for one geometry; the indicator keeps mixed points out of the mapping.
    A proposal within ``tolerance`` [m] of an evaluated h_i (and within the frequency tolerance of
    its wavelength) counts as that point, and so does one promising less than ``gain_tolerance``
    [-] more deflection: the search then checks the bracket and stops.
    """

    what = "design"

    def __init__(self, coarse, problem: DesignProblem, tolerance: float = 0.01 * MM, gain_tolerance: float = 1e-5):
        self.coarse, self.problem, self.tolerance, self.gain_tolerance = coarse, problem, tolerance, gain_tolerance
        self.bounds_mm = (problem.lower[1] / MM, problem.upper[1] / MM)
        span_mm = self.bounds_mm[1] - self.bounds_mm[0]
        self.thickness_mm = np.linspace(*self.bounds_mm, CURVE_POINTS)
        self.coarse_curve = coarse_wavelength(coarse, problem, self.thickness_mm * MM, problem.min_frequency)
        self.spread_mm, self.near_mm = SPREAD_FRACTION * span_mm, NEAR_FRACTION * span_mm
        self.trust_mm = TRUST_FRACTION * span_mm
        self.local_mm = max(LOCAL_FRACTION * span_mm, 2 * tolerance / MM)
        self.shrink = 1.0

    def evaluate(self, fine, design: np.ndarray) -> ExtractedStep:
        """One fine evaluation at (lambda, h_i) [m] and its parameter extraction."""
        coarse, problem = self.coarse, self.problem
        plate = problem.plate(np.atleast_1d(design[0]), np.atleast_1d(design[1]))
        response = [float(np.ravel(a)[0]) for a in fine(plate)]
        deflection, frequency = response[:2]
        indicator = response[2] if len(response) > 2 else 0.0
        extracted = float(coarse_wavelength(coarse, problem, design[1], frequency))
        coarse_deflection, _ = coarse(problem.plate(np.atleast_1d(extracted), np.atleast_1d(design[1])))
        coarse_deflection = float(np.ravel(coarse_deflection)[0])
        return ExtractedStep(np.asarray(design, float), deflection, frequency, indicator, extracted, coarse_deflection)

    def best(self, steps) -> ExtractedStep | None:
        """The feasible clean step of largest deflection (feasible mixed steps when none is clean)."""
        return best_step(steps, self.problem, accept_mixed=True)

    def anchor(self, steps) -> ExtractedStep:
        """Where the mapping is centred: the best feasible clean step, else the clean step nearest the
        f_min curve, else the first.

        Deflections of steps below the curve are not compared: the lower their frequency, the
        longer and softer the plate and the larger the deflection.
        """
        clean = [s for s in steps if not s.mixed]
        best = best_step(clean, self.problem, accept_mixed=False)
        if best is not None:
            return best
        return nearest_to_curve(clean, self.problem) if clean else steps[0]

    def fine_wavelength(self, mapping: CurveMapping, thickness_mm) -> np.ndarray:
        """lambda_c(h_i; f_min) / m(h_i): the surrogate's f_min curve at ``thickness_mm`` [m] (not clipped)."""
        return np.interp(thickness_mm, self.thickness_mm, self.coarse_curve) / mapping.wavelength_ratio(thickness_mm)

    def surrogate(self, steps) -> Surrogate:
        """The mapping fitted around the anchor; the surrogate's deflection along its f_min curve on the grid."""
        problem = self.problem
        anchor = self.anchor(steps)
        mapping = fit_mapping(steps, problem, anchor, self.spread_mm)
        fine_wavelength = self.fine_wavelength(mapping, self.thickness_mm)
        feasible = fine_wavelength >= problem.wavelength_range[0]
        clipped = np.clip(fine_wavelength, *problem.wavelength_range)
        ratio = mapping.wavelength_ratio(self.thickness_mm)
        deflection, _ = self.coarse(problem.plate(clipped * ratio, self.thickness_mm * MM))
        predicted = np.where(feasible, deflection * mapping.deflection_ratio(self.thickness_mm), np.nan)
        determined = mapping.determined >= 2
        return Surrogate(anchor, np.log(anchor.deflection), feasible, np.log(predicted), determined, mapping)

    def reach(self, steps, surrogate: Surrogate) -> float:
        """:data:`SPREAD_FRACTION` of the range while not determined, then :data:`TRUST_FRACTION`, halved
        per surrogate step without gain [mm]."""
        return max(self.shrink * self.trust_mm, self.local_mm) if surrogate.determined else self.spread_mm

    def candidates(self, within: np.ndarray, steps, surrogate: Surrogate) -> np.ndarray:
        """``within``, once the mapping is determined away from mixed steps (unless nothing else is left) [bool]."""
        allowed = within.copy()
        if surrogate.determined:  # where a mixed mode was seen, the smooth surrogate does not hold
            for step in steps:
                if step.mixed:
                    allowed &= np.abs(self.thickness_mm - step.thickness_mm) >= self.near_mm
        return allowed if np.any(allowed) else within

    def place(self, steps, surrogate: Surrogate, thickness_mm: float) -> np.ndarray:
        """The design (lambda, h_i) [m] on the surrogate's f_min curve at ``thickness_mm``.

        The wavelength ratio is fitted around that thickness, so the fine steps there (a secant
        in frequency when one sits at the same h_i) count most.
        """
        mapping = fit_mapping(steps, self.problem, surrogate.anchor, self.spread_mm, thickness_mm)
        wavelength = float(np.clip(self.fine_wavelength(mapping, thickness_mm), *self.problem.wavelength_range))
        return np.array([wavelength, thickness_mm * MM])

    def repeats(self, thickness_mm: float, design: np.ndarray, steps) -> bool:
        """Whether a step sits at ``design`` [m]: h_i within ``tolerance``, lambda within half
        :data:`FREQUENCY_TOLERANCE`."""
        return any(
            abs(design[1] - s.design[1]) <= self.tolerance
            and abs(design[0] / s.design[0] - 1) <= FREQUENCY_TOLERANCE / 2
            for s in steps
        )

    def reached(self, thickness_mm: float, design: np.ndarray, best: ExtractedStep, steps) -> bool:
        """Whether the proposal repeats an evaluated point (:meth:`repeats`)."""
        return self.repeats(thickness_mm, design, steps)

    def _feasible_at(self, surrogate: Surrogate, thickness_mm: float) -> bool:
        """Whether the surrogate reaches f_min at the grid point nearest ``thickness_mm``."""
        return bool(surrogate.feasible[int(np.argmin(np.abs(self.thickness_mm - thickness_mm)))])

    def _on_design_curve(self, step: ExtractedStep) -> bool:
        """Whether a clean step lies on the fine f_min curve (within :data:`NEAR_CURVE`) or the lambda upper bound."""
        on_bound = step.design[0] >= self.problem.wavelength_range[1] * (1 - 1e-9)
        return not step.mixed and (on_bound or abs(np.log(step.frequency / self.problem.min_frequency)) <= NEAR_CURVE)

    def bracket_thickness(self, steps, best: ExtractedStep, surrogate: Surrogate) -> float | None:
        """h_i [mm] :data:`LOCAL_FRACTION` of the range beside ``best`` on a side with no point on the design
        curve there, None when both sides have one.

        A bound, or a thickness the surrogate does not reach f_min at, counts as a bracket.  The
        surrogate is only trusted where fine points surround it.
        """
        local_mm, thickness_mm = self.local_mm, best.thickness_mm
        near = [s.thickness_mm - thickness_mm for s in steps if self._on_design_curve(s)]
        for side, bound in ((-1, self.bounds_mm[0]), (1, self.bounds_mm[1])):
            room = abs(bound - thickness_mm)
            if room < 1e-9 or not self._feasible_at(surrogate, thickness_mm + side * min(local_mm, room)):
                continue
            closest = min(BRACKET_WINDOW[0] * local_mm, room - 1e-9)  # a point on a nearby bound brackets too
            if not any(closest <= side * d <= BRACKET_WINDOW[1] * local_mm for d in near):
                return float(np.clip(thickness_mm + side * local_mm, *self.bounds_mm))
        return None

    def explores_instead_of(self, steps, thickness_mm: float | None) -> bool:
        """Whether there is no proposal or it lies within :data:`NEAR_FRACTION` of the range of an evaluated point."""
        return thickness_mm is None or min(abs(s.thickness_mm - thickness_mm) for s in steps) < self.near_mm

    def exploring_thickness(self, steps, surrogate: Surrogate) -> float | None:
        """h_i [mm] a spread (else half, a quarter of one) from the anchor, at least :data:`NEAR_FRACTION`
        of the range from every point evaluated.

        The side towards mid-range is tried first (the surrogate cannot tell the sides apart yet:
        the anchor is the coarse optimum, or the mapping has no slope); thicknesses the surrogate
        does not reach f_min at are skipped; None when no candidate is left.
        """
        anchor_mm, bounds_mm = surrogate.anchor.thickness_mm, self.bounds_mm
        evaluated = np.array([s.thickness_mm for s in steps])
        sign = 1 if anchor_mm <= np.mean(bounds_mm) else -1
        for fraction in (1, 0.5, 0.25):
            for side in (sign, -sign):
                thickness = anchor_mm + side * fraction * self.spread_mm
                if (
                    bounds_mm[0] <= thickness <= bounds_mm[1]
                    and np.min(np.abs(evaluated - thickness)) >= 0.999 * self.near_mm
                    and self._feasible_at(surrogate, thickness)
                ):
                    return float(thickness)
        return None

    def learn(self, proposal: Proposal, step: ExtractedStep) -> None:
        """After a surrogate step of the determined mapping: the full trust interval if it improved on the
        best point, else half the last one."""
        if proposal.determined and proposal.from_surrogate and proposal.best is not None:
            improved = reaches_min_frequency(step, self.problem) and step.deflection > proposal.best.deflection
            self.shrink = 1.0 if improved else self.shrink / 2
