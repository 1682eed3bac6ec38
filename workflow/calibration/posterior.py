"""Posterior of the calibration parameters given what the built plates' logs measured (emcee).

Likelihood (docs/calibration.md), each term only for the plates whose logs have it:

* resonance: ln f_meas,j ~ N(ln S_j(theta), sigma_j^2) with sigma_j^2 = measurement^2 +
  surrogate leave-one-out^2 + FEM discretisation^2 (all relative), S_j the plate's surrogate
  (:mod:`workflow.calibration.plate_surrogate`);
* deflection per volt per Q: ln g_meas,j ~ N(ln G_j(theta), deflection^2 + leave-one-out^2);
* scan pattern: each point p, m_p ~ N(s P_j,p(theta), noise^2 + leave-one-out_p^2), s = +-1 the
  sign that aligns the patterns (:func:`~workflow.calibration.measurements.aligned_misfit`).

Priors from :class:`~workflow.calibration.parameters.CalibrationSettings`.  Samples are SI values.
"""

import math
import time
from dataclasses import dataclass
from typing import Sequence

import emcee
import numpy as np

from workflow.calibration.measurements import aligned_misfit
from workflow.calibration.parameters import CalibrationSettings
from workflow.calibration.plate_surrogate import PlateSurrogate

CHAIN_TAUS = 50
"""A chain counts as converged when it is at least this many autocorrelation times long [-]."""
CONSTRAINED_RATIO = 0.5
"""A direction is constrained when its posterior standard deviation is below this share of the prior's [-]."""
BOUND_ZONE = 0.1
"""Share of a prior's range next to each bound in which :func:`prior_bounds` compares posterior and prior mass [-]."""
BOUND_EXCESS = 2.0
"""A posterior sits at a bound when it puts at least this many times the prior's mass in the bound's zone [-]..."""
BOUND_MIN_SHARE = 0.1
"""... and at least this share of its samples [-] (a normal prior's thin tail next to its bound is not a pile-up)."""


@dataclass(frozen=True)
class CalibrationData:
    """What the likelihood needs: priors, one surrogate and one measured frequency per plate.

    Attributes
    ----------
    settings : CalibrationSettings
    surrogates : tuple of PlateSurrogate
    log_measured : numpy.ndarray
        ln of the measured frequencies [-] (Hz inside the log).
    sigma : numpy.ndarray
        Relative standard deviation of each plate's residual [-].
    deflections : tuple
        Per plate, None or (ln of the measured deflection per volt [-] (m/V inside the log), its relative sd [-]).
    patterns : tuple
        Per plate, None or (measured pattern (n_points,) [-], sd of each point (n_points,) [-]).
    """

    settings: CalibrationSettings
    surrogates: tuple
    log_measured: np.ndarray
    sigma: np.ndarray
    deflections: tuple = ()
    patterns: tuple = ()


def calibration_data(settings: CalibrationSettings, surrogates: Sequence[PlateSurrogate], measured: Sequence[float],
                     deflections: Sequence = (), scans: Sequence = ()) -> CalibrationData:
    """Bundle the likelihood's inputs, one entry per surrogate.

    Parameters
    ----------
    measured : sequence of float
        Resonance frequencies [Hz].
    deflections : sequence of float or None
        Deflection per volt per Q [m/V], None where a plate's logs have none (empty: none at all).
    scans : sequence of ScanShape or None
        Scanned patterns, None where a plate has no scan; its surrogate then needs a ``shape``.
    """
    sigma = np.array([np.hypot(settings.measurement_sigma, s.frequency_sigma) for s in surrogates])
    deflection_terms = tuple(
        None if g is None else (float(np.log(g)), float(np.hypot(settings.deflection_sigma, s.log_point_deflection.loo_rms)))
        for g, s in zip(deflections, surrogates)
    )
    pattern_terms = tuple(None if scan is None else (np.asarray(scan.pattern), np.hypot(scan.noise, s.shape.errors))
                          for scan, s in zip(scans, surrogates))
    return CalibrationData(settings, tuple(surrogates), np.log(np.asarray(measured, dtype=float)), sigma,
                           deflection_terms, pattern_terms)


