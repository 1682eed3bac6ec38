"""Bayesian fit of Q(v) to interferometer sweeps with emcee, and the comparison of laws.

Steps, for each law: model-free estimates per sweep (peak, half-power bandwidth) give a
start; L-BFGS-B finds the maximum a posteriori (MAP) with a gradient from one batched
finite-difference evaluation; a finite-difference Hessian there gives a Laplace
covariance from which the walkers start; emcee then runs until the project's one convergence
rule holds (:mod:`workflow.sampling`: 50 integrated autocorrelation times, tau stable to 1 %),
or until the step cap.

:func:`fit_damping` screens the laws at their MAP (BIC within :data:`SCREEN_BIC` of the
best are sampled, and the flexible law always), compares the sampled laws by PSIS-LOO
(:mod:`workflow.damping.comparison`), checks their misfit (:mod:`workflow.damping.checks`) and picks
the answer the design uses: the best law, the laws the data do not tell apart mixed in equal shares, or
the flexible law when the best law fails its checks.  BIC at the MAP is also given for every law.
"""

from dataclasses import dataclass, field, replace
from typing import Callable, Dict, Optional, Sequence, Tuple

import arviz as az
import numpy as np
from scipy import optimize
from threadpoolctl import threadpool_limits

from workflow.damping.checks import MisfitCheck, misfit_check
from workflow.damping.comparison import CLOSE_DSE, CRITERION, LawComparison, answer_shares, compare_laws
from workflow.damping.inference_data import law_inference_data, loo_draws
from workflow.damping.laws import LAWS, SAMPLED_LAWS, MonotoneSpline, ThresholdLoss, parameter_names
from workflow.damping.likelihood import (
    DRIFT_SCALE,
    FitData,
    ForwardModel,
    ParameterLayout,
    WarmStarts,
    decay_estimates,
    default_forward_model,
    fit_data,
    in_prior,
    initial_effects,
    log_probability,
    pointwise_log_likelihood,
)
from workflow.damping.logs import CampaignLog, drop_short_sweeps
from workflow.damping.posterior import DampingPosterior, stacked_posterior, with_shape_discrepancy
from workflow.resonance import half_power_bandwidth
from workflow.sampling import CHAIN_TAUS, ChainDiagnostics, quantile_summary, run_ensemble

DEFAULT_LAWS = SAMPLED_LAWS
"""The laws screened and sampled by default; every law of :data:`~workflow.damping.laws.LAWS` gets a MAP and a BIC."""
FALLBACK_LAW = MonotoneSpline.name
"""The law the answer falls back to when the best law fails its misfit checks."""
SCREEN_BIC = 10.0
"""Laws whose BIC at the MAP is more than this above the best law's are not sampled [-]: odds of
about e^5 = 150 to 1 against them (a law that only adds parameters to a law that fits lands here)."""
VELOCITY_CONVENTION = "v: peak velocity amplitude at the antinodes (measured velocities divided by |phi| at their point)"
"""The velocity Q(v) is a function of (docs/damping.md)."""
COMPARISON_TAUS = 25
"""The same for each law of :func:`fit_damping` [-]: with 32-72 walkers, 25 tau give 800-1800
effectively independent draws, plenty for 90 % bands and LOO.  The rule's other half (tau stable
to 1 %) often sets the length anyway: 4100-6200 steps, 90-130 tau, on the simulated campaigns."""
STACKED_DRAWS = 4000
"""Draws of a stacked (model-averaged) posterior [-]."""
SHAPE_DISCREPANCY = 0.003
"""Relative sd of the law-shape discrepancy in the answer [-]: each posterior sample's Q(v) is multiplied by
exp(N(0, 0.003^2)) at every velocity, the amount by which the laws miss smooth Q(v) curves they do not contain below
what one campaign can show.  Calibrated on the 40 simulated truths of seed 2030 (the smallest sd, on a 0.1 % grid,
whose band holds the truth at 90 % of the velocities on average, as a 90 % band should), validated on seed 2029's
(docs/damping.md, coverage over truths the fit does not contain)."""


single_threaded_blas = threadpool_limits.wrap(limits=1, user_api="blas")
"""Decorator: BLAS on one thread while a fit runs.  Its matrices are tiny (L-BFGS-B's, the Laplace covariance's), and
a threaded BLAS spins on them: the MAP's L-BFGS-B steps took 2.5 ms each instead of 0.05 ms on the 2 shared cores."""


_FD_STEP = 1e-4
"""Finite-difference step in standardised coordinates."""


@dataclass(frozen=True)
class SweepEstimates:
    """Model-free estimates per sweep.

    Attributes
    ----------
    voltage : numpy.ndarray
        Drive voltage of the sweep [V].
    peak_frequency : numpy.ndarray
        Frequency of the largest velocity [Hz].
    peak_velocity : numpy.ndarray
        Largest velocity [m/s].
    quality_factor : numpy.ndarray
        Half-power-bandwidth Q = f_peak / (f_2 - f_1) [-]; NaN where no crossing was seen.
    """

    voltage: np.ndarray
    peak_frequency: np.ndarray
    peak_velocity: np.ndarray
    quality_factor: np.ndarray


