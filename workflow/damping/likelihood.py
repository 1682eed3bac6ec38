"""Forward model and log-probability of the sweeps and ring-downs, vectorised over walkers.

Forward model of the sweeps (one resonant mode, amplitude-dependent damping): a row
measured at drive frequency f, peak voltage V and time t in sweep k has the antinode deflection

    w = g V / sqrt((1 - r^2)^2 + (r / Q(v))^2),   r = f / f_r(v, t),   v = 2 pi f w,
    f_r(v, t) = (f_r,k + beta (t - t_k)) (1 - h E(t)) (1 - kappa v^2),
    E(t) = sum over the sweep's rows j read by t of pi f_j u_j^2 dt_j / Q(u_j),

solved self-consistently (:mod:`workflow.damping.harmonic`, the bench simulator's solve),
with t_k the sweep's mean time and E the energy per modal mass the plate has dissipated since the
sweep began (u_j the measured antinode velocity of row j, dt_j the time since the previous reading): a
plate of heat capacity C, modal mass m_eff and relative frequency coefficient c [1/K] heats by
m_eff E / C and has h = -c m_eff / C [kg/J] while the sweep is short beside its cooling time C / G
(:class:`HeatData`; the simulator's plate: h = 2.2e-7 kg/J, C / G = 7.6 min).  Without softening
(kappa) every row is solved at once, with it the rows of each sweep are solved in the order they
were measured, each from the previous one's amplitude (branch following; walkers whose curves are
provably single-valued skip the ordering).  The vibrometer reads v |phi| at its point (|phi| from
the log's ``x_mm``, ``y_mm``, :mod:`~workflow.damping.mode_shape`), so the law is fitted
in the antinode's peak velocity.  A ring-down sample at time t after burst j reads
|phi| v_j(t), the free decay from v_j(0) = v0_j (:mod:`~workflow.damping.ringdown`).

Parameters, in the order of :attr:`ParameterLayout.names`:

- the law's parameters: ``ln_q0`` = ln Q0, ``alpha`` (>= 0) for the velocity-dependent laws,
  ``v_t`` [m/s] and ``ln_onset`` (ln of the onset width over v_t) for the threshold law, ``d1`` .. ``d8`` (>= 0) for the flexible law (whose
  knots are fixed by the data, :func:`spline_knots`, :attr:`ParameterLayout.fixed`);
- with sweeps: ``ln_gain`` (ln g, g the quasi-static deflection per volt [m/V]) and
  ``f_r_<k>``, one resonance frequency per sweep [Hz] (drift between sweeps is free);
- ``kappa`` (softening [s^2/m^2], >= 0), ``drift_rate`` (beta [Hz/s]) and ``heating`` (h [kg/J], >= 0) when fitted;
- with ring-downs: ``ln_v0_<j>``, each burst's initial antinode velocity [m/s], and the
  ring-down record's noise ``ln_sigma_decay_rel``, ``ln_sigma_decay_abs``;
- with sweeps: ``ln_sigma_rel``, ``ln_sigma_abs``: the noise, Gaussian with variance
  (sigma_rel v_model)^2 + sigma_abs^2 (sigma_abs in m/s).

Priors are flat on these coordinates within :attr:`FitData.lower` .. :attr:`FitData.upper`;
the flexible law's slopes of 1/Q in (v / v_top)^2, b_j = d_j v_top^2 / (u_j^2 - u_(j-1)^2), have
in addition a Gaussian random-walk prior, b_{j+1} - b_j ~ N(0, :data:`RANDOM_WALK_SCALE`^2)
(:func:`log_prior`), which keeps 1/Q(v) close to the quadratic law where the data do not say otherwise.
Every function here is module-level and takes arrays, so emcee can pickle it.
"""

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Optional, Tuple

import numpy as np

from workflow.damping.harmonic import (
    self_consistent_roots,
    single_mode_deflection,
    single_valued,
    softened_amplitudes,
    softened_roots,
)
from workflow.damping.laws import LAWS, MonotoneSpline, parameter_names
from workflow.damping.logs import CampaignLog
from workflow.damping.ringdown import burst_decays, decay_quality_factors
from workflow.errors import InputFileError

SAMPLED_LAW_PARAMETERS = {"q0": "ln_q0", "alpha": "alpha", "v_t": "v_t", "onset": "ln_onset",
                          **{d: d for d in MonotoneSpline.INCREMENTS}}
"""Law parameter -> the coordinate it is sampled in (Q0 and the threshold's onset width in log, the others linear)."""


