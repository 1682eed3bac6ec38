"""Laws for the quality factor as a function of the vibration velocity, Q(v).

v is the peak surface velocity amplitude at the antinodes [m/s] (docs/damping.md).  Each
law is a frozen dataclass whose parameters may be numpy arrays (e.g. one value per
walker, shape (n, 1)) that broadcast against the velocities.  Every law is
non-increasing in |v|, which the harmonic solve relies on.
"""

from dataclasses import dataclass, fields, make_dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np

MIN_Q_AT_MAX_VELOCITY = 1.0
"""A law's loss coefficient's prior stops where Q at the highest measured velocity would fall to this [-]."""
THRESHOLD_RANGE = (0.02, 0.9)
"""Prior range of the threshold law's v_t, relative to the largest measured velocity [-]."""
MAX_INCREMENT = 0.2
"""Prior bound of each increment of the flexible law's 1/Q [-]."""


def _loss_coefficient_box(law, v_max: float) -> dict:
    """Flat prior ranges of a law's sampled parameters other than ln Q0, given the largest measured antinode velocity
    ``v_max`` [m/s] (sampled name -> (low, high) in that parameter's unit): alpha from 0 to where the loss term alone
    brings Q(v_max) down to :data:`MIN_Q_AT_MAX_VELOCITY`."""
    return {"alpha": (0.0, 1.0 / MIN_Q_AT_MAX_VELOCITY / v_max**law.velocity_exponent)}


@dataclass(frozen=True)
class QuadraticLoss:
    """1/Q(v) = 1/Q0 + alpha v^2 (Takahashi, Hirose & Uchino 1994).

    Attributes
    ----------
    q0 : float or array
        Low-velocity quality factor [-].
    alpha : float or array
        Velocity-squared loss coefficient [s^2/m^2], >= 0.
    """

    q0: float
    alpha: float
    name: ClassVar[str] = "quadratic"
    velocity_exponent: ClassVar[int] = 2
    """p of the law's loss term alpha |v|^p [-]."""
    loss_terms: ClassVar[tuple] = ("alpha",)
    """Parameters 1/Q is linear in, besides 1/Q0 (:func:`scaled_parameters`)."""
    units: ClassVar[dict] = {"q0": "-", "alpha": "s^2/m^2"}
    """Parameter -> unit."""

    prior_box = classmethod(_loss_coefficient_box)

    def quality_factor(self, velocity):
        """Q at the peak velocity amplitude ``velocity`` [m/s] -> [-]."""
        return 1.0 / self.loss(velocity)

    def loss(self, velocity):
        """Loss factor 1/Q at ``velocity`` [m/s] -> [-]."""
        return 1.0 / np.asarray(self.q0) + np.asarray(self.alpha) * np.square(velocity)


@dataclass(frozen=True)
class LinearLoss:
    """1/Q(v) = 1/Q0 + alpha |v| (loss growing linearly with velocity).

    Attributes
    ----------
    q0 : float or array
        Low-velocity quality factor [-].
    alpha : float or array
        Velocity loss coefficient [s/m], >= 0.
    """

    q0: float
    alpha: float
    name: ClassVar[str] = "linear"
    velocity_exponent: ClassVar[int] = 1
    loss_terms: ClassVar[tuple] = ("alpha",)
    units: ClassVar[dict] = {"q0": "-", "alpha": "s/m"}

    prior_box = classmethod(_loss_coefficient_box)

    def quality_factor(self, velocity):
        """Q at the peak velocity amplitude ``velocity`` [m/s] -> [-]."""
        return 1.0 / self.loss(velocity)

    def loss(self, velocity):
        """Loss factor 1/Q at ``velocity`` [m/s] -> [-]."""
        return 1.0 / np.asarray(self.q0) + np.asarray(self.alpha) * np.abs(velocity)


@dataclass(frozen=True)
class ConstantQ:
    """Q(v) = Q0: no amplitude dependence (the design with constant Q).

    Attributes
    ----------
    q0 : float or array
        Quality factor [-].
    """

    q0: float
    name: ClassVar[str] = "constant"
    velocity_exponent: ClassVar[int] = 0
    loss_terms: ClassVar[tuple] = ()
    units: ClassVar[dict] = {"q0": "-"}

    @classmethod
    def prior_box(cls, v_max: float) -> dict:
        """Nothing but ln Q0 is sampled."""
        return {}

    def quality_factor(self, velocity):
        """Q0, broadcast to the shape of ``velocity`` [-]."""
        return np.asarray(self.q0) + np.zeros_like(np.asarray(velocity, dtype=float))


