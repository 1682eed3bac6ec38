"""Forward model and log-probability of the sweeps, vectorised over walkers.

Forward model (one resonant mode, amplitude-dependent damping): a row measured at drive
frequency f and peak voltage V in sweep k has the antinode deflection

    w = g V / sqrt((1 - r^2)^2 + (r / Q(2 pi f w))^2),   r = f / f_r,k,

solved self-consistently (:func:`~workflow.damping.harmonic.self_consistent_amplitude`, the
bench simulator's solve), and the vibrometer reads the velocity amplitude v = 2 pi f w.
Parameters, in the order of :attr:`ParameterLayout.names`:

- the law's parameters: ``ln_q0`` = ln Q0, ``alpha`` (>= 0) for the velocity-dependent laws,
  ``v_t`` [m/s] for the threshold law, ``d1`` .. ``d6`` (>= 0) for the flexible law (whose
  last knot ``v_top`` is fixed at the largest measured velocity, :attr:`ParameterLayout.fixed`);
- ``ln_gain``: ln g, g the quasi-static deflection per volt [m/V];
- ``f_r_<k>``: one resonance frequency per sweep [Hz] (drift between sweeps is free);
- ``ln_sigma_rel``, ``ln_sigma_abs``: the noise, Gaussian with variance
  (sigma_rel v_model)^2 + sigma_abs^2 (sigma_abs in m/s).

Priors are flat on these coordinates within :attr:`FitData.lower` .. :attr:`FitData.upper`;
the flexible law's increments have in addition a Gaussian random-walk prior,
d_{j+1} - d_j ~ N(0, :data:`RANDOM_WALK_SCALE`^2) (:func:`log_prior`), which keeps 1/Q(v)
smooth where the data do not say otherwise.
Every function here is module-level and takes arrays, so emcee can pickle it.
"""

from dataclasses import dataclass
from typing import Tuple

import numpy as np

from workflow.damping.harmonic import self_consistent_amplitude
from workflow.damping.laws import LAWS, MonotoneSpline, ThresholdLoss, parameter_names
from workflow.damping.logs import CampaignLog

SAMPLED_LAW_PARAMETERS = {"q0": "ln_q0", "alpha": "alpha", "v_t": "v_t", **{d: d for d in MonotoneSpline.INCREMENTS}}
"""Law parameter -> the coordinate it is sampled in (Q0 in log, the others linear)."""

Q0_RANGE = (1.0, 1e5)
"""Prior range of Q0 [-]."""
MIN_Q_AT_MAX_VELOCITY = 1.0
"""alpha's prior stops where Q at the highest measured velocity would fall to this [-]."""
GAIN_RANGE = (1e-15, 1e-3)
"""Prior range of the quasi-static deflection per volt [m/V]."""
SIGMA_REL_RANGE = (1e-4, 1.0)
"""Prior range of the relative noise [-]."""
SIGMA_ABS_RANGE = (1e-7, 1.0)
"""Prior range of the absolute noise, relative to the largest measured velocity [-]."""
THRESHOLD_RANGE = (0.02, 0.9)
"""Prior range of the threshold law's v_t, relative to the largest measured velocity [-]."""
MAX_INCREMENT = 0.2
"""Prior bound of each increment of the flexible law's 1/Q [-] (six of them: Q down to 1 at the largest velocity)."""
RANDOM_WALK_SCALE = 0.01
"""Standard deviation of the step between consecutive increments of the flexible law's 1/Q [-]:
weak for plates with Q above ~20 (1/Q changing by 0.01 or less between knots)."""


@dataclass(frozen=True)
class ParameterLayout:
    """Names and positions of the sampled parameters for a law and a number of sweeps."""

    law_name: str
    n_sweeps: int
    fixed: Tuple[Tuple[str, float], ...] = ()
    """Values of the law parameters that are not sampled (name, value): the flexible law's ``v_top`` [m/s]."""

    @property
    def law_parameters(self) -> Tuple[str, ...]:
        """The law's sampled parameter names (``q0``, ``alpha``, ...)."""
        return tuple(name for name in parameter_names(LAWS[self.law_name]) if name in SAMPLED_LAW_PARAMETERS)

    @property
    def names(self) -> Tuple[str, ...]:
        """All sampled coordinates, in order."""
        law = tuple(SAMPLED_LAW_PARAMETERS[name] for name in self.law_parameters)
        sweeps = tuple(f"f_r_{k}" for k in range(self.n_sweeps))
        return law + ("ln_gain",) + sweeps + ("ln_sigma_rel", "ln_sigma_abs")

    @property
    def dimension(self) -> int:
        return len(self.names)

    @property
    def gain_index(self) -> int:
        return len(self.law_parameters)

    @property
    def resonance_slice(self) -> slice:
        return slice(self.gain_index + 1, self.gain_index + 1 + self.n_sweeps)

    def law(self, theta: np.ndarray):
        """The Q(v) law with one parameter row per walker: parameters of shape (W, 1)."""
        theta = np.atleast_2d(theta)
        values = dict(self.fixed)
        for i, name in enumerate(self.law_parameters):
            column = theta[:, i : i + 1]
            values[name] = np.exp(column) if SAMPLED_LAW_PARAMETERS[name].startswith("ln_") else column
        return LAWS[self.law_name](**values)

    def natural(self, theta: np.ndarray) -> dict:
        """Parameter name -> values in natural units (q0, alpha, gain [m/V], f_r_k [Hz], sigma_rel, sigma_abs [m/s])."""
        theta = np.atleast_2d(theta)
        out = {}
        for i, name in enumerate(self.names):
            if name.startswith("ln_"):
                out[name[3:]] = np.exp(theta[:, i])
            else:
                out[name] = theta[:, i]
        return out