@dataclass(frozen=True)
class ForwardModel:
    """Which effects beyond Q(v) the sweeps' forward model fits.

    Attributes
    ----------
    softening : bool
        Fit kappa in f_r(v) = f_r0 (1 - kappa v^2) (branch-following solve along each sweep).
    drift : bool
        Fit a campaign-wide drift rate of f_r within each sweep (needs ``timestamp_s``).
    heating : bool
        Fit the fall of f_r with the energy the plate has dissipated since its sweep began (its heating while it is
        driven; needs ``timestamp_s``): :meth:`HeatData.energy`.
    """

    softening: bool = False
    drift: bool = False
    heating: bool = False


def default_forward_model(log: CampaignLog) -> ForwardModel:
    """The effects fitted unless the caller says otherwise (issue 29: a fit that left them out blamed the law for their
    mark on the curves, and its band missed the truth): softening whenever the logs have sweeps, drift and heating
    whenever they also have ``timestamp_s``.  Each prior includes the effect's absence (kappa = 0, beta = 0, h = 0);
    the drift's is bounded by :data:`MAX_DRIFT_SHARE`, the heating's by :data:`HEATING_RANGE`."""
    timed = log.n_sweeps > 0 and log.timestamp is not None
    return ForwardModel(softening=log.n_sweeps > 0, drift=timed, heating=timed)


HEATING_RANGE = (0.0, 1e-3 / 300.0)
"""Prior range of the heating coefficient h = |c| m_eff / C [kg/J]: a relative frequency coefficient |c| up to
1e-3 /K (CuBe's is 1.75e-4 /K: half its modulus's) and m_eff / C up to 1 / (300 J/(kg K)) (the modal mass at most the
plate's, the specific heats of metals and ceramics above 300 J/(kg K)); the simulator's plate has 2.2e-7."""
MAX_DRIFT_SHARE = 0.1
"""Prior bound of the drift within a sweep, as a share of the slowest sweep's rate (span / duration) [-]: a resonance
moving by more than a tenth of the span while it is swept leaves no curve to fit, and near the sweep rate the drift
trades against Q (a synthetic campaign without drift, its four sweeps upward, gave Q0 100 [83, 121] for a true 150
with the bound at the full rate)."""
DRIFT_SCALE = 0.5
"""Scale of the drift rate's Gaussian prior, beta ~ N(0, DRIFT_SCALE^2) inside its box [Hz/s].  A drift of the
resonance within a sweep that the plate's own heating does not explain is the bench's surroundings: CuBe's frequency
falls by about 4 Hz/K at 25 kHz, so 0.5 Hz/s is the plate's temperature changing by 7 K a minute, far beyond a lab's
(the heating term follows the plate's own).  With every sweep in one direction the drift trades against Q and is
hardly identified (its 90 % interval about +-1 Hz/s on the bench's campaigns); under the flat box prior the noise
alone could then carry it to 1-1.5 Hz/s and Q 2 % with it (docs/damping.md, "Softening and drift within a sweep")."""
Q0_RANGE = (1.0, 1e5)
"""Prior range of Q0 [-]."""
GAIN_RANGE = (1e-15, 1e-3)
"""Prior range of the quasi-static deflection per volt [m/V]."""
SIGMA_REL_RANGE = (1e-4, 1.0)
"""Prior range of the relative noise [-]."""
SIGMA_ABS_RANGE = (1e-7, 1.0)
"""Prior range of the absolute noise, relative to the largest measured velocity [-]."""
RANDOM_WALK_SCALE = 0.01
"""Standard deviation of the step between consecutive slopes of the flexible law's 1/Q in (v / v_top)^2 [-]:
a change of slope that would move 1/Q(v_top) by 0.01, above the 0.005-0.008 a threshold's onset makes
between two knots (the simulated threshold campaign: Q0 140, alpha 0.45 s^2/m^2, v_t 0.1 m/s)."""
FIRST_KNOT_RANGE = (0.1, 0.6)
"""Bounds of the flexible law's first knot, relative to its last one (the largest antinode velocity) [-]."""


SOLVE_RTOL = 1e-10
"""Tolerance of the self-consistent solves of the sweeps' forward model, on ln w [-]: 1e-10 of the deflection, far
below any vibrometer's noise (0.5 % here)."""
SOFTENING_MAX_SHIFT = 0.2
"""kappa's prior stops where f_r at the highest antinode velocity measured would fall by this fraction [-]."""
V0_RANGE = (0.1, 10.0)
"""Prior range of a burst's initial velocity, relative to its largest sample's antinode velocity [-]."""