@dataclass(frozen=True)
class LawFit:
    """The posterior of one law.

    Attributes
    ----------
    data : FitData
    samples : numpy.ndarray (M, D)
        Posterior samples in the sampled coordinates (after burn-in, thinned).
    theta_map : numpy.ndarray (D,)
        The MAP.
    log_likelihood_map : float
    diagnostics : ChainDiagnostics
    bic : float
        BIC at the MAP (lower is better).
    trace : numpy.ndarray (S, W, D)
        The whole chain, subsampled to at most a few hundred steps, for trace plots.
    loo : tuple of numpy.ndarray
        At most 2000 draws (S', W, D), their log-posterior (S', W) and pointwise log-likelihood
        (S', W, N) (:func:`~workflow.damping.inference_data.loo_draws`), plain arrays so that a
        fit can be cached; :attr:`inference_data` builds the ArviZ object from them.
    """

    data: FitData
    samples: np.ndarray
    theta_map: np.ndarray
    log_likelihood_map: float
    diagnostics: ChainDiagnostics
    bic: float
    trace: np.ndarray = field(repr=False)
    loo: Tuple[np.ndarray, np.ndarray, np.ndarray] = field(repr=False)

    @property
    def inference_data(self) -> az.InferenceData:
        """The posterior with its log-likelihood, for LOO and ``posterior.nc`` (:mod:`workflow.damping.inference_data`)."""
        return law_inference_data(*self.loo, self.data)

    @property
    def law_name(self) -> str:
        return self.data.layout.law_name

    def laws(self):
        """The law with one parameter row per posterior sample, parameters of shape (M, 1)."""
        return self.data.layout.law(self.samples)

    def posterior(self) -> DampingPosterior:
        """The law's parameters' samples in natural units, for design and for the posterior file."""
        law, shape = self.laws(), (len(self.samples), 1)
        names = parameter_names(LAWS[self.law_name])
        return DampingPosterior(self.law_name, {name: np.ravel(np.broadcast_to(getattr(law, name), shape)) for name in names})

    def quality_factor_quantiles(self, velocity, quantiles=(0.05, 0.5, 0.95)) -> np.ndarray:
        """Posterior quantiles of Q at each velocity [m/s] -> array (len(quantiles), len(velocity))."""
        return np.quantile(self.laws().quality_factor(np.asarray(velocity)[None, :]), quantiles, axis=0)


@dataclass(frozen=True)
class DampingFit:
    """Result of :func:`fit_damping`.

    Attributes
    ----------
    log : CampaignLog
    sweeps : SweepEstimates
    fits : dict
        Law name -> :class:`LawFit` for the sampled laws.
    map_criteria : dict
        Law name -> {"log_likelihood", "n_parameters", "aic", "bic", "sampled"} at the MAP, every law.
    preferred : str
        The screened law with the highest elpd_loo (before a fallback adds the flexible law).
    comparison : LawComparison
    checks : dict
        Law name -> :class:`~workflow.damping.checks.MisfitCheck` of each sampled law.
    selection : str
        What the design uses: ``"best"`` (the preferred law), ``"mixture"`` (the laws the data do not tell
        apart, in equal shares: :func:`~workflow.damping.comparison.answer_shares`) or ``"fallback"`` (the
        flexible law, the preferred law having failed its checks).
    shares : dict
        Law name -> its share of the answer [-].
    answer : DampingPosterior
        The posterior the design uses (``posterior.npz``).
    agreement : RingdownAgreement or None
        Q(v) of the sweeps alone against the ring-downs alone (preferred law), when the log has both.
    """

    log: CampaignLog
    sweeps: SweepEstimates
    fits: Dict[str, LawFit]
    map_criteria: Dict[str, dict]
    preferred: str
    comparison: LawComparison
    checks: Dict[str, MisfitCheck]
    selection: str
    shares: Dict[str, float]
    answer: DampingPosterior
    agreement: Optional["RingdownAgreement"] = None

    @property
    def best(self) -> LawFit:
        return self.fits[self.preferred]

    @property
    def warning(self) -> Optional[str]:
        """One line when the preferred law failed its misfit checks, else None."""
        check = self.checks[self.preferred]
        if check.passed:
            return None
        fallback = FALLBACK_LAW if self.selection == "fallback" else self.answer.law_name
        return f"the {self.preferred} law fails its misfit checks ({check.reasons[0]}); the answer uses the {fallback} law"


def sweep_estimates(log: CampaignLog) -> SweepEstimates:
    """Peak and half-power-bandwidth quality factor of every sweep (model-free, :mod:`workflow.resonance`)."""
    rows = [(np.nan,) * 4] if not log.n_sweeps else []
    for k in range(log.n_sweeps):
        mine = log.sweep == k
        order = np.argsort(log.frequency[mine])
        f, v = log.frequency[mine][order], log.velocity[mine][order]
        peak = int(np.argmax(v))
        rows.append((np.median(log.drive_voltage[mine]), f[peak], v[peak], f[peak] / half_power_bandwidth(f, v)))
    voltage, frequency, velocity, q = (np.array(column) for column in zip(*rows))
    return SweepEstimates(voltage, frequency, velocity, q)