@dataclass(frozen=True)
class FitData:
    """The measured rows, the parameter layout and the prior box, for the log-probability.

    Attributes
    ----------
    frequency, voltage, velocity : numpy.ndarray
        Drive frequency [Hz], peak voltage [V], measured velocity amplitude [m/s] per row.
    sweep : numpy.ndarray of int
        Sweep index per row.
    layout : ParameterLayout
    lower, upper : numpy.ndarray
        Prior bounds of each sampled coordinate.
    """

    frequency: np.ndarray
    voltage: np.ndarray
    velocity: np.ndarray
    sweep: np.ndarray
    layout: ParameterLayout
    lower: np.ndarray
    upper: np.ndarray


def fit_data(log: CampaignLog, law_name: str) -> FitData:
    """The :class:`FitData` of a campaign for a law, with its prior box."""
    v_max = float(np.max(log.velocity))
    layout = ParameterLayout(law_name, log.n_sweeps, (("v_top", v_max),) if law_name == MonotoneSpline.name else ())
    exponent = {"quadratic": 2, "linear": 1}
    bounds = {
        "ln_q0": np.log(Q0_RANGE),
        "ln_gain": np.log(GAIN_RANGE),
        "ln_sigma_rel": np.log(SIGMA_REL_RANGE),
        "ln_sigma_abs": np.log(np.asarray(SIGMA_ABS_RANGE) * v_max),
    }
    if law_name in exponent:
        bounds["alpha"] = (0.0, 1.0 / MIN_Q_AT_MAX_VELOCITY / v_max ** exponent[law_name])
    if law_name == ThresholdLoss.name:
        onset = (1 - THRESHOLD_RANGE[1]) * v_max
        bounds["alpha"] = (0.0, 1.0 / MIN_Q_AT_MAX_VELOCITY / onset**2)
        bounds["v_t"] = tuple(np.asarray(THRESHOLD_RANGE) * v_max)
    for name in MonotoneSpline.INCREMENTS:
        bounds[name] = (0.0, MAX_INCREMENT)
    for k in range(log.n_sweeps):
        f = log.frequency[log.sweep == k]
        span = max(f.max() - f.min(), 0.01 * f.mean())
        bounds[f"f_r_{k}"] = (max(f.min() - span, 0.5 * f.min()), f.max() + span)
    lower = np.array([bounds[name][0] for name in layout.names], dtype=float)
    upper = np.array([bounds[name][1] for name in layout.names], dtype=float)
    return FitData(log.frequency, log.drive_voltage, log.velocity, log.sweep, layout, lower, upper)


def predicted_velocity(theta, layout: ParameterLayout, frequency, voltage, sweep) -> np.ndarray:
    """Noise-free velocity amplitude 2 pi f w at each row, one row per walker [m/s].

    Parameters
    ----------
    theta : array (W, D) or (D,)
        Sampled coordinates.
    layout : ParameterLayout
    frequency, voltage : array (N,)
        Drive frequency [Hz] and peak voltage [V].
    sweep : array of int (N,)
        Sweep index of each row (selects f_r).

    Returns
    -------
    numpy.ndarray (W, N)
    """
    theta = np.atleast_2d(theta)
    gain = np.exp(theta[:, layout.gain_index : layout.gain_index + 1])
    resonance = theta[:, layout.resonance_slice][:, sweep]
    deflection = self_consistent_amplitude(gain * voltage, frequency, resonance, layout.law(theta).quality_factor)
    return 2 * np.pi * frequency * deflection


def pointwise_log_likelihood(theta, data: FitData) -> np.ndarray:
    """ln p(v_i | theta) for each walker and row, shape (W, N)."""
    theta = np.atleast_2d(theta)
    model = predicted_velocity(theta, data.layout, data.frequency, data.voltage, data.sweep)
    sigma_rel = np.exp(theta[:, -2:-1])
    sigma_abs = np.exp(theta[:, -1:])
    variance = (sigma_rel * model) ** 2 + sigma_abs**2
    return -0.5 * ((data.velocity - model) ** 2 / variance + np.log(2 * np.pi * variance))


def in_prior(theta, data: FitData) -> np.ndarray:
    """Whether each walker lies inside the prior box, shape (W,)."""
    theta = np.atleast_2d(theta)
    return np.all((theta >= data.lower) & (theta <= data.upper), axis=1)


def log_prior(theta, layout: ParameterLayout) -> np.ndarray:
    """ln of the prior's non-flat part, shape (W,): the flexible law's random walk on its increments."""
    theta = np.atleast_2d(theta)
    if layout.law_name != MonotoneSpline.name:
        return np.zeros(len(theta))
    increments = theta[:, [layout.names.index(name) for name in MonotoneSpline.INCREMENTS]]
    return -0.5 * np.sum(np.square(np.diff(increments, axis=1) / RANDOM_WALK_SCALE), axis=1)


def log_probability(theta, data: FitData) -> np.ndarray:
    """Log-posterior (up to a constant) of each walker, shape (W,); -inf outside the prior.

    Vectorised: ``theta`` is (W, D), as emcee passes it with ``vectorize=True``; a single
    (D,) vector gives shape (1,).
    """
    theta = np.atleast_2d(theta)
    result = np.full(len(theta), -np.inf)
    inside = in_prior(theta, data)
    if inside.any():
        total = pointwise_log_likelihood(theta[inside], data).sum(axis=1) + log_prior(theta[inside], data.layout)
        result[inside] = np.where(np.isfinite(total), total, -np.inf)
    return result


def log_probability_single(theta, data: FitData) -> float:
    """The log-posterior of one parameter vector (D,), as a float (per-walker reference)."""
    return float(log_probability(theta, data)[0])