@dataclass(frozen=True)
class ParameterLayout:
    """Names and positions of the sampled parameters for a law, the sweeps, the effects fitted and the bursts."""

    law_name: str
    n_sweeps: int
    forward: ForwardModel = ForwardModel()
    n_bursts: int = 0
    fixed: Tuple[Tuple[str, float], ...] = ()
    """Values of the law parameters that are not sampled (name, value): the flexible law's knots ``v_top``, ``v_first`` [m/s]."""

    @property
    def law_parameters(self) -> Tuple[str, ...]:
        """The law's sampled parameter names (``q0``, ``alpha``, ...)."""
        return tuple(name for name in parameter_names(LAWS[self.law_name]) if name in SAMPLED_LAW_PARAMETERS)

    @cached_property
    def names(self) -> Tuple[str, ...]:
        """All sampled coordinates, in order (computed once)."""
        law = tuple(SAMPLED_LAW_PARAMETERS[name] for name in self.law_parameters)
        sweeps = ("ln_gain",) + tuple(f"f_r_{k}" for k in range(self.n_sweeps)) if self.n_sweeps else ()
        effects = (("kappa",) * self.forward.softening + ("drift_rate",) * self.forward.drift
                   + ("heating",) * self.forward.heating)
        bursts = tuple(f"ln_v0_{j}" for j in range(self.n_bursts))
        decay_noise = ("ln_sigma_decay_rel", "ln_sigma_decay_abs") if self.n_bursts else ()
        noise = ("ln_sigma_rel", "ln_sigma_abs") if self.n_sweeps else ()
        return law + sweeps + effects + bursts + decay_noise + noise

    @property
    def dimension(self) -> int:
        return len(self.names)

    @property
    def gain_index(self) -> int:
        return len(self.law_parameters)

    @property
    def resonance_slice(self) -> slice:
        return slice(self.gain_index + 1, self.gain_index + 1 + self.n_sweeps)

    def column(self, theta: np.ndarray, name: str) -> np.ndarray:
        """The coordinate ``name`` of each walker, shape (W, 1)."""
        i = self.names.index(name)
        return np.atleast_2d(theta)[:, i : i + 1]

    def block(self, theta: np.ndarray, prefix: str) -> np.ndarray:
        """The coordinates ``<prefix>0``, ``<prefix>1``, ... of each walker, shape (W, count)."""
        columns = [i for i, name in enumerate(self.names) if name.startswith(prefix) and name[len(prefix):].isdigit()]
        return np.atleast_2d(theta)[:, columns]

    def law(self, theta: np.ndarray):
        """The Q(v) law with one parameter row per walker: parameters of shape (W, 1)."""
        theta = np.atleast_2d(theta)
        values = dict(self.fixed)
        for i, name in enumerate(self.law_parameters):
            column = theta[:, i : i + 1]
            values[name] = np.exp(column) if SAMPLED_LAW_PARAMETERS[name].startswith("ln_") else column
        return LAWS[self.law_name](**values)

    def natural(self, theta: np.ndarray) -> dict:
        """Parameter name -> values in natural units (q0, alpha, gain [m/V], f_r_k [Hz], kappa [s^2/m^2],
        drift_rate [Hz/s], heating [kg/J], v0_j [m/s], sigma_rel, sigma_abs [m/s] and their decay counterparts)."""
        theta = np.atleast_2d(theta)
        out = {}
        for i, name in enumerate(self.names):
            if name.startswith("ln_"):
                out[name[3:]] = np.exp(theta[:, i])
            else:
                out[name] = theta[:, i]
        return out


@dataclass(frozen=True)
class DecayData:
    """Ring-down samples for the log-probability.

    Attributes
    ----------
    frequency : numpy.ndarray
        Burst frequency [Hz] per sample.
    burst : numpy.ndarray of int
    time : numpy.ndarray
        Time since the end of the burst [s].
    mode_factor : numpy.ndarray
        |phi| at the measurement point [-].
    """

    frequency: np.ndarray
    burst: np.ndarray
    time: np.ndarray
    mode_factor: np.ndarray

    @cached_property
    def burst_frequency(self) -> np.ndarray:
        """Frequency of each burst [Hz] (its first sample's), computed once."""
        return self.frequency[np.unique(self.burst, return_index=True)[1]]