def log_probability(theta: np.ndarray, data: CalibrationData) -> np.ndarray:
    """Log posterior of parameter vectors ``theta`` (n_walkers, n) [SI] up to a constant (vectorised)."""
    prior = data.settings.log_prior(theta)
    inside = np.isfinite(prior)
    clipped = np.clip(theta, data.settings.bounds[:, 0], data.settings.bounds[:, 1])
    predicted = np.stack([s.log_frequency(clipped) for s in data.surrogates], axis=-1)
    likelihood = -0.5 * np.sum(((data.log_measured - predicted) / data.sigma) ** 2, axis=-1)
    for surrogate, term in zip(data.surrogates, data.deflections):
        if term is not None:
            likelihood = likelihood - 0.5 * ((term[0] - surrogate.log_point_deflection(clipped)) / term[1]) ** 2
    for surrogate, term in zip(data.surrogates, data.patterns):
        if term is not None:
            misfit = aligned_misfit(term[0], surrogate.shape(clipped)) / term[1]
            likelihood = likelihood - 0.5 * np.sum(misfit**2, axis=-1)
    return np.where(inside, prior + likelihood, -np.inf)


@dataclass(frozen=True)
class ChainDiagnostics:
    """Convergence of the sampler.

    Attributes
    ----------
    tau : tuple of float
        Integrated autocorrelation time per parameter [steps].
    n_steps, n_walkers, burn_in : int
    acceptance : float
        Mean acceptance fraction [-].
    seconds : float
        Wall time of the sampling [s].
    """

    tau: tuple
    n_steps: int
    n_walkers: int
    burn_in: int
    acceptance: float
    seconds: float

    def __post_init__(self):
        counts = (self.n_steps, self.n_walkers, self.burn_in)
        if not (self.tau and all(math.isfinite(t) and t > 0 for t in self.tau)):
            raise ValueError(f"chain diagnostics: tau must be positive finite times, got {self.tau!r}")
        if not (all(isinstance(n, int) and n >= 0 for n in counts) and 0 <= self.acceptance <= 1
                and math.isfinite(self.seconds) and self.seconds >= 0):
            raise ValueError("chain diagnostics: steps, walkers and burn-in must be counts, acceptance in [0, 1]")

    @property
    def steps_per_tau(self) -> float:
        """Run length over the largest autocorrelation time [-]."""
        return self.n_steps / max(self.tau)

    @property
    def converged(self) -> bool:
        """At least :data:`CHAIN_TAUS` autocorrelation times and a sane acceptance (0.1 to 0.9)."""
        return self.steps_per_tau >= CHAIN_TAUS and 0.1 <= self.acceptance <= 0.9

    def to_dict(self) -> dict:
        return {
            "tau": list(self.tau),
            "tau_max": max(self.tau),
            "n_steps": self.n_steps,
            "n_walkers": self.n_walkers,
            "burn_in": self.burn_in,
            "steps_per_tau": self.steps_per_tau,
            "acceptance": self.acceptance,
            "converged": self.converged,
            "rule": f"n_steps >= {CHAIN_TAUS} tau_max and acceptance in [0.1, 0.9]",
            "seconds": self.seconds,
        }

    @classmethod
    def from_dict(cls, data: dict) -> "ChainDiagnostics":
        return cls(tuple(data["tau"]), data["n_steps"], data["n_walkers"], data["burn_in"], data["acceptance"], data["seconds"])


