"""The mapping from the FEM's design sensitivities: the FEM optimum in about four FEM evaluations.

The mapping of :mod:`workflow.optimise.space_mapping.from_responses` learns how the fine (FEM)
model departs from the coarse (beam) one from the fine responses alone, so the search spends
its first fine points on exploring.  Here every fine evaluation also returns the gradients of
its deflection and frequency over (lambda, h_i) (:mod:`workflow.models.fem.sensitivity`, about
1.6 times the cost of a plain evaluation), and each fine point then fixes the mapping's value
*and slope*.

Curve and mapping.  The search runs along the fine f_min curve, parametrised by u = h_i [mm];
v = ln lambda.
Each fine point k is projected onto the curve at its own h_i by one Newton step in v
(v*_k = v_k + ln(f_min / f_k) / (d ln f / d v)); the curve's slope there is the fine
iso-frequency tangent t_k = -(d ln f / d u) / (d ln f / d v), and the deflection on the curve
W*_k = ln w_k + (d ln w / d v)(v*_k - v_k) changes along it as W'_k = d ln w/du + (d ln w/dv) t_k.
The mapping has two parts, both functions of u:

- ln m(u) = v_c(u) - v_f(u), where v_c is the coarse f_min curve: value v_c(u_k) - v*_k and
  slope v_c'(u_k) - t_k at each fine point;
- ln rho(u) = W(u) - ln w_c(v_f(u), u), the deflection the coarse model misses on the curve:
  value W*_k - ln w_c(v*_k, u_k) and slope W'_k - (d/du) ln w_c along the tangent.

Both are fitted as polynomials in (u - u_anchor) to the values and slopes of the clean fine
points, weighted towards the anchor (the best feasible clean point, else the clean point
nearest the curve): with one point it is the first-order (value and slope) correction of the
coarse model, from two on a local quadratic, whose curvature comes from the slopes of
neighbouring points (a secant on the derivative).  The surrogate deflection along its f_min
curve is ln w_c(v_f(u), u) + ln rho(u); the mapping is always determined (the search never
explores nor asks for a bracket).  A new point's wavelength comes from ln m refitted around its own
thickness (fine points there count most: repeated points at one h_i converge as a secant in
frequency), a little (:data:`FREQUENCY_MARGIN`) above f_min.

Trust interval.  :data:`TRUST_MM` to start with, :data:`MIXED_TRUST_MM` while no clean point
is known (the coarse optimum then sits in a transverse-mode band, and the gradients there
describe the band, not the plate); halved when a step lands on a mixed mode or delivers less
than :data:`ACCEPTED_GAIN_RATIO` of the gain the surrogate promised, doubled (up to
:data:`TRUST_MM`) when a step to its edge delivers :data:`GROWING_GAIN_RATIO`.  While the clean points
share one h_i, the mapping is first-order and the step also stops where it would promise more
than :data:`FIRST_ORDER_GAIN` over the anchor: a slope the beam does not share is only
extrapolated that far.

Transverse modes.  A point whose working mode has a transverse indicator above
:data:`MIXING_LIMIT` does not shape the mapping, and the surrogate proposes no point within
:data:`MIXED_EXCLUSION_MM` of it, nor beyond halfway to the nearest clean point.

Stop.  When the surrogate's next point is within :data:`STEP_TOLERANCE_MM` in h_i and
:data:`WAVELENGTH_TOLERANCE` in lambda of the best feasible clean fine point, or promises less
than ``gain_tolerance`` over it, the search ends without evaluating it; the answer is that
point.  An exact repeat of an evaluated point also ends it.

Measured (``python bench/bench_space_mapping.py 0.5 1 2 [--width-mm B]``): 4 FEM evaluations
for the original plate (b = 49 mm, h_p = 0.5, 1, 2 mm), 2 to 6 at b = 40, 55, 70 mm, within
0.1 mm of the direct run; on held-out widths 3 to 12, and at b = 60 mm, h_p = 1 mm 0.18 mm off
(a veering pair at the working frequency); see ``docs/fem.md``.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workflow.optimise.problem import DesignProblem
from workflow.optimise.space_mapping.search import Proposal, Surrogate, coarse_wavelength
from workflow.optimise.space_mapping.steps import FineStep, best_step, nearest_to_curve
from workflow.units import MM

TRUST_MM = 0.3
"""First trust half-width in h_i [mm]."""
MIXED_TRUST_MM = 0.6
"""Trust half-width in h_i while no clean fine point is known [mm]."""
FIRST_ORDER_GAIN = 0.03
"""Largest gain in ln w over the anchor that a first-order mapping may promise [-].