@dataclass(frozen=True)
class HeatData:
    """The measured sweep rows as the heating term needs them (:meth:`energy`).

    Attributes
    ----------
    velocity : numpy.ndarray
        Measured antinode velocity of each sweep row [m/s].
    weight : numpy.ndarray
        pi f u^2 dt of each row [m^2/s^2]: the energy per modal mass its drive dissipated until its reading, times Q
        (dt from the previous reading of its sweep, the sweep's median step for the first).
    grid : SweepGrid
        The rows of each sweep in measuring order.
    """

    velocity: np.ndarray
    weight: np.ndarray
    grid: "SweepGrid"

    @classmethod
    def of(cls, log: CampaignLog) -> "HeatData":
        grid = SweepGrid.of(log.sweep)
        time = log.timestamp[grid.index]
        step = np.diff(time, axis=1)
        first = np.array([np.median(row[row > 0]) if np.any(row > 0) else 0.0 for row in step])
        dt = np.maximum(np.concatenate([first[:, None], step], axis=1), 0.0).ravel()[grid.position]
        velocity = log.velocity / log.measurement_factor()
        return cls(velocity, np.pi * log.frequency * velocity**2 * dt, grid)

    def energy(self, quality_factor) -> np.ndarray:
        """Energy per modal mass dissipated in each row's sweep until its reading [J/kg], one row per walker, for
        the Q(u) of each walker's law at the rows' velocities (W, N) [-]: (W, N)."""
        per_row = self.weight / quality_factor
        along = np.cumsum(per_row[:, self.grid.index], axis=2)
        return along.reshape(len(per_row), -1)[:, self.grid.position]


@dataclass(frozen=True)
class FitData:
    """The measured rows, the parameter layout and the prior box, for the log-probability.

    Attributes
    ----------
    frequency, voltage : numpy.ndarray
        Drive frequency [Hz], peak voltage [V] per sweep row.
    velocity : numpy.ndarray
        Measured velocity amplitude [m/s]: the sweep rows, then the ring-down samples.
    sweep : numpy.ndarray of int
        Sweep index per row.
    layout : ParameterLayout
    lower, upper : numpy.ndarray
        Prior bounds of each sampled coordinate.
    time_offset : numpy.ndarray or None
        Time of each row from its sweep's mean time [s] (for the drift).
    mode_factor : numpy.ndarray or None
        |phi| at each row's measurement point [-] (None: 1).
    decays : DecayData or None
    heat : HeatData or None
        The rows as the heating term needs them (with ``forward.heating``).
    """

    frequency: np.ndarray
    voltage: np.ndarray
    velocity: np.ndarray
    sweep: np.ndarray
    layout: ParameterLayout
    lower: np.ndarray
    upper: np.ndarray
    time_offset: Optional[np.ndarray] = None
    mode_factor: Optional[np.ndarray] = None
    decays: Optional[DecayData] = None
    heat: Optional[HeatData] = None

    @property
    def n_rows(self) -> int:
        """Sweep rows [-] (the first entries of :attr:`velocity`)."""
        return len(self.frequency)

    @cached_property
    def sweep_grid(self) -> "SweepGrid":
        """The sweeps' rows in measuring order (:class:`SweepGrid`), computed once."""
        return SweepGrid.of(self.sweep)