def _softplus(x):
    """ln(1 + e^x), evaluated without overflow [-]: max(x, 0) + ln(1 + e^-|x|), five times faster than
    ``np.logaddexp(0, x)`` and equal to it within 3e-16 (relative)."""
    return np.maximum(x, 0.0) + np.log1p(np.exp(-np.abs(x)))


@dataclass(frozen=True)
class ThresholdLoss:
    """Q flat at Q0 below a threshold velocity v_t and falling above it, with a smooth onset of its own width.

    1/Q(v) = 1/Q0 + alpha (s softplus((|v| - v_t) / s))^2,  s = onset v_t,

    softplus(x) = ln(1 + e^x).  Far above v_t the extra loss is alpha (|v| - v_t)^2 (the
    quadratic law shifted to start at v_t); far below it is nil; the onset is spread over
    about ``s`` = ``onset`` v_t, a fitted share (:data:`ONSET_RANGE`) whose default, 0.2, was the law's fixed
    value before issue 29.  v_t -> 0 gives back :class:`QuadraticLoss`.

    Attributes
    ----------
    q0 : float or array
        Quality factor below the threshold [-].
    alpha : float or array
        Loss coefficient above the threshold [s^2/m^2], >= 0.
    v_t : float or array
        Threshold velocity amplitude [m/s], > 0.
    onset : float or array
        Width of the onset relative to the threshold, s / v_t [-], > 0.
    """

    q0: float
    alpha: float
    v_t: float
    onset: float = 0.2
    name: ClassVar[str] = "threshold"
    velocity_exponent: ClassVar[int] = 2
    """p of the loss term far above the threshold, alpha (|v| - v_t)^p [-]."""
    loss_terms: ClassVar[tuple] = ("alpha",)
    units: ClassVar[dict] = {"q0": "-", "alpha": "s^2/m^2", "v_t": "m/s", "onset": "-"}
    ONSET_RANGE: ClassVar[tuple] = (0.05, 1.0)
    """Range of the onset width the fit explores, s / v_t [-]: from a sharp corner to an onset spread over the whole
    threshold."""

    @classmethod
    def prior_box(cls, v_max: float) -> dict:
        """As :meth:`QuadraticLoss.prior_box`: v_t over :data:`THRESHOLD_RANGE` of ``v_max``, ln onset over
        :data:`ONSET_RANGE`, and alpha up to Q(v_max) = :data:`MIN_Q_AT_MAX_VELOCITY` from the highest threshold."""
        onset = (1 - THRESHOLD_RANGE[1]) * v_max
        return {"alpha": (0.0, 1.0 / MIN_Q_AT_MAX_VELOCITY / onset**cls.velocity_exponent),
                "v_t": tuple(np.asarray(THRESHOLD_RANGE) * v_max), "ln_onset": tuple(np.log(cls.ONSET_RANGE))}

    def quality_factor(self, velocity):
        """Q at the peak velocity amplitude ``velocity`` [m/s] -> [-]."""
        return 1.0 / self.loss(velocity)

    def loss(self, velocity):
        """Loss factor 1/Q at ``velocity`` [m/s] -> [-]."""
        width = np.asarray(self.onset, dtype=float) * np.maximum(np.asarray(self.v_t, dtype=float), 1e-300)
        excess = width * _softplus((np.abs(velocity) - np.asarray(self.v_t)) / width)
        return 1.0 / np.asarray(self.q0) + np.asarray(self.alpha) * np.square(excess)