While the clean points share one h_i, ln rho continues along the slope measured there; where
that slope is not the beam's, the gain it promises grows with the step and is soon
extrapolation (FEM, b = 49 mm, h_p = 0.5 mm: a slope of 0.76 /mm at h_i = 0.5 mm promises
+22 % at 0.8 mm, where a transverse mode halves the deflection; the curve peaks at 0.515 mm).
The step then goes only as far as this gain."""
ACCEPTED_GAIN_RATIO = 0.25
"""A step that delivers less than this fraction of its promised gain halves the trust interval [-]."""
GROWING_GAIN_RATIO = 0.75
"""A step to the edge of the trust interval that delivers this fraction of its promise doubles it, up to :data:`TRUST_MM` [-]."""
MIXING_LIMIT = 0.1
"""Transverse indicator above which a fine point does not shape the mapping [-] (the FEM's
deflection and its lambda-derivative are disturbed from about 0.1: b = 49 mm, h_p = 2 mm)."""
MIXED_EXCLUSION_MM = 0.1
"""No proposal within this of a mixed fine point (nor beyond halfway to the nearest clean one) [mm]."""
FREQUENCY_MARGIN = 1e-4
"""Relative margin above f_min at which new points are placed [-] (2.5 Hz at 25 kHz)."""
STEP_TOLERANCE_MM = 0.02
"""A proposal within this h_i [mm] (and :data:`WAVELENGTH_TOLERANCE`) of the best point ends the search."""
WAVELENGTH_TOLERANCE = 1e-3
"""Relative lambda tolerance of the stop [-]."""
REPEAT_TOLERANCE_MM, REPEAT_WAVELENGTH_TOLERANCE = 1e-3, 2e-5
"""A proposal closer than these in h_i [mm] and ln lambda [-] to an evaluated point repeats it."""
MAPPING_DEGREE = 2
"""Degree of the polynomials ln m(u), ln rho(u) once two thicknesses are known [-]."""
VALUE_NOISE, SLOPE_NOISE = 1e-4, 1e-3
"""Scatter of a fitted value [-] and slope [1/mm] at the anchor."""
LOCALITY = 10.0
"""Growth of the quadratic's error with the distance d from the anchor [1/mm^4]: values weigh
1e-4 + LOCALITY d^4, slopes 1e-3 + 4 LOCALITY |d|^3 (transverse modes bend the ratios on a
scale of 0.1 mm)."""
MIXING_SCATTER = 10.0
"""Added scatter per unit of t^2 above the anchor's [-]."""
CURVE_POINTS = 2501
"""h_i grid on which the surrogate is maximised [-] (1 um steps on 0.5-3 mm)."""
COARSE_STEP = 1e-4
"""Relative step of the coarse model's finite differences [-]."""

GradientFineModel = Callable
"""fine(plate) -> (deflection [m], frequency [Hz], transverse indicator [-],
d deflection / d (lambda, h_i) [m/m], d frequency / d (lambda, h_i) [Hz/m]) for a scalar plate."""


@dataclass(frozen=True)
class GradientStep(FineStep):
    """One fine evaluation with its gradients.

    Attributes
    ----------
    deflection_gradient, frequency_gradient : ndarray
        Over (lambda, h_i) [m/m], [Hz/m].
    """

    mixing_limit = MIXING_LIMIT

    deflection_gradient: np.ndarray
    frequency_gradient: np.ndarray

    def logarithmic_slopes(self) -> tuple[float, float, float, float]:
        """d ln f/du [1/mm], d ln f/dv, d ln w/du [1/mm], d ln w/dv (u = h_i [mm], v = ln lambda)."""
        wavelength = self.design[0]
        return (
            self.frequency_gradient[1] * MM / self.frequency,
            self.frequency_gradient[0] * wavelength / self.frequency,
            self.deflection_gradient[1] * MM / self.deflection,
            self.deflection_gradient[0] * wavelength / self.deflection,
        )

    def on_curve(self, min_frequency: float) -> tuple[float, float, float, float]:
        """Projection onto the fine f_min curve at this h_i: v*, its slope dv/du [1/mm], W* = ln w there and dW/du [1/mm]."""
        fu, fv, wu, wv = self.logarithmic_slopes()
        v = np.log(self.design[0])
        projected = v + np.log(min_frequency / self.frequency) / fv
        tangent = -fu / fv
        return projected, tangent, np.log(self.deflection) + wv * (projected - v), wu + wv * tangent