def fit_data(log: CampaignLog, law_name: str, forward: ForwardModel = ForwardModel()) -> FitData:
    """The :class:`FitData` of a campaign (sweeps, and its ring-downs if any) for a law, with its prior box.

    Raises
    ------
    InputFileError
        Drift or heating requested of logs without ``timestamp_s``, or softening, drift or heating without sweeps.
    """
    decays = log.ringdown
    layout = ParameterLayout(law_name, log.n_sweeps, forward, decays.n_bursts if decays else 0)
    factor = log.measurement_factor()
    antinode = np.concatenate([log.velocity / factor] + ([decays.velocity / decays.mode_factor] if decays else []))
    v_max = float(np.max(antinode))
    layout = replace(layout, fixed=spline_knots(log, v_max)) if law_name == MonotoneSpline.name else layout
    law = LAWS[law_name]
    bounds = {
        "ln_q0": np.log(Q0_RANGE),
        "ln_gain": np.log(GAIN_RANGE),
        "ln_sigma_rel": np.log(SIGMA_REL_RANGE),
        "ln_sigma_abs": np.log(np.asarray(SIGMA_ABS_RANGE) * v_max),
        "ln_sigma_decay_rel": np.log(SIGMA_REL_RANGE),
        "ln_sigma_decay_abs": np.log(np.asarray(SIGMA_ABS_RANGE) * v_max),
        "kappa": (0.0, SOFTENING_MAX_SHIFT / v_max**2),
        **law.prior_box(v_max),
    }
    for k in range(log.n_sweeps):
        f = log.frequency[log.sweep == k]
        span = max(f.max() - f.min(), 0.01 * f.mean())
        bounds[f"f_r_{k}"] = (max(f.min() - span, 0.5 * f.min()), f.max() + span)
    time_offset = None
    if (forward.softening or forward.drift or forward.heating) and not log.n_sweeps:
        raise InputFileError(f"{', '.join(log.sources + (decays.sources if decays else ()))}: "
                             "softening, drift and heating are fitted from sweeps; no sweep log given")
    if (forward.drift or forward.heating) and log.timestamp is None:
        what = "the drift" if forward.drift else "the heating"
        raise InputFileError(f"{', '.join(log.sources)}: fitting {what} needs the 'timestamp_s' column in every sweep log")
    if forward.drift:
        means = np.array([np.mean(log.timestamp[log.sweep == k]) for k in range(log.n_sweeps)])
        time_offset = log.timestamp - means[log.sweep]
        durations = np.array([np.ptp(time_offset[log.sweep == k]) for k in range(log.n_sweeps)])
        spans = np.array([np.ptp(log.frequency[log.sweep == k]) for k in range(log.n_sweeps)])
        limit = MAX_DRIFT_SHARE * float(np.min(spans / np.maximum(durations, 1e-9)))
        bounds["drift_rate"] = (-limit, limit)
    heat = HeatData.of(log) if forward.heating else None
    bounds["heating"] = HEATING_RANGE
    decay_data = None
    if decays:
        decay_data = DecayData(decays.frequency, decays.burst, decays.decay_time, decays.mode_factor)
        for j in range(decays.n_bursts):
            largest = float(np.max((decays.velocity / decays.mode_factor)[decays.burst == j]))
            bounds[f"ln_v0_{j}"] = np.log(np.asarray(V0_RANGE) * largest)
    lower = np.array([bounds[name][0] for name in layout.names], dtype=float)
    upper = np.array([bounds[name][1] for name in layout.names], dtype=float)
    velocity = np.concatenate([log.velocity] + ([decays.velocity] if decays else []))
    return FitData(log.frequency, log.drive_voltage, velocity, log.sweep, layout, lower, upper, time_offset,
                   log.mode_factor, decay_data, heat)


def spline_knots(log: CampaignLog, v_top: float) -> Tuple[Tuple[str, float], ...]:
    """The flexible law's fixed knots (("v_top", v_top), ("v_first", u_1)) [m/s] for a campaign.

    u_1 is the smallest sweep peak (antinode velocity): below it no sweep reaches its resonance,
    so the law there is the parabola the data just above it support; kept within
    :data:`FIRST_KNOT_RANGE` of ``v_top``; without sweeps, v_top / 3.
    """
    antinode = log.velocity / log.measurement_factor()
    peaks = [np.max(antinode[log.sweep == k]) for k in range(log.n_sweeps)]
    first = min(peaks) if peaks else v_top / 3
    return ("v_top", v_top), ("v_first", float(np.clip(first, *(np.asarray(FIRST_KNOT_RANGE) * v_top))))


def sweep_order(sweep: np.ndarray) -> np.ndarray:
    """Row indices of each sweep present, in measuring order (the rows' order), shape (S, P), each padded with its last index."""
    rows = [np.nonzero(sweep == k)[0] for k in np.unique(sweep)]
    width = max(len(r) for r in rows)
    return np.array([np.r_[r, np.full(width - len(r), r[-1])] for r in rows])


@dataclass(frozen=True)
class SweepGrid:
    """The rows of each sweep in measuring order on a (sweeps, points) grid, and the way back.

    Attributes
    ----------
    index : numpy.ndarray of int (S, P)
        :func:`sweep_order`.
    position : numpy.ndarray of int (N,)
        Each row's first place in ``index.ravel()``.
    """

    index: np.ndarray
    position: np.ndarray

    @classmethod
    def of(cls, sweep: np.ndarray) -> "SweepGrid":
        index = sweep_order(np.asarray(sweep))
        return cls(index, np.unique(index.ravel(), return_index=True)[1])