def initial_guess(data: FitData, sweeps: SweepEstimates) -> Tuple[np.ndarray, np.ndarray]:
    """A starting point and a scale per coordinate, from the model-free estimates.

    The law is a least-squares line of 1/Q against v^2 (quadratic), v (linear) or a mean
    (constant) through the per-sweep (peak velocity, half-power Q) points; the threshold
    law starts from that quadratic line with v_t at 10 % of the largest velocity, the
    flexible law from its increments between knots; the gain is v_peak / (2 pi f_peak Q V).
    """
    layout = data.layout
    ok = np.isfinite(sweeps.quality_factor)
    decay_velocity, decay_q = decay_estimates(data)
    ok_q, ok_v = np.r_[sweeps.quality_factor[ok], decay_q], np.r_[sweeps.peak_velocity[ok], decay_velocity]
    q = ok_q if ok_q.size else np.array([50.0])
    velocity = ok_v if ok_v.size else np.array([np.max(data.velocity)])
    loss = 1 / q
    start, scale = {}, {}
    exponent = LAWS[layout.law_name].velocity_exponent or None
    alpha_upper = data.upper[layout.names.index("alpha")] if "alpha" in layout.names else 0.0
    if exponent is None or len(q) < 2:
        intercept, slope = float(np.mean(loss)), 0.01 * alpha_upper
    else:
        slope, intercept = np.polyfit(velocity**exponent, loss, 1)
        if slope <= 0 or intercept <= 0:
            intercept, slope = 0.5 * float(np.min(loss)), 0.5 * float(np.mean(loss)) / float(np.mean(velocity**exponent))
    start["ln_q0"], scale["ln_q0"] = np.log(1 / intercept), 0.1
    start["alpha"], scale["alpha"] = slope, max(0.1 * slope, 1e-4 * alpha_upper)
    v_max = float(np.max(data.velocity))
    start["v_t"], scale["v_t"] = 0.1 * v_max, 0.05 * v_max
    start["ln_onset"], scale["ln_onset"] = np.log(ThresholdLoss.onset), 0.3
    fixed = dict(layout.fixed)
    knots = MonotoneSpline.knots(fixed.get("v_top", v_max), fixed.get("v_first"))
    for name, rise in zip(MonotoneSpline.INCREMENTS, slope * np.diff(knots**2)):
        start[name], scale[name] = max(rise, 1e-6), max(0.1 * rise, 1e-5)
    peak_q = np.where(np.isfinite(sweeps.quality_factor), sweeps.quality_factor, np.median(q))
    gains = sweeps.peak_velocity / (2 * np.pi * sweeps.peak_frequency * peak_q * np.maximum(sweeps.voltage, 1e-12))
    start["ln_gain"], scale["ln_gain"] = np.log(np.median(gains)), 0.1
    for k in range(layout.n_sweeps):
        start[f"f_r_{k}"], scale[f"f_r_{k}"] = sweeps.peak_frequency[k], sweeps.peak_frequency[k] / peak_q[k] / 10
    start["ln_sigma_rel"], scale["ln_sigma_rel"] = np.log(0.03), 0.5
    start["ln_sigma_abs"], scale["ln_sigma_abs"] = np.log(0.01 * np.max(data.velocity)), 0.5
    effects = initial_effects(data)
    start.update(effects[0])
    scale.update(effects[1])
    theta = np.array([start[name] for name in layout.names])
    margin = 1e-6 * (data.upper - data.lower)
    return np.clip(theta, data.lower + margin, data.upper - margin), np.array([scale[name] for name in layout.names])