@dataclass(frozen=True)
class MonotoneSpline:
    """1/Q(v) monotone non-decreasing, piecewise linear in v^2: the flexible law.

    Knots u_0 = 0 < u_1 = v_first < u_2 < .. < u_K = v_top, equally spaced from v_first to
    v_top (K = 8 segments).  1/Q(0) = 1/Q0 and 1/Q rises by d_j >= 0 over segment j,
    linearly in v^2, so

    1/Q(v) = 1/Q0 + sum_j d_j clip((v^2 - u_(j-1)^2) / (u_j^2 - u_(j-1)^2), 0, 1),

    with the last segment's slope (in v^2) continued above v_top.  Below v_first the law is
    1/Q0 + d1 (v / v_first)^2, the low-velocity form of every smooth even loss, so the
    velocities the sweeps hardly probe follow the curvature measured just above them;
    the quadratic law is followed exactly, any other non-increasing Q(v) up to the knot
    spacing.  The fit places the knots on the measured velocities and puts a random-walk
    prior on the increments (:mod:`workflow.damping.likelihood`).

    Attributes
    ----------
    q0 : float or array
        Quality factor at v = 0 [-].
    d1 .. d8 : float or array
        Rise of 1/Q over each segment [-], >= 0.
    v_top : float or array
        Velocity of the last knot [m/s], > v_first (fixed by the data, not fitted).
    v_first : float or array
        Velocity of the first knot [m/s], > 0 (fixed by the data, not fitted); default v_top / 3.
    """

    q0: float
    d1: float
    d2: float
    d3: float
    d4: float
    d5: float
    d6: float
    d7: float
    d8: float
    v_top: float
    v_first: float = None
    name: ClassVar[str] = "flexible"
    INCREMENTS: ClassVar[tuple] = ("d1", "d2", "d3", "d4", "d5", "d6", "d7", "d8")
    velocity_exponent: ClassVar[int] = 2
    """The law is piecewise linear in v^p [-]."""
    loss_terms: ClassVar[tuple] = INCREMENTS
    units: ClassVar[dict] = {"q0": "-", **{d: "-" for d in INCREMENTS}, "v_top": "m/s", "v_first": "m/s"}

    @classmethod
    def prior_box(cls, v_max: float) -> dict:
        """Each increment from 0 to :data:`MAX_INCREMENT` (the knots are fixed by the data, not sampled)."""
        return {name: (0.0, MAX_INCREMENT) for name in cls.INCREMENTS}

    @classmethod
    def knots(cls, v_top, v_first=None) -> np.ndarray:
        """The knots u_0 = 0, u_1 = ``v_first`` (default ``v_top`` / 3) .. u_K = ``v_top`` [m/s], along the first axis."""
        v_top = np.asarray(v_top, dtype=float)
        v_first = v_top / 3 if v_first is None else np.asarray(v_first, dtype=float)
        step = np.arange(len(cls.INCREMENTS)).reshape((-1,) + (1,) * v_top.ndim) / (len(cls.INCREMENTS) - 1)
        return np.concatenate([np.zeros((1,) + v_top.shape), v_first + step * (v_top - v_first)])

    @cached_property
    def segments(self) -> tuple:
        """The law as its 8 segments, each linear in v^2 (computed once per law).

        Returns
        -------
        squared, loss, slope : tuple of 8 arrays each
            u_(j-1)^2, the square of each segment's lower knot [m^2/s^2]; 1/Q there [-]; d(1/Q)/d(v^2) on the
            segment [s^2/m^2] (the last one continued above v_top).
        """
        squared = tuple(np.square(self.knots(self.v_top, self.v_first)))
        rises = [np.asarray(getattr(self, name), dtype=float) for name in self.INCREMENTS]
        loss = [1.0 / np.asarray(self.q0, dtype=float)]
        for rise in rises[:-1]:
            loss.append(loss[-1] + rise)
        slope = tuple(rise / (upper - lower) for rise, lower, upper in zip(rises, squared, squared[1:]))
        return squared[:-1], tuple(loss), slope

    def quality_factor(self, velocity):
        """Q at the peak velocity amplitude ``velocity`` [m/s] -> [-]."""
        return 1.0 / self.loss(velocity)

    def loss(self, velocity):
        """Loss factor 1/Q at ``velocity`` [m/s] -> [-].

        Summed as hinges, 1/Q0 + b_1 v^2 + sum_(j >= 2) (b_j - b_(j-1)) max(v^2 - u_(j-1)^2, 0) with b_j the
        segments' slopes in v^2: the same law, in 2 operations per knot instead of a clipped share per segment.
        """
        squared, loss, slope = self.segments
        v2 = np.square(velocity)
        total = loss[0] + slope[0] * v2
        for j in range(1, len(slope)):
            total = total + (slope[j] - slope[j - 1]) * np.maximum(v2 - squared[j], 0.0)
        return total