def predicted_velocity(theta, layout: ParameterLayout, frequency, voltage, sweep, time_offset=None,
                       mode_factor=None, grid: Optional[SweepGrid] = None, warm: Optional["WarmStarts"] = None,
                       heat: Optional[HeatData] = None) -> np.ndarray:
    """Noise-free velocity amplitude at the measurement point, 2 pi f w |phi|, at each sweep row, one row per walker [m/s].

    Parameters
    ----------
    theta : array (W, D) or (D,)
        Sampled coordinates.
    layout : ParameterLayout
    frequency, voltage : array (N,)
        Drive frequency [Hz] and peak voltage [V], rows of each sweep in measuring order.
    sweep : array of int (N,)
        Sweep index of each row (selects f_r).
    time_offset : array (N,), optional
        Time from the sweep's mean time [s] (drift); default 0.
    mode_factor : array (N,), optional
        |phi| at the measurement point [-]; default 1.
    grid : SweepGrid, optional
        ``SweepGrid.of(sweep)``, when already computed (with softening).
    warm : WarmStarts, optional
        Solutions of walkers evaluated before, to start the softened solve from (:class:`WarmStarts`).
    heat : HeatData, optional
        The measured rows, for the heating term (rows as ``frequency``); without it, no heating.

    Returns
    -------
    numpy.ndarray (W, N)
    """
    theta = np.atleast_2d(theta)
    frequency, voltage = np.asarray(frequency, dtype=float), np.asarray(voltage, dtype=float)
    gain = np.exp(theta[:, layout.gain_index : layout.gain_index + 1])
    resonance = theta[:, layout.resonance_slice][:, sweep]
    if layout.forward.drift and time_offset is not None:
        resonance = resonance + layout.column(theta, "drift_rate") * time_offset
    if layout.forward.heating and heat is not None:
        resonance = resonance * (1.0 - layout.column(theta, "heating") * heat.energy(layout.law(theta).quality_factor(heat.velocity)))
    if layout.forward.softening:
        deflection = _softened_rows(theta, layout, gain * voltage, frequency, resonance, grid or SweepGrid.of(sweep), warm)
    else:
        start, slope = (None, None) if warm is None else warm.nearest(theta)
        roots, slope = self_consistent_roots(single_mode_deflection(gain * voltage, frequency, resonance),
                                             layout.law(theta).quality_factor, 2 * np.pi * frequency, SOLVE_RTOL, start=start,
                                             slope=slope)
        deflection = np.exp(roots)
        if warm is not None:
            warm.add(theta, roots, slope)
    return 2 * np.pi * frequency * deflection * (1.0 if mode_factor is None else mode_factor)


def _softened_rows(theta, layout: ParameterLayout, static, frequency, resonance, grid: SweepGrid,
                   warm: Optional["WarmStarts"] = None) -> np.ndarray:
    """Deflection at each row with softening: sweeps in measuring order; branch following only for the walkers
    whose curves may fold (:func:`~workflow.damping.harmonic.single_valued`); the others solved at once, from the
    nearest walker ``warm`` holds when given."""
    kappa, law = layout.column(theta, "kappa"), layout.law(theta)
    points = (static[:, grid.index], frequency[grid.index], resonance[:, grid.index])
    single = single_valued(*points, kappa, law.quality_factor).all(axis=1)
    solved = np.empty(points[0].shape)
    at_once = np.nonzero(single)[0]
    if at_once.size:
        chosen, chosen_law = (slice(None), law) if single.all() else (at_once, layout.law(theta[at_once]))
        start, slope = (None, None) if warm is None else warm.nearest(theta[chosen])
        roots, slope = softened_roots(points[0][chosen], points[1], points[2][chosen], kappa[chosen],
                                      chosen_law.quality_factor, start, 1.0 if slope is None else slope, SOLVE_RTOL)
        solved[chosen] = np.exp(roots)
        if warm is not None:
            warm.add(theta[chosen], roots, slope)
    walkers = np.nonzero(~single)[0]
    if walkers.size:
        solved[walkers] = softened_amplitudes(points[0][walkers], points[1], points[2][walkers], kappa[walkers],
                                              layout.law(theta[walkers]).quality_factor, rtol=SOLVE_RTOL)
    return solved.reshape(len(solved), -1)[:, grid.position]