def finite_difference_gradients(model, relative_step: float = 1e-6) -> GradientFineModel:
    """A :data:`GradientFineModel` from a cheap (deflection, frequency[, indicator]) model by central differences.

    For synthetic fine models and tests; the FEM gives exact gradients
    (:meth:`workflow.optimise.fem_model.FemModel.responses_with_gradients`).
    """

    def fine(plate):
        design = np.array([plate.wavelength, plate.resonator_thickness], dtype=float).ravel()
        steps = relative_step * design
        shifted = design + np.vstack([np.zeros(2), np.diag(steps), -np.diag(steps)])
        response = model(plate.with_(wavelength=shifted[:, 0], resonator_thickness=shifted[:, 1]))
        deflection, frequency = (np.ravel(a) for a in response[:2])
        indicator = float(np.ravel(response[2])[0]) if len(response) > 2 else 0.0

        def gradient(values):
            return (values[1:3] - values[3:5]) / (2 * steps)

        return deflection[0], frequency[0], indicator, gradient(deflection), gradient(frequency)

    return fine


def _coarse_log_deflection(coarse, problem: DesignProblem, log_wavelength, thickness_mm):
    """ln w_c [ln m] and its partials d/du [1/mm], d/dv at (e^v, u), vectorised."""
    v, u = np.broadcast_arrays(np.asarray(log_wavelength, float), np.asarray(thickness_mm, float))
    dv, du = COARSE_STEP, COARSE_STEP * np.maximum(u, 1.0)
    wavelength = np.exp(np.stack([v, v + dv, v - dv, v, v]))
    thickness = np.stack([u, u, u, u + du, u - du]) * MM
    deflection, _ = coarse(problem.plate(wavelength, thickness))
    logarithm = np.log(deflection)
    return logarithm[0], (logarithm[3] - logarithm[4]) / (2 * du), (logarithm[1] - logarithm[2]) / (2 * dv)


def _fit(values, slopes, thickness_mm, scatter_values, scatter_slopes, centre_mm, degree) -> np.ndarray:
    """Polynomial in (u - centre) [ascending powers] fitted to values and slopes by weighted least squares."""
    d = np.asarray(thickness_mm) - centre_mm
    powers = np.arange(degree + 1)
    value_rows = d[:, None] ** powers
    slope_rows = np.where(powers > 0, powers * d[:, None] ** np.maximum(powers - 1, 0), 0.0)
    rows = np.vstack([value_rows / scatter_values[:, None], slope_rows / scatter_slopes[:, None]])
    right = np.concatenate([values / scatter_values, slopes / scatter_slopes])
    coefficients, *_ = np.linalg.lstsq(rows, right, rcond=None)
    return coefficients