def maximum_a_posteriori(data: FitData, start: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """The MAP by L-BFGS-B in standardised coordinates z = (theta - start) / s, s the coordinate ``scale``
    rescaled by the curvature at each stage's start (:func:`_maximise`).

    Two stages: the physical parameters with the noise held at its starting value (so
    the optimiser cannot explain the sweeps away as noise), then everything.  The
    gradient is a central difference computed as one batched evaluation; points are
    clipped into the prior box, so the objective stays finite up to the bounds.
    """
    physical = np.array([not name.startswith("ln_sigma") for name in data.layout.names])
    theta = _maximise(data, start, scale, physical)
    return _maximise(data, theta, scale, np.ones(len(start), dtype=bool))


PRECONDITION_RANGE = 1e-3, 1e3
"""Bounds of the factor by which the start's curvature rescales a coordinate of the MAP search [-]."""
LINE_SEARCH_STEPS = 8
"""Evaluations of one L-BFGS-B line search at most (scipy's default 20) [-]: the smooth laws take 1-3; only the
constant-Q baseline, whose softened curves fold and jump, spent its time in failing line searches."""


def _maximise(data: FitData, start: np.ndarray, scale: np.ndarray, free: np.ndarray) -> np.ndarray:
    """L-BFGS-B on the coordinates marked ``free``; the others stay at ``start``.

    Preconditioned: each free coordinate's scale is set by the log-posterior's curvature along it at ``start``
    (second differences of the first gradient's batch), so that the search sees unit curvature on every axis;
    where the curvature is not positive the given scale stays (within :data:`PRECONDITION_RANGE` of it).
    """
    n = int(free.sum())
    step = np.zeros((n, len(start)))
    step[np.arange(n), np.nonzero(free)[0]] = _FD_STEP
    offsets = np.vstack([np.zeros(len(start)), step, -step])
    warm = WarmStarts()
    values = log_probability(np.clip(start + offsets * scale, data.lower, data.upper), data, warm)
    with np.errstate(invalid="ignore", divide="ignore"):
        curvature = -(values[1 : n + 1] + values[n + 1 :] - 2 * values[0]) / _FD_STEP**2
        factor = np.where(np.isfinite(curvature) & (curvature > 0), 1 / np.sqrt(curvature), 1.0)
    scale = scale.copy()
    scale[free] *= np.clip(factor, *PRECONDITION_RANGE)

    def theta_of(z):
        theta = start.copy()
        theta[free] += z * scale[free]
        return theta

    def negative_and_gradient(z):
        values = log_probability(np.clip(theta_of(z) + offsets * scale, data.lower, data.upper), data, warm)
        if not np.isfinite(values[0]):
            return 1e300, np.zeros(n)
        values = np.where(np.isfinite(values), values, values[0])
        return -values[0], -(values[1 : n + 1] - values[n + 1 :]) / (2 * _FD_STEP)

    bounds = list(zip(((data.lower - start) / scale)[free], ((data.upper - start) / scale)[free]))
    result = optimize.minimize(negative_and_gradient, np.zeros(n), jac=True, method="L-BFGS-B", bounds=bounds,
                               options={"maxiter": 5000, "maxls": LINE_SEARCH_STEPS})
    return np.clip(theta_of(result.x), data.lower, data.upper)


def laplace_covariance(data: FitData, theta: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Covariance -H^-1 of the log-posterior at ``theta`` (finite-difference Hessian, one batch).

    Eigenvalues of -H that are not positive are replaced by the coordinate scale's, so the
    result is always a usable covariance.
    """
    n = len(theta)
    h = 10 * _FD_STEP
    signs = np.array([(1, 1), (1, -1), (-1, 1), (-1, -1)])
    rows = []
    for i in range(n):
        for j in range(n):
            for si, sj in signs:
                z = np.zeros(n)
                z[i] += si * h
                z[j] += sj * h
                rows.append(z)
    values = log_probability(theta + np.array(rows) * scale, data).reshape(n, n, 4)
    with np.errstate(invalid="ignore", over="ignore"):  # -inf at a prior edge: handled below
        hessian = (values[..., 0] - values[..., 1] - values[..., 2] + values[..., 3]) / (4 * h * h)
    precision = -0.5 * (hessian + hessian.T)
    if not np.all(np.isfinite(precision)):
        return np.diag(scale**2)
    eigenvalues, vectors = np.linalg.eigh(precision)
    eigenvalues = np.where(eigenvalues > 1e-12, eigenvalues, 1.0)
    covariance_z = (vectors / eigenvalues) @ vectors.T
    return covariance_z * np.outer(scale, scale)


def initial_walkers(data: FitData, theta: np.ndarray, covariance: np.ndarray, n_walkers: int, rng) -> np.ndarray:
    """Walkers drawn from N(theta, covariance), redrawn until inside the prior and finite."""
    walkers = np.empty((n_walkers, len(theta)))
    filled = 0
    for _ in range(100):
        draws = rng.multivariate_normal(theta, covariance, size=n_walkers, method="eigh")
        good = draws[np.isfinite(log_probability(draws, data))]
        take = min(len(good), n_walkers - filled)
        walkers[filled : filled + take] = good[:take]
        filled += take
        if filled == n_walkers:
            return walkers
        covariance = 0.25 * covariance
    raise RuntimeError("could not place the walkers inside the prior around the MAP")


def bic(log_likelihood: float, n_parameters: int, n_points: int) -> float:
    """BIC = -2 ln L + k ln n."""
    return float(-2 * log_likelihood + n_parameters * np.log(n_points))


@single_threaded_blas
def map_fit(log: CampaignLog, law_name: str, sweeps: Optional[SweepEstimates] = None, forward: ForwardModel = ForwardModel()):
    """MAP of one law: (FitData, theta_map, scale, log-likelihood at the MAP)."""
    data = fit_data(log, law_name, forward)
    start, scale = initial_guess(data, sweeps or sweep_estimates(log))
    theta = maximum_a_posteriori(data, start, scale)
    return data, theta, scale, float(pointwise_log_likelihood(theta, data).sum())


def aic(log_likelihood: float, n_parameters: int) -> float:
    """AIC = -2 ln L + 2 k."""
    return float(-2 * log_likelihood + 2 * n_parameters)


def minimum_walkers(laws: Sequence[str], n_sweeps: int, forward: ForwardModel = ForwardModel(), n_bursts: int = 0) -> int:
    """Fewest walkers emcee's differential-evolution moves accept for ``laws`` fitted to ``n_sweeps`` sweeps and
    ``n_bursts`` ring-downs: twice the largest number of sampled parameters (law, gain, one resonance per sweep,
    softening, drift and heating, one initial velocity per burst, noise)."""
    return 2 * max(ParameterLayout(name, n_sweeps, forward, n_bursts).dimension for name in laws)


@single_threaded_blas
def fit_law(
    log: CampaignLog,
    law_name: str,
    seed: int = 0,
    n_walkers: Optional[int] = None,
    max_steps: int = 20000,
    max_seconds: Optional[float] = None,
    check_every: int = 100,
    progress: bool = False,
    sweeps: Optional[SweepEstimates] = None,
    forward: ForwardModel = ForwardModel(),
    chain_taus: float = CHAIN_TAUS,
    start: Optional[tuple] = None,
) -> LawFit:
    """MAP, Laplace start and emcee posterior of one Q(v) law.

    Parameters
    ----------
    log : CampaignLog
    law_name : str
        A key of :data:`~workflow.damping.laws.LAWS`.
    seed : int
        Seeds the initial walkers and emcee's generator.
    n_walkers : int, optional
        Default: max(32, 2 D + 2), even (twice the dimension suffices for the differential-evolution moves;
        on the joint softening fit 42 walkers reach the same tau in steps as 80, at half the cost).
    max_steps, max_seconds, check_every : int, float, int
        Caps on the chain and the convergence-check interval [steps, s, steps].
    progress : bool
        Show the chain's progress towards convergence on stderr.
    sweeps : SweepEstimates, optional
    forward : ForwardModel
        Softening and drift fitted beyond Q(v) (default: neither).
    chain_taus : float
        Chain length the convergence rule asks for, in autocorrelation times [-].
    start : tuple, optional
        The law's :func:`map_fit` result, when already computed.
    """
    data, theta_map, scale, log_likelihood = start or map_fit(log, law_name, sweeps, forward)
    rng = np.random.default_rng(seed)
    n_dim = data.layout.dimension
    n_walkers = max(n_walkers, 2 * n_dim) if n_walkers else max(32, 2 * n_dim + 2)
    n_walkers += n_walkers % 2
    covariance = laplace_covariance(data, theta_map, scale)
    walkers = initial_walkers(data, theta_map, covariance, n_walkers, rng)
    sampler, diagnostics = run_ensemble(
        log_probability, walkers, int(rng.integers(2**31)), (data, WarmStarts()), max_steps, chain_taus, check_every,
        max_seconds, progress, f"emcee, {law_name} law",
    )
    kept = sampler.get_chain(discard=diagnostics.burn_in, thin=diagnostics.thin)
    chain = sampler.get_chain()
    return LawFit(
        data=data,
        samples=kept.reshape(-1, n_dim),
        theta_map=theta_map,
        log_likelihood_map=log_likelihood,
        diagnostics=diagnostics,
        bic=bic(log_likelihood, n_dim, len(data.velocity)),
        trace=chain[:: max(1, len(chain) // 400)],
        loo=loo_draws(kept, sampler.get_log_prob(discard=diagnostics.burn_in, thin=diagnostics.thin), data),
    )


def _fit_law_task(task: tuple) -> LawFit:
    """:func:`fit_law` on (log, law_name, seed, n_walkers, max_steps, max_seconds, progress, sweeps,
    forward, chain_taus, start), for a process pool."""
    log, name, seed, n_walkers, max_steps, max_seconds, progress, sweeps, forward, chain_taus, start = task
    return fit_law(log, name, seed, n_walkers, max_steps, max_seconds, progress=progress, sweeps=sweeps,
                   forward=forward, chain_taus=chain_taus, start=start)


@single_threaded_blas
def fit_damping(
    log: CampaignLog,
    laws: Sequence[str] = DEFAULT_LAWS,
    seed: int = 0,
    max_steps: int = 20000,
    max_seconds: Optional[float] = None,
    progress: bool = False,
    n_walkers: Optional[int] = None,
    forward: Optional[ForwardModel] = None,
    stated_noise: Optional[float] = None,
    chain_taus: float = COMPARISON_TAUS,
    mapper: Optional[Callable] = None,
) -> DampingFit:
    """Screen, sample and compare the ``laws``, check the best one and choose the answer.

    Parameters
    ----------
    log : CampaignLog
        From :func:`~workflow.damping.logs.read_logs`; sweeps too short to locate their
        resonance are dropped (:func:`~workflow.damping.logs.drop_short_sweeps`).
    laws : sequence of str
        Candidate laws (keys of :data:`~workflow.damping.laws.LAWS`); those within
        :data:`SCREEN_BIC` of the best BIC at the MAP are sampled, and the flexible law whenever it is a
        candidate (it nests the others up to its knots: the measure of what their shapes leave out).
    seed : int
    max_steps : int
        Cap on each chain [steps].
    max_seconds : float, optional
        Cap on each chain's wall time [s].
    progress : bool
    n_walkers : int, optional
        Walkers per chain (default max(32, 2 D + 2)).
    forward : ForwardModel, optional
        Softening and drift fitted beyond Q(v); default
        :func:`~workflow.damping.likelihood.default_forward_model`: both when the logs can show them.
    stated_noise : float, optional
        The instrument's relative velocity noise [-], for the misfit check.
    chain_taus : float
        Chain length in autocorrelation times (:func:`convergence_rule`) [-].
    mapper : callable, optional
        ``mapper(function, items) -> list`` running the laws' samplers, e.g. side by side with
        :func:`~workflow.execution.parallel.map_evaluations`; default: one after the other here.

    Returns
    -------
    DampingFit
        ``preferred`` has the highest elpd_loo; ``answer`` is the preferred law, the laws within
        :data:`~workflow.damping.comparison.CLOSE_DSE` dse of it that pass their checks mixed in equal
        shares, or, when the preferred law fails :func:`~workflow.damping.checks.misfit_check`, the
        flexible law (sampled then if it was not).
    """
    log = drop_short_sweeps(log)
    forward = default_forward_model(log) if forward is None else forward
    sweeps = sweep_estimates(log)
    maps = {name: map_fit(log, name, sweeps, forward) for name in dict.fromkeys((*laws, *LAWS))}
    n_points = len(log.velocity) + (0 if log.ringdown is None else len(log.ringdown.velocity))
    criteria = {}
    for name, (data, _, _, log_likelihood) in maps.items():
        k = data.layout.dimension
        criteria[name] = {"log_likelihood": log_likelihood, "n_parameters": k, "aic": aic(log_likelihood, k),
                          "bic": bic(log_likelihood, k, n_points)}
    lowest = min(criteria[name]["bic"] for name in laws)
    screened = [name for name in laws if criteria[name]["bic"] <= lowest + SCREEN_BIC]

    def sample(names):
        shown = progress and (mapper is None or len(names) == 1)  # a chain's own progress unless several run at once
        tasks = [(log, name, seed, n_walkers, max_steps, max_seconds, shown, sweeps, forward, chain_taus, maps[name])
                 for name in names]
        alone = mapper is None or len(names) == 1
        results = [_fit_law_task(task) for task in tasks] if alone else mapper(_fit_law_task, tasks)
        return dict(zip(names, results))

    def check(name):
        flexible = criteria[FALLBACK_LAW]
        alternative = (
            None if name == FALLBACK_LAW
            else (flexible["log_likelihood"] - criteria[name]["log_likelihood"], flexible["n_parameters"] - criteria[name]["n_parameters"])
        )
        return misfit_check(fits[name].samples, fits[name].data, stated_noise, seed, alternative)

    fits = sample(list(dict.fromkeys(screened + [name for name in laws if name == FALLBACK_LAW])))
    checks = {name: check(name) for name in fits}
    comparison = compare_laws({name: f.inference_data for name, f in fits.items()})
    preferred = comparison.best
    if not checks[preferred].passed and FALLBACK_LAW not in fits:
        fits.update(sample([FALLBACK_LAW]))
        checks[FALLBACK_LAW] = check(FALLBACK_LAW)
        comparison = compare_laws({name: f.inference_data for name, f in fits.items()})
    for name in criteria:
        criteria[name]["sampled"] = name in fits
    if not checks[preferred].passed and preferred != FALLBACK_LAW:
        selection, shares = "fallback", {FALLBACK_LAW: 1.0}
    else:
        shares = answer_shares(comparison, {name: check.passed for name, check in checks.items()})
        selection = "mixture" if len(shares) > 1 else "best"
    posteriors = {name: fits[name].posterior() for name in shares}
    answer = posteriors[next(iter(shares))] if len(shares) == 1 else stacked_posterior(posteriors, shares, STACKED_DRAWS, seed)
    answer = with_shape_discrepancy(answer, SHAPE_DISCREPANCY, seed)
    agreement = ringdown_agreement(log, preferred, forward, seed) if log.n_sweeps and log.ringdown is not None else None
    return DampingFit(log, sweeps, fits, criteria, preferred, comparison, checks, selection, shares, answer, agreement)


AGREEMENT_Z = 3.0
"""Sweeps and ring-downs agree when their Q differs by less than this many combined standard deviations at every
velocity compared [-]."""
AGREEMENT_VELOCITIES = 5
"""Antinode velocities compared, spanning the range both measurements cover [-]."""
LAPLACE_DRAWS = 2000
"""Draws of a Laplace approximation (MAP and covariance) for the agreement [-]."""


@dataclass(frozen=True)
class RingdownAgreement:
    """Q(v) of one law fitted to the sweeps alone and to the ring-downs alone: two independent measurements of Q.

    Each side is its MAP with a Laplace covariance (:func:`laplace_covariance`; draws inside the prior), not a chain.

    Attributes
    ----------
    law_name : str
    velocity : numpy.ndarray
        Antinode velocities compared, spanning the range both measurements cover [m/s] (empty: no common range).
    sweeps, ringdowns : numpy.ndarray (3, V)
        Q at ``velocity``: p05, p50, p95 [-].
    z : numpy.ndarray (V,)
        Difference of the medians over the combined standard deviation (p95 - p05 = 3.29 sigma) [-].
    """

    law_name: str
    velocity: np.ndarray
    sweeps: np.ndarray
    ringdowns: np.ndarray
    z: np.ndarray

    @property
    def agree(self) -> Optional[bool]:
        """|z| below :data:`AGREEMENT_Z` everywhere; None without a common velocity range."""
        return bool(np.all(np.abs(self.z) < AGREEMENT_Z)) if self.velocity.size else None

    def summary(self) -> dict:
        """JSON-able: velocities, both sides' quantiles, z, the verdict and how it was computed."""
        sides = {name: {"q_p05": q[0], "q_p50": q[1], "q_p95": q[2]} for name, q in (("sweeps", self.sweeps),
                                                                                     ("ringdowns", self.ringdowns))}
        return {"law": self.law_name, "v_m_s": self.velocity, **sides, "z": self.z, "agree": self.agree,
                "max_abs_z": float(np.max(np.abs(self.z))) if self.z.size else None,
                "rule": f"|z| < {AGREEMENT_Z:g} at every velocity; each side its MAP with a Laplace covariance"}


def laplace_quality_factors(log: CampaignLog, law_name: str, velocity: np.ndarray, forward: ForwardModel = ForwardModel(),
                            seed: int = 0) -> np.ndarray:
    """Q at ``velocity`` [m/s] from the MAP and Laplace covariance of ``law_name`` on ``log``: p05, p50, p95, shape (3, V)."""
    data, theta, scale, _ = map_fit(log, law_name, forward=forward)
    draws = np.random.default_rng(seed).multivariate_normal(theta, laplace_covariance(data, theta, scale), LAPLACE_DRAWS,
                                                            method="eigh")
    inside = draws[in_prior(draws, data)]
    return np.quantile(data.layout.law(inside).quality_factor(velocity[None, :]), (0.05, 0.5, 0.95), axis=0)


def ringdown_agreement(log: CampaignLog, law_name: str, forward: ForwardModel = ForwardModel(), seed: int = 0) -> RingdownAgreement:
    """Q(v) of ``law_name`` from the sweeps alone against the ring-downs alone, where both measured (:class:`RingdownAgreement`)."""
    decays = log.ringdown
    sweeps_only = replace(log, ringdown=None)
    ringdowns_only = CampaignLog(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, dtype=int), decays.sources,
                                 ringdown=decays)
    swept, decayed = log.velocity / log.measurement_factor(), decays.velocity / decays.mode_factor
    low, high = max(swept.min(), decayed.min()), min(swept.max(), decayed.max())
    velocity = np.linspace(low, high, AGREEMENT_VELOCITIES) if low < high else np.zeros(0)
    sides = [laplace_quality_factors(part, law_name, velocity, effects, seed)
             for part, effects in ((sweeps_only, forward), (ringdowns_only, ForwardModel()))]
    sigma = np.hypot(*((q[2] - q[0]) / 3.29 for q in sides))
    return RingdownAgreement(law_name, velocity, *sides, (sides[0][1] - sides[1][1]) / sigma)


_UNITS = {"gain": "m/V", "sigma_rel": "-", "sigma_abs": "m/s", "kappa": "s^2/m^2", "drift_rate": "Hz/s",
          "heating": "kg/J", "sigma_decay_rel": "-", "sigma_decay_abs": "m/s"}
"""Units of the fitted parameters beside the law's own (the law's are in its ``units``)."""


def parameter_unit(law_name: str, name: str) -> str:
    """Unit of the fitted parameter ``name`` of the law ``law_name`` (``"-"`` when dimensionless)."""
    law_units = LAWS[law_name].units
    return "Hz" if name.startswith("f_r_") else "m/s" if name.startswith("v0_") else law_units.get(name) or _UNITS[name]


def parameter_summary(law_fit: LawFit) -> dict:
    """Name -> {median, p05, p95, unit} in natural units (f_r_k in Hz)."""
    return {name: quantile_summary(values, unit=parameter_unit(law_fit.law_name, name))
            for name, values in law_fit.data.layout.natural(law_fit.samples).items()}


def diagnostics_summary(law_fit: LawFit) -> dict:
    """The chain's convergence figures, JSON-able."""
    return {**law_fit.diagnostics.to_dict(law_fit.data.layout.names), "n_samples": len(law_fit.samples)}


def velocity_grid(log: CampaignLog, n: int = 50) -> np.ndarray:
    """n antinode velocities spanning the measured ones (sweeps and ring-downs) [m/s]."""
    velocity = log.velocity / log.measurement_factor()
    if log.ringdown is not None:
        velocity = np.r_[velocity, log.ringdown.velocity / log.ringdown.mode_factor]
    return np.linspace(float(np.min(velocity)), float(np.max(velocity)), n)


def ringdown_summary(fit: DampingFit, parameters: dict) -> Optional[dict]:
    """The ring-downs in ``fit.json``: per burst its level, fitted initial velocity and temperature; the decay
    noise fitted; the agreement of sweeps and ring-downs (None without ring-downs).  ``parameters``: the
    preferred law's :func:`parameter_summary`."""
    decays = fit.log.ringdown
    if decays is None:
        return None
    bursts = []
    for j in range(decays.n_bursts):
        mine = decays.burst == j
        temperature = float(np.nanmedian(decays.temperature[mine])) if np.any(np.isfinite(decays.temperature[mine])) else None
        bursts.append({"burst": j, "voltage_v": float(np.median(decays.drive_voltage[mine])), "samples": int(mine.sum()),
                       "v0_m_s": parameters[f"v0_{j}"], "temperature_c": temperature})
    return {
        "n_bursts": decays.n_bursts,
        "n_samples": int(len(decays.velocity)),
        "bursts": bursts,
        "sigma_decay_rel": parameters["sigma_decay_rel"],
        "agreement": None if fit.agreement is None else fit.agreement.summary(),
    }


SOFTENING_DETECTED = 0.25
"""Softening is detected when its posterior's 5 % quantile exceeds this share of its median [-]: a posterior piled
against kappa = 0 (no softening) has 0.09, one clear of zero by three standard errors 0.5 or more."""


def effects_summary(fit: DampingFit, parameters: dict) -> dict:
    """Softening, drift and heating: whether the fit modelled them and whether the logs show them (``parameters``: the
    preferred law's :func:`parameter_summary`).  Softening and heating are detected by :data:`SOFTENING_DETECTED`
    (their priors start at zero); a drift when its 90 % interval excludes zero."""
    forward = fit.best.data.layout.forward

    def from_zero(name):
        value = parameters.get(name)
        return None if value is None else bool(value["p05"] > SOFTENING_DETECTED * value["median"])

    drift = parameters.get("drift_rate")
    return {
        "softening": {"fitted": forward.softening, "detected": from_zero("kappa"),
                      "rule": f"kappa's 5 % quantile is above {SOFTENING_DETECTED:g} of its median"},
        "drift": {"fitted": forward.drift,
                  "detected": None if drift is None else bool(drift["p05"] > 0 or drift["p95"] < 0),
                  "rule": "the drift rate's 90 % interval excludes zero",
                  **({} if forward.drift else {"not_fitted_because": _left_out(fit.log, "drift")})},
        "heating": {"fitted": forward.heating, "detected": from_zero("heating"),
                    "rule": f"the heating coefficient's 5 % quantile is above {SOFTENING_DETECTED:g} of its median",
                    **({} if forward.heating else {"not_fitted_because": _left_out(fit.log, "heating")})},
    }


def _left_out(log: CampaignLog, effect: str) -> str:
    """Why a fit did not model the timed ``effect`` ("drift" or "heating") of the sweeps (:func:`default_forward_model`)."""
    if not log.n_sweeps:
        return "the logs have no sweeps"
    if log.timestamp is None:
        return "the logs have no timestamp_s"
    return f"left out by the caller (fit-damping --no-{effect}, or [damping] {effect} = false in tactile run)"


def band_contents(fit: DampingFit) -> dict:
    """What the 90 % band of Q(v) (``q_of_v``, and the draws the design uses) contains and what it does not."""
    laws = ", ".join(f"{name} {share:.2g}" for name, share in fit.shares.items())
    forward = fit.best.data.layout.forward
    effects = [name for name, fitted in (("the softening", forward.softening), ("the drift", forward.drift),
                                         ("the heating", forward.heating)) if fitted]
    return {
        "contains": [
            "the measurement noise (fitted: relative and absolute)",
            "the posterior of each law's parameters with the nuisance parameters (gain, each sweep's resonance"
            + "".join(f", {name}" for name in effects) + ")",
            f"the law's shape: the laws the data do not tell apart (PSIS-LOO within {CLOSE_DSE:g} dse) in equal shares "
            f"({laws}); the flexible law is always among the candidates",
            f"a law-shape discrepancy: Q within {100 * SHAPE_DISCREPANCY:g} % (1 sd) of every law's at all velocities, "
            "by which the laws miss smooth Q(v) curves they do not contain below what one campaign shows (calibrated on "
            "simulated truths)",
        ],
        "does_not_contain": [
            "Q(v) outside the measured velocities (the laws extrapolate)",
            "another plate's Q(v): the fit is of the plate measured",
            "the drift of Q itself with temperature or time beyond the resonance's drift",
            *([] if forward.heating else [
                "a shift of the resonance that follows the amplitude with a lag, as the plate's heating while it is "
                "driven (not fitted: a steady drift rate cannot follow it; on the simulated bench it made Q 1-5 % high, "
                "outside the band: docs/damping.md#coverage-over-truths-the-fit-does-not-contain)"]),
            *(["the plate's cooling within a sweep (the heating term counts the energy dissipated since the sweep "
               "began; the drift rate takes up a steady cooling)"] if forward.heating else []),
            *([f"a drift of the resonance well beyond its prior's scale ({DRIFT_SCALE:g} Hz/s, the plate's temperature "
               "changing by about 7 K a minute): with every sweep in one direction such a drift is partly taken for Q "
               "(campaigns with alternating sweeps tell them apart)"] if forward.drift else []),
            "a measurement point or a velocity calibration other than the logs say",
        ],
    }


def fit_summary(fit: DampingFit) -> dict:
    """The JSON of ``tactile fit-damping`` (docs/cli.md): the answer, the preferred law, the comparison and the checks."""
    best = fit.best
    parameters = parameter_summary(best)
    velocity = velocity_grid(fit.log)
    q05, q50, q95 = np.quantile(fit.answer.law_from_samples().quality_factor(velocity[:, None]), (0.05, 0.5, 0.95), axis=1)
    comparison = {
        "criterion": CRITERION,
        "preferred": fit.preferred,
        "selection": fit.selection,
        "shares": fit.shares,
        "weights": fit.comparison.weights,
        "loo": fit.comparison.laws,
        "pareto_k_warning": fit.comparison.pareto_warning,
        "screen": f"laws with BIC at the MAP within {SCREEN_BIC:g} of the best are sampled",
        "laws": fit.map_criteria,
    }
    return {
        "law": fit.preferred,
        "selection": fit.selection,
        "design_law": fit.answer.law_name,
        "weights": fit.comparison.weights,
        "warning": fit.warning,
        "checks": {name: check.summary() for name, check in fit.checks.items()},
        "parameters": parameters,
        "shares": fit.shares,
        "q_of_v": {"v_m_s": velocity, "q_p05": q05, "q_p50": q50, "q_p95": q95, "law": fit.answer.law_name,
                   "interval": band_contents(fit)},
        "diagnostics": diagnostics_summary(best),
        "comparison": comparison,
        "other_laws": {
            name: {"parameters": parameter_summary(f), "diagnostics": diagnostics_summary(f)}
            for name, f in fit.fits.items()
            if name != fit.preferred
        },
        "sweeps": {
            "voltage_v": fit.sweeps.voltage,
            "peak_velocity_m_s": fit.sweeps.peak_velocity,
            "half_power_q": [None if not np.isfinite(q) else float(q) for q in fit.sweeps.quality_factor],
        },
        "forward_model": {"softening": best.data.layout.forward.softening, "drift": best.data.layout.forward.drift,
                          "heating": best.data.layout.forward.heating},
        "effects": effects_summary(fit, parameters),
        "ringdown": ringdown_summary(fit, parameters),
        "velocity_convention": VELOCITY_CONVENTION,
        "n_points": int(len(fit.log.velocity)),
        "n_ringdown_samples": 0 if fit.log.ringdown is None else int(len(fit.log.ringdown.velocity)),
        "n_sweeps": fit.log.n_sweeps,
        "sources": list(fit.log.sources),
    }