class WarmStarts:
    """The softened solve's roots (ln w on the sweep grid) and slopes of the walkers evaluated last, to start nearby
    walkers from: a Markov chain's proposals and a gradient's batch lie close to walkers already solved.

    Used only where the root is unique (:func:`~workflow.damping.harmonic.single_valued`): any start reaches it, a
    near one in about 4 residual evaluations instead of 9 from the small-amplitude response.  The result differs
    from a cold start's only within the solve's tolerance (1e-10 in ln w), so a log-probability with warm starts
    depends on what was evaluated before at that level only.  Nearest: in the coordinates scaled by their spread
    among the walkers held.

    Parameters
    ----------
    capacity : int
        Walkers held (the most recent, in a ring) [-].
    """

    def __init__(self, capacity: int = 64):
        self.capacity = capacity
        self.held = self.next = 0
        self.theta = self.roots = self.slope = None

    def nearest(self, theta: np.ndarray):
        """(roots, slope) of the walker held nearest each row of ``theta`` (W, D); (None, None) when none is held."""
        if not self.held:
            return None, None
        held = self.theta[: self.held]
        spread = np.std(held, axis=0)
        scaled, points = held / np.where(spread > 0, spread, 1.0), theta / np.where(spread > 0, spread, 1.0)
        distance = np.sum(np.square(scaled), axis=1) - 2 * points @ scaled.T  # + |point|^2, the same for every walker held
        near = np.argmin(distance, axis=1)
        return self.roots[near], self.slope[near]

    def add(self, theta: np.ndarray, roots: np.ndarray, slope: np.ndarray) -> None:
        """Hold the walkers ``theta`` (W, D) whose every root was found (not NaN), with their ``roots`` and ``slope`` (W, ...)."""
        good = np.nonzero(~np.any(np.isnan(roots.reshape(len(roots), -1)), axis=1))[0][-self.capacity:]
        if self.theta is None:
            self.theta, self.roots, self.slope = (np.empty((self.capacity,) + x.shape[1:]) for x in (theta, roots, slope))
        place = (self.next + np.arange(len(good))) % self.capacity
        self.theta[place], self.roots[place], self.slope[place] = theta[good], roots[good], slope[good]
        self.next = (self.next + len(good)) % self.capacity
        self.held = min(self.held + len(good), self.capacity)


def predicted_decay(theta, layout: ParameterLayout, decays: DecayData) -> np.ndarray:
    """Noise-free ring-down envelope at the measurement point, |phi| v_j(t), at each sample, one row per walker [m/s]."""
    theta = np.atleast_2d(theta)
    initial = np.exp(layout.block(theta, "ln_v0_"))
    return burst_decays(layout.law(theta), decays.burst_frequency, initial, decays.burst, decays.time) * decays.mode_factor


def _gaussian(measured, model, sigma_rel, sigma_abs, mean=None):
    """ln N(measured | mean, (sigma_rel model)^2 + sigma_abs^2), the mean ``model`` unless given."""
    variance = (sigma_rel * model) ** 2 + sigma_abs**2
    mean = model if mean is None else mean
    return -0.5 * ((measured - mean) ** 2 / variance + np.log(2 * np.pi * variance))


def envelope_reading(envelope, sigma_abs):
    """What a magnitude detector reads on average for an envelope in a noise floor: sqrt(A^2 + sigma_abs^2) [m/s].

    A lock-in's R (or any |X + iY|) of an envelope A [m/s] plus complex Gaussian noise of sigma_abs [m/s] per
    quadrature is Rice-distributed: it reads high by about sigma_abs^2 / (2 A) where A is not far above the floor.
    A ring-down's tail reaches the floor; fitted as if it read A, its slow-looking tail raised Q0 and alpha (over
    40 seeded simulated ring-downs the truth sat in the 90 % intervals of Q0 and alpha 70 % and 65 % of the time, its
    z-score centred at -0.7; with this mean 85 % and 75 %, centred at -0.1 and -0.3: bench/bench_ringdown_coverage.py)."""
    return np.sqrt(np.square(envelope) + np.square(sigma_abs))


def pointwise_log_likelihood(theta, data: FitData, warm: Optional[WarmStarts] = None) -> np.ndarray:
    """ln p(v_i | theta) for each walker and measured value (sweep rows, then ring-down samples), shape (W, N);
    ``warm``: :class:`WarmStarts` for the softened solve."""
    theta = np.atleast_2d(theta)
    layout = data.layout
    parts = []
    if layout.n_sweeps:
        grid = data.sweep_grid if layout.forward.softening else None
        model = predicted_velocity(theta, layout, data.frequency, data.voltage, data.sweep, data.time_offset, data.mode_factor,
                                   grid, warm, data.heat)
        noise = (np.exp(layout.column(theta, name)) for name in ("ln_sigma_rel", "ln_sigma_abs"))
        parts.append(_gaussian(data.velocity[: data.n_rows], model, *noise))
    if data.decays is not None:
        model = predicted_decay(theta, layout, data.decays)
        sigma_rel, sigma_abs = (np.exp(layout.column(theta, name)) for name in ("ln_sigma_decay_rel", "ln_sigma_decay_abs"))
        parts.append(_gaussian(data.velocity[data.n_rows :], model, sigma_rel, sigma_abs, envelope_reading(model, sigma_abs)))
    return np.concatenate(parts, axis=1)