@dataclass(frozen=True)
class _MappingData:
    """Values and slopes of ln m and ln rho at the clean fine points, to be fitted around any centre.

    Attributes
    ----------
    thickness_mm : ndarray
        h_i of the points [mm].
    log_ratio, log_ratio_slope : ndarray
        ln m = v_c - v* [-] and its slope along the curve [1/mm].
    log_deflection_ratio, log_deflection_ratio_slope : ndarray
        ln rho = W* - ln w_c [-] and its slope along the curve [1/mm].
    mixing : ndarray
        Added scatter of mixed points [-] (:data:`MIXING_SCATTER`).
    """

    thickness_mm: np.ndarray
    log_ratio: np.ndarray
    log_ratio_slope: np.ndarray
    log_deflection_ratio: np.ndarray
    log_deflection_ratio_slope: np.ndarray
    mixing: np.ndarray

    @classmethod
    def of(cls, clean, anchor: GradientStep, coarse, problem: DesignProblem, grid_mm, coarse_curve, coarse_slope):
        """From the ``clean`` steps projected onto the fine f_min curve; mixing is counted beyond the anchor's."""
        projected = np.array([s.on_curve(problem.min_frequency) for s in clean])
        thickness = np.array([s.thickness_mm for s in clean])
        coarse_log, coarse_du, coarse_dv = _coarse_log_deflection(coarse, problem, projected[:, 0], thickness)
        indicator = np.array([s.transverse_indicator for s in clean])
        return cls(
            thickness,
            np.interp(thickness, grid_mm, coarse_curve) - projected[:, 0],
            np.interp(thickness, grid_mm, coarse_slope) - projected[:, 1],
            projected[:, 2] - coarse_log,
            projected[:, 3] - coarse_du - coarse_dv * projected[:, 1],
            MIXING_SCATTER * np.maximum(0.0, indicator**2 - anchor.transverse_indicator**2),
        )

    @property
    def first_order(self) -> bool:
        """Whether the points share one h_i (the fit is then linear: value and slope) [-]."""
        return len(np.unique(np.round(self.thickness_mm, 4))) == 1

    def fit(self, centre_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """ln m and ln rho as polynomials in (u - centre_mm) [ascending powers], points weighted towards the centre."""
        distance = np.abs(self.thickness_mm - centre_mm)
        settings = {
            "thickness_mm": self.thickness_mm,
            "scatter_values": VALUE_NOISE + LOCALITY * distance**4 + self.mixing,
            "scatter_slopes": SLOPE_NOISE + 4 * LOCALITY * distance**3 + self.mixing,
            "centre_mm": centre_mm,
            "degree": 1 if self.first_order else MAPPING_DEGREE,
        }
        return (
            _fit(self.log_ratio, self.log_ratio_slope, **settings),
            _fit(self.log_deflection_ratio, self.log_deflection_ratio_slope, **settings),
        )


def _surrogate(mapping: _MappingData, anchor: GradientStep, coarse, problem: DesignProblem, grid_mm, coarse_curve):
    """The surrogate's f_min curve v_f(u) (placed :data:`FREQUENCY_MARGIN` above f_min) and its ln w there, on the grid.

    ln m and ln rho are fitted around the anchor; the deflection is the coarse one at (v_f, u),
    v_f clipped to the wavelength bounds, times rho.
    """
    log_ratio, log_deflection_ratio = mapping.fit(anchor.thickness_mm)
    offset = grid_mm - anchor.thickness_mm
    polynomial = np.polynomial.polynomial
    curve = coarse_curve - polynomial.polyval(offset, log_ratio) - FREQUENCY_MARGIN / 2
    clipped = np.clip(curve, *np.log(problem.wavelength_range))
    coarse_deflection, _ = coarse(problem.plate(np.exp(clipped), grid_mm * MM))
    predicted = np.log(coarse_deflection) + polynomial.polyval(offset, log_deflection_ratio)
    return curve, predicted


def _near_mixed_points(grid_mm, steps) -> np.ndarray:
    """Where on the grid the surrogate proposes nothing: near mixed steps [bool].

    Within :data:`MIXED_EXCLUSION_MM` of each mixed step, but at most halfway to the nearest
    clean step: a transverse band can be narrower than that, and the optimum often lies next to it.
    """
    clean = np.array([s.thickness_mm for s in steps if not s.mixed])
    near = np.zeros(np.shape(grid_mm), dtype=bool)
    for step in steps:
        if step.mixed:
            radius = min(MIXED_EXCLUSION_MM, np.min(np.abs(clean - step.thickness_mm), initial=np.inf) / 2)
            near |= np.abs(grid_mm - step.thickness_mm) < radius
    return near


class SensitivityMapping:
    """The mapping from fine values and slopes (a :class:`~.search.Mapping` of ``coarse`` and ``problem``).

    The fine model is a :data:`GradientFineModel`; only clean points count as answers.  Below
    ``gain_tolerance``, the relative gain promised by the surrogate over the best of them [-],
    the search ends.
    """

    what = "clean design"

    def __init__(self, coarse, problem: DesignProblem, gain_tolerance: float = 1e-4):
        self.coarse, self.problem, self.gain_tolerance = coarse, problem, gain_tolerance
        self.thickness_mm = np.linspace(problem.lower[1] / MM, problem.upper[1] / MM, CURVE_POINTS)
        self.coarse_curve = np.log(coarse_wavelength(coarse, problem, self.thickness_mm * MM, problem.min_frequency))
        self.coarse_slope = np.gradient(self.coarse_curve, self.thickness_mm)
        self.trust_mm = TRUST_MM

    def evaluate(self, fine, design: np.ndarray) -> GradientStep:
        """One fine evaluation at (lambda, h_i) [m] with its gradients."""
        response = fine(self.problem.plate(float(design[0]), float(design[1])))
        values = [float(np.ravel(a)[0]) for a in response[:3]]
        gradients = (np.ravel(np.asarray(g, float)) for g in response[3:5])
        return GradientStep(np.asarray(design, float), *values, *gradients)

    def best(self, steps) -> GradientStep | None:
        """The feasible clean step of largest deflection."""
        return best_step(steps, self.problem, accept_mixed=False)

    def surrogate(self, steps) -> Surrogate:
        """The mapping fitted around the anchor: the best step, else the clean step nearest the f_min curve,
        else the step nearest it."""
        problem = self.problem
        clean = [s for s in steps if not s.mixed] or steps
        anchor = self.best(steps) or nearest_to_curve(clean, problem)
        mapping = _MappingData.of(
            clean, anchor, self.coarse, problem, self.thickness_mm, self.coarse_curve, self.coarse_slope
        )
        curve, predicted = _surrogate(mapping, anchor, self.coarse, problem, self.thickness_mm, self.coarse_curve)
        feasible = curve >= np.log(problem.wavelength_range[0])
        return Surrogate(anchor, anchor.on_curve(problem.min_frequency)[2], feasible, predicted, True, mapping)

    def reach(self, steps, surrogate: Surrogate) -> float:
        """The trust half-width, :data:`MIXED_TRUST_MM` while every step is mixed [mm]."""
        return self.trust_mm if any(not s.mixed for s in steps) else MIXED_TRUST_MM

    def candidates(self, within: np.ndarray, steps, surrogate: Surrogate) -> np.ndarray:
        """``within`` away from mixed steps; while the mapping is first-order, promising at most
        :data:`FIRST_ORDER_GAIN` [bool]."""
        allowed = within & ~_near_mixed_points(self.thickness_mm, steps)
        if surrogate.mapping.first_order and not surrogate.anchor.mixed:
            modest = allowed & (surrogate.log_deflection - surrogate.anchor_log_deflection <= FIRST_ORDER_GAIN)
            allowed = modest if np.any(modest) else allowed
        return allowed

    def place(self, steps, surrogate: Surrogate, thickness_mm: float) -> np.ndarray:
        """The design (lambda, h_i) [m] at ``thickness_mm``, :data:`FREQUENCY_MARGIN` above the f_min curve
        of ln m refitted around it."""
        coarse_curve = np.interp(thickness_mm, self.thickness_mm, self.coarse_curve)
        placed = coarse_curve - surrogate.mapping.fit(thickness_mm)[0][0] - FREQUENCY_MARGIN / 2
        return np.array([np.clip(np.exp(placed), *self.problem.wavelength_range), thickness_mm * MM])

    def reached(self, thickness_mm: float, design: np.ndarray, best: GradientStep, steps) -> bool:
        """Whether the proposal is within :data:`STEP_TOLERANCE_MM` and :data:`WAVELENGTH_TOLERANCE` of ``best``."""
        return (
            abs(thickness_mm - best.thickness_mm) <= STEP_TOLERANCE_MM
            and abs(np.log(design[0] / best.design[0])) <= WAVELENGTH_TOLERANCE
        )

    def repeats(self, thickness_mm: float, design: np.ndarray, steps) -> bool:
        """Whether a step lies within :data:`REPEAT_TOLERANCE_MM` in h_i and
        :data:`REPEAT_WAVELENGTH_TOLERANCE` in ln lambda of the proposal."""
        return any(
            abs(s.thickness_mm - thickness_mm) < REPEAT_TOLERANCE_MM
            and abs(np.log(design[0] / s.design[0])) < REPEAT_WAVELENGTH_TOLERANCE
            for s in steps
        )

    def bracket_thickness(self, steps, best: GradientStep, surrogate: Surrogate) -> None:
        """The slopes at the fine points show the peak: no bracket is asked for."""
        return None

    def learn(self, proposal: Proposal, step: GradientStep) -> None:
        """Halve the trust interval when the step is mixed or delivers under :data:`ACCEPTED_GAIN_RATIO` of its promise;
        double it (up to :data:`TRUST_MM`) when a step to its edge delivers :data:`GROWING_GAIN_RATIO`."""
        promised = proposal.promised
        delivered = step.on_curve(self.problem.min_frequency)[2] - proposal.reference
        if step.mixed or (promised > 0 and delivered < ACCEPTED_GAIN_RATIO * promised):
            self.trust_mm /= 2
        elif proposal.at_edge and delivered >= GROWING_GAIN_RATIO * promised > 0:
            self.trust_mm = min(2 * self.trust_mm, TRUST_MM)