def sample_posterior(data: CalibrationData) -> tuple[np.ndarray, ChainDiagnostics]:
    """Run emcee for ``settings.steps`` steps from prior draws; keep ``settings.kept_samples`` after burn-in.

    Returns
    -------
    samples : numpy.ndarray
        (kept, n) posterior samples [SI], evenly thinned after a burn-in of 2 tau_max.
    diagnostics : ChainDiagnostics
    """
    settings = data.settings
    rng = np.random.default_rng(settings.sampler_seed)
    start = np.stack([p.draw(settings.walkers, rng) for p in settings.parameters], axis=1)
    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(settings.walkers, len(settings.parameters), log_probability, args=(data,),
                                    vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(settings.sampler_seed).get_state()
    began = time.perf_counter()
    sampler.run_mcmc(start, settings.steps, progress=False)
    seconds = time.perf_counter() - began
    tau = sampler.get_autocorr_time(tol=0)
    tau = np.where(np.isfinite(tau), tau, settings.steps)
    burn_in = int(min(2 * np.max(tau), settings.steps // 2))
    chain = sampler.get_chain(discard=burn_in, flat=True)
    kept = chain[np.linspace(0, len(chain) - 1, min(settings.kept_samples, len(chain))).astype(int)]
    diagnostics = ChainDiagnostics(
        tau=tuple(float(t) for t in tau),
        n_steps=settings.steps,
        n_walkers=settings.walkers,
        burn_in=burn_in,
        acceptance=float(np.mean(sampler.acceptance_fraction)),
        seconds=seconds,
    )
    return kept, diagnostics


def parameter_summary(settings: CalibrationSettings, samples: np.ndarray) -> dict:
    """name -> {median, p05, p95} in display units (factors [-], lengths [um])."""
    summary = {}
    for k, parameter in enumerate(settings.parameters):
        p05, p50, p95 = np.percentile(samples[:, k], [5, 50, 95]) / parameter.display_scale
        summary[parameter.name] = {"median": float(p50), "p05": float(p05), "p95": float(p95), "unit": parameter.unit}
    return summary


def prior_bounds(settings: CalibrationSettings, samples: np.ndarray, seed: int = 0) -> dict:
    """Parameters whose posterior sits at a prior bound: name -> "at lower prior bound" or "at upper prior bound".

    A posterior sits at a bound when its mass in the outer :data:`BOUND_ZONE` of the prior's range next to
    that bound is at least :data:`BOUND_EXCESS` times the prior's own mass there and at least
    :data:`BOUND_MIN_SHARE` (the data push the parameter against the bound; the bound, not the data,
    then limits it).
    """
    rng = np.random.default_rng(seed)
    flagged = {}
    for k, parameter in enumerate(settings.parameters):
        prior = parameter.draw(20_000, rng)
        zone = BOUND_ZONE * (parameter.high - parameter.low)
        for side, near in (("lower", lambda v: v <= parameter.low + zone), ("upper", lambda v: v >= parameter.high - zone)):
            if np.mean(near(samples[:, k])) >= max(BOUND_EXCESS * np.mean(near(prior)), BOUND_MIN_SHARE):
                flagged[parameter.name] = f"at {side} prior bound"
    return flagged


def identifiability(settings: CalibrationSettings, samples: np.ndarray) -> dict:
    """Which combinations of the parameters the data constrain.

    In coordinates standardised by the prior (z = (theta - prior mean) / prior sd) the prior's
    covariance is about the identity; the eigenvectors of the posterior covariance of z are the
    principal directions, and the square root of each eigenvalue is the posterior standard
    deviation along it as a share of the prior's.  A direction below :data:`CONSTRAINED_RATIO`
    is constrained; the others trade off within their prior.

    Returns
    -------
    dict
        ``correlations`` (pair "a|b" -> posterior correlation), ``directions`` (list of
        ``{weights: {name: component}, sd_ratio, constrained}``, most constrained first),
        ``constrained`` (count) and ``statement`` (one sentence).
    """
    mean, sd = settings.prior_scale()
    z = (samples - mean) / sd
    covariance = np.cov(z, rowvar=False)
    names = settings.names
    correlation = np.corrcoef(samples, rowvar=False)
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    directions = []
    for value, vector in zip(eigenvalues, eigenvectors.T):
        vector = vector * np.sign(vector[np.argmax(np.abs(vector))])
        ratio = float(np.sqrt(max(value, 0.0)))
        directions.append({
            "weights": {name: float(w) for name, w in zip(names, vector)},
            "sd_ratio": ratio,
            "constrained": ratio < CONSTRAINED_RATIO,
        })
    n_constrained = sum(d["constrained"] for d in directions)
    statement = (
        f"{n_constrained} of {len(names)} combinations of the parameters {'is' if n_constrained == 1 else 'are'} constrained by the data "
        f"(posterior sd < {CONSTRAINED_RATIO:g} x prior sd along them); "
        + ("the others trade off and stay near their priors" if n_constrained < len(names) else "all are constrained")
    )
    return {
        "correlations": {f"{a}|{b}": float(correlation[i, j]) for i, a in enumerate(names) for j, b in enumerate(names) if i < j},
        "directions": directions,
        "constrained": n_constrained,
        "statement": statement,
    }


def predictive_quantiles(surrogate: PlateSurrogate, samples: np.ndarray, seed: int = 0, quantiles=(5, 50, 95)) -> dict:
    """Quantiles of f_r [Hz] and w [m] of a plate over posterior samples, surrogate and FEM error included.

    Each sample's ln f gets an independent normal error of the surrogate's ``frequency_sigma``, and
    ln w one of the deflection surface's leave-one-out error.
    """
    rng = np.random.default_rng(seed)
    bounds = np.asarray(surrogate.log_frequency.bounds)
    clipped = np.clip(samples, bounds[:, 0], bounds[:, 1])
    log_f = surrogate.log_frequency(clipped) + rng.normal(0, surrogate.frequency_sigma, len(samples))
    log_w = surrogate.log_deflection(clipped) + rng.normal(0, surrogate.log_deflection.loo_rms, len(samples))
    return {
        "frequency": np.exp(np.percentile(log_f, quantiles)),
        "deflection": np.exp(np.percentile(log_w, quantiles)),
    }