def initial_effects(data: FitData) -> Tuple[dict, dict]:
    """Start and scale of the coordinates beyond the law, gain, resonances and noise: kappa, drift, bursts, decay noise."""
    start, scale = {}, {}
    names = data.layout.names
    if "kappa" in names:
        index = names.index("kappa")
        start["kappa"], scale["kappa"] = 0.01 * data.upper[index], 0.01 * data.upper[index]
    if "drift_rate" in names:
        start["drift_rate"], scale["drift_rate"] = 0.0, 0.01 * data.upper[names.index("drift_rate")]
    if "heating" in names:
        index = names.index("heating")
        start["heating"], scale["heating"] = 0.01 * data.upper[index], 0.01 * data.upper[index]
    if data.decays is not None:
        measured = data.velocity[data.n_rows :] / data.decays.mode_factor
        for j in range(data.layout.n_bursts):
            mine = data.decays.burst == j
            start[f"ln_v0_{j}"] = np.log(measured[mine][np.argmin(data.decays.time[mine])])
            scale[f"ln_v0_{j}"] = 0.02
        start["ln_sigma_decay_rel"], scale["ln_sigma_decay_rel"] = np.log(0.03), 0.5
        start["ln_sigma_decay_abs"], scale["ln_sigma_decay_abs"] = np.log(0.01 * np.max(measured)), 0.5
    return start, scale


def decay_estimates(data: FitData) -> Tuple[np.ndarray, np.ndarray]:
    """Model-free (antinode velocity [m/s], Q [-]) points from the ring-downs (empty without them)."""
    if data.decays is None:
        return np.zeros(0), np.zeros(0)
    d = data.decays
    return decay_quality_factors(d.frequency, data.velocity[data.n_rows :] / d.mode_factor, d.burst, d.time)


def in_prior(theta, data: FitData) -> np.ndarray:
    """Whether each walker lies inside the prior box, shape (W,)."""
    theta = np.atleast_2d(theta)
    return np.all((theta >= data.lower) & (theta <= data.upper), axis=1)


def log_prior(theta, layout: ParameterLayout) -> np.ndarray:
    """ln of the prior's non-flat part, shape (W,): the drift rate's Gaussian (:data:`DRIFT_SCALE`) and the flexible
    law's random walk on its slopes."""
    theta = np.atleast_2d(theta)
    drift = (-0.5 * np.square(layout.column(theta, "drift_rate")[:, 0] / DRIFT_SCALE)
             if "drift_rate" in layout.names else np.zeros(len(theta)))
    if layout.law_name != MonotoneSpline.name:
        return drift
    increments = theta[:, [layout.names.index(name) for name in MonotoneSpline.INCREMENTS]]
    fixed = dict(layout.fixed)
    squared = np.square(MonotoneSpline.knots(fixed["v_top"], fixed["v_first"]))
    slopes = increments / np.diff(squared) * fixed["v_top"] ** 2  # of 1/Q in (v / v_top)^2
    return drift - 0.5 * np.sum(np.square(np.diff(slopes, axis=1) / RANDOM_WALK_SCALE), axis=1)


def log_probability(theta, data: FitData, warm: Optional[WarmStarts] = None) -> np.ndarray:
    """Log-posterior (up to a constant) of each walker, shape (W,); -inf outside the prior.

    Vectorised: ``theta`` is (W, D), as emcee passes it with ``vectorize=True``; a single
    (D,) vector gives shape (1,).  ``warm``: :class:`WarmStarts` for the softened solve (a chain, a MAP search).
    """
    theta = np.atleast_2d(theta)
    result = np.full(len(theta), -np.inf)
    inside = in_prior(theta, data)
    if inside.any():
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            total = pointwise_log_likelihood(theta[inside], data, warm).sum(axis=1) + log_prior(theta[inside], data.layout)
        result[inside] = np.where(np.isfinite(total), total, -np.inf)
    return result


def log_probability_single(theta, data: FitData) -> float:
    """The log-probability of one parameter vector (D,), as a float (per-walker reference)."""
    return float(log_probability(theta, data)[0])