LAWS = {law.name: law for law in (QuadraticLoss, LinearLoss, ThresholdLoss, MonotoneSpline, ConstantQ)}
"""The Q(v) laws by name."""
SAMPLED_LAWS = tuple(name for name in LAWS if name != "constant")
"""Laws whose posterior can be sampled; the constant Q is the baseline of the comparison (BIC at the MAP)."""


STACKED_COMPONENTS = SAMPLED_LAWS
"""The laws a stacked (model-averaged) posterior may mix, in the order of its ``component`` index."""


def _stacked_quality_factor(self, velocity):
    """Q of each draw's own law at ``velocity`` [m/s] -> [-] (``component`` selects the law)."""
    component = np.asarray(self.component)
    result = None
    for index, law in enumerate(self.components()):
        q = law.quality_factor(velocity)
        result = q if result is None else np.where(component == index, q, result)
    return result


def _stacked_components(self) -> tuple:
    """One law per name of :data:`STACKED_COMPONENTS`, with this object's parameter arrays."""
    return tuple(
        LAWS[name](**{p: getattr(self, f"{name}_{p}") for p in parameter_names(LAWS[name])}) for name in STACKED_COMPONENTS
    )


StackedLaws = make_dataclass(
    "StackedLaws",
    [("component", float)]
    + [(f"{name}_{p}", float) for name in STACKED_COMPONENTS for p in (f.name for f in fields(LAWS[name]))],
    namespace={
        "name": "stacking",
        "quality_factor": _stacked_quality_factor,
        "components": _stacked_components,
        "__doc__": """Posterior draws of several laws mixed by stacking weights (a model-averaged Q(v)).

    Each draw i is a draw of the law ``STACKED_COMPONENTS[component_i]``; its parameters are the
    columns ``<law>_<parameter>`` (the other laws' columns of that draw hold a valid draw of
    theirs and are not used).  Non-increasing in |v| like every component.""",
    },
    frozen=True,
)
StackedLaws.__module__ = __name__
POSTERIOR_LAWS = {**LAWS, StackedLaws.name: StackedLaws}
"""The laws a posterior file may hold: every law of :data:`LAWS` and the stacked mixture."""


def parameter_names(law_class) -> tuple:
    """Names of a law class's parameters, e.g. ("q0", "alpha")."""
    return tuple(f.name for f in fields(law_class))


def scaled_parameters(law_class, parameters: dict, factor) -> dict:
    """Parameters of the law whose Q is ``factor`` times that of ``parameters`` at every velocity [natural units].

    Every law here is 1/Q = 1/Q0 + terms linear in its :attr:`loss_terms`, so Q0 is multiplied and each loss term
    divided by ``factor``; the shape parameters (v_t, onset, the knots) are kept.  ``factor`` broadcasts against the
    parameters (one value per posterior sample).
    """
    scaled = dict(parameters)
    scaled["q0"] = np.asarray(parameters["q0"]) * factor
    for name in law_class.loss_terms:
        scaled[name] = np.asarray(parameters[name]) / factor
    return scaled


def law_parameters(law) -> dict:
    """Parameter name -> value of a law instance."""
    return {f.name: getattr(law, f.name) for f in fields(law)}


def quadratic_law_through(q_low: float, q_work: float, v_work: float) -> QuadraticLoss:
    """The quadratic law with Q(0) = ``q_low`` that passes through Q(``v_work``) = ``q_work``.

    Parameters
    ----------
    q_low : float
        Low-velocity quality factor [-], > q_work.
    q_work : float
        Quality factor at the working point [-].
    v_work : float
        Peak velocity amplitude at the working point [m/s].
    """
    if not q_low > q_work > 0 or not v_work > 0:
        raise ValueError("need q_low > q_work > 0 and v_work > 0")
    return QuadraticLoss(q0=q_low, alpha=(1 / q_work - 1 / q_low) / v_work**2)
