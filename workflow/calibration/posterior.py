"""Posterior of the calibration parameters given what the built plates' logs measured (emcee).

Likelihood (docs/calibration.md), each term only for the plates whose logs have it:

* resonance: ln f_meas,j ~ N(ln S_j(theta), sigma_j^2) with sigma_j^2 = measurement^2 +
  surrogate leave-one-out^2 + FEM discretisation^2 (all relative), S_j the plate's surrogate
  (:mod:`workflow.calibration.plate_surrogate`);
* deflection per volt per Q: ln g_meas,j ~ N(ln G_j(theta), deflection^2 + leave-one-out^2);
* scan pattern: each point p, m_p ~ N(s P_j,p(theta), noise^2 + leave-one-out_p^2), s = +-1 the
  sign that aligns the patterns (:func:`~workflow.calibration.measurements.aligned_misfit`).

Model discrepancy (issue 29): a built plate may differ from the FEM in ways the parameters do not span, so
the resonance's variance gains (tau_f u_f)^2 and the deflection's (tau_g u_g)^2, u_f and u_g sampled beside the
parameters with half-normal priors of scale 1 (tau: the settings' ``discrepancy_scales``), sampled as ln u (no
boundary at u = 0 for the walkers to stick to; the prior's density in ln u is u exp(-u^2/2)).  With the variances
depending on u, the likelihood keeps its normalisation -1/2 ln(variance).  When the parameters can take up what
the plates measured, u's posterior stays near its prior; when they cannot, the plates push it up.  A prediction
of a plate adds N(0, (tau_f u_f)^2) to ln f_r at each posterior sample.

Priors from :class:`~workflow.calibration.parameters.CalibrationSettings`.  Samples are SI values.
"""

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import stats

from workflow.calibration.measurements import aligned_misfit
from workflow.calibration.parameters import DISCREPANCIES, CalibrationSettings
from workflow.calibration.plate_surrogate import PlateSurrogate
from workflow.sampling import ChainDiagnostics, evenly_kept, quantile_summary, run_ensemble

CONSTRAINED_RATIO = 0.5
"""A direction is constrained when its posterior standard deviation is below this share of the prior's [-]."""
BOUND_ZONE = 0.1
"""Share of a prior's range next to each bound in which :func:`prior_bounds` compares posterior and prior mass [-]."""
BOUND_EXCESS = 1.5
"""A posterior sits at a bound when it puts at least this many times the prior's mass in the bound's zone [-]...
(the published plates' calibration puts 18 % of its glue samples in the top tenth of the glue's uniform prior, its
density as high there as anywhere: 2 missed it; a posterior equal to a uniform prior has 1)."""
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


def _gaussian(residual, variance):
    """ln N(residual; 0, variance) up to a constant, summed over the last axis when there is one [-]."""
    return -0.5 * (residual**2 / variance + np.log(variance))


def log_probability(state: np.ndarray, data: CalibrationData) -> np.ndarray:
    """Log posterior of sampler states (n_walkers, n + 2) up to a constant (vectorised): the parameters [SI] and the
    logarithms of the discrepancy terms' standardised sizes u (:data:`~workflow.calibration.parameters.DISCREPANCIES`)."""
    theta, units = split_state(state, data.settings)
    with np.errstate(over="ignore"):  # a walker far out in ln u: an infinite term, its probability -inf
        prior = data.settings.log_prior(theta) + np.sum(np.log(units) - 0.5 * units**2, axis=-1)
        frequency_extra, deflection_extra = np.moveaxis(np.square(units * data.settings.discrepancy_scales), -1, 0)
    inside = np.isfinite(prior)
    clipped = np.clip(theta, data.settings.bounds[:, 0], data.settings.bounds[:, 1])
    predicted = np.stack([s.log_frequency(clipped) for s in data.surrogates], axis=-1)
    variance = data.sigma**2 + frequency_extra[..., None]
    likelihood = np.sum(_gaussian(data.log_measured - predicted, variance), axis=-1)
    for surrogate, term in zip(data.surrogates, data.deflections):
        if term is not None:
            likelihood = likelihood + _gaussian(term[0] - surrogate.log_point_deflection(clipped), term[1] ** 2 + deflection_extra)
    for surrogate, term in zip(data.surrogates, data.patterns):
        if term is not None:
            misfit = aligned_misfit(term[0], surrogate.shape(clipped)) / term[1]
            likelihood = likelihood - 0.5 * np.sum(misfit**2, axis=-1)
    return np.where(inside, prior + likelihood, -np.inf)


def split_state(state: np.ndarray, settings: CalibrationSettings) -> tuple[np.ndarray, np.ndarray]:
    """(parameters [SI], discrepancy terms' standardised sizes u [-]) of sampler states (..., n + 2), which hold ln u."""
    n = len(settings.parameters)
    with np.errstate(over="ignore"):
        return state[..., :n], np.exp(state[..., n:])


def sample_posterior(data: CalibrationData) -> tuple[np.ndarray, np.ndarray, ChainDiagnostics]:
    """Run emcee (:func:`~workflow.sampling.run_ensemble`, at most ``settings.steps`` steps) from prior draws; keep
    ``settings.kept_samples`` evenly spaced after burn-in.

    Returns
    -------
    samples : numpy.ndarray
        (kept, n) posterior samples of the parameters [SI].
    discrepancy : numpy.ndarray
        (kept, 2) the discrepancy terms' relative standard deviations tau u at the same samples [-].
    diagnostics : ChainDiagnostics
        Of the parameters and the discrepancy terms.
    """
    settings = data.settings
    rng = np.random.default_rng(settings.sampler_seed)
    units = np.abs(rng.normal(size=(settings.walkers, len(DISCREPANCIES))))
    start = np.column_stack([np.stack([p.draw(settings.walkers, rng) for p in settings.parameters], axis=1), np.log(units)])
    sampler, diagnostics = run_ensemble(log_probability, start, settings.sampler_seed, (data,), settings.steps)
    theta, units = split_state(evenly_kept(sampler, diagnostics, settings.kept_samples), settings)
    return theta, units * settings.discrepancy_scales, diagnostics


def parameter_summary(settings: CalibrationSettings, samples: np.ndarray) -> dict:
    """name -> {median, p05, p95} in display units (factors [-], lengths [um])."""
    return {parameter.name: quantile_summary(samples[:, k], parameter.display_scale, parameter.unit)
            for k, parameter in enumerate(settings.parameters)}


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


def predictive_quantiles(surrogate: PlateSurrogate, samples: np.ndarray, discrepancy: np.ndarray, seed: int = 0,
                         quantiles=(5, 50, 95)) -> dict:
    """Quantiles of f_r [Hz] and w [m] of a plate over posterior samples: surrogate, FEM and model discrepancy included.

    Each sample's ln f gets independent normal errors of the surrogate's ``frequency_sigma`` and of the sample's
    frequency discrepancy, and ln w one of the deflection surface's leave-one-out error and the sample's deflection
    discrepancy (the deflection per volt's, taken for the deflection's).

    Parameters
    ----------
    surrogate : PlateSurrogate
    samples : numpy.ndarray
        (n, k) posterior samples [SI].
    discrepancy : numpy.ndarray
        (n, 2) the samples' discrepancy terms, relative sds of ln f_r and ln g [-].
    """
    rng = np.random.default_rng(seed)
    bounds = np.asarray(surrogate.log_frequency.bounds)
    clipped = np.clip(samples, bounds[:, 0], bounds[:, 1])
    n = len(samples)
    log_f = surrogate.log_frequency(clipped) + rng.normal(0, np.hypot(surrogate.frequency_sigma, discrepancy[:, 0]), n)
    log_w = surrogate.log_deflection(clipped) + rng.normal(0, np.hypot(surrogate.log_deflection.loo_rms, discrepancy[:, 1]), n)
    return {
        "frequency": np.exp(np.percentile(log_f, quantiles)),
        "deflection": np.exp(np.percentile(log_w, quantiles)),
    }


CHECK_ALPHA = 0.01
"""A calibration plate's measurement fails the posterior-predictive check when its two-sided p is below this [-]."""
HALF_NORMAL_MEDIAN = 0.6745
"""Median of a half-normal distribution of scale 1 [-]."""


def predictive_check(data: CalibrationData, samples: np.ndarray, discrepancy: np.ndarray, names) -> dict:
    """Posterior-predictive check of the calibration plates: can the parameters represent what they measured?

    For each plate's resonance (and deflection per volt, when used), the posterior predictive without the
    discrepancy term (surrogate at each posterior sample plus the measurement's, surrogate's and FEM's errors) is
    compared with the measurement: z = (measured - mean) / sd in ln, two-sided p = 2 Phi(-|z|).  A measurement
    with p below :data:`CHECK_ALPHA` is one the parameters cannot represent; the discrepancy term's posterior then
    sits above its prior, and widens every prediction accordingly.

    Parameters
    ----------
    data : CalibrationData
    samples : numpy.ndarray
        (n, k) posterior samples [SI].
    discrepancy : numpy.ndarray
        (n, 2) their discrepancy terms [-].
    names : sequence of str
        The plates' names.

    Returns
    -------
    dict
        ``plates`` (per plate: name -> {quantity: {z, p}}), ``passed``, ``worst`` (the smallest p and where),
        ``discrepancy`` (per term: posterior median and p95 against the prior's median, relative sds) and
        ``statement`` (one sentence).
    """
    clipped = np.clip(samples, data.settings.bounds[:, 0], data.settings.bounds[:, 1])
    plates, worst = [], (1.0, None)
    for k, (name, surrogate) in enumerate(zip(names, data.surrogates)):
        terms = {"resonance frequency": (data.log_measured[k], surrogate.log_frequency(clipped), data.sigma[k])}
        if k < len(data.deflections) and data.deflections[k] is not None:
            terms["deflection per volt"] = (data.deflections[k][0], surrogate.log_point_deflection(clipped),
                                            data.deflections[k][1])
        record = {}
        for quantity, (measured, predicted, sigma) in terms.items():
            z = float((measured - np.mean(predicted)) / np.sqrt(np.var(predicted) + sigma**2))
            p = float(2 * stats.norm.sf(abs(z)))
            record[quantity] = {"z": z, "p": p}
            worst = min(worst, (p, f"{name}: {quantity}"), key=lambda pair: pair[0])
        plates.append({"name": name, **record})
    scales = data.settings.discrepancy_scales
    terms = {}
    for j, term in enumerate(DISCREPANCIES):
        if scales[j] > 0:
            median, high = np.percentile(discrepancy[:, j], [50, 95])
            terms[term] = {"median": float(median), "p95": float(high), "prior_median": float(HALF_NORMAL_MEDIAN * scales[j])}
    passed = worst[0] >= CHECK_ALPHA
    frequency = terms.get("frequency")
    if passed:
        statement = (f"the parameters represent what the calibration plates measured (posterior-predictive p >= "
                     f"{worst[0]:.2g} for every measurement)")
    else:
        statement = (f"the parameters cannot represent what was measured: {worst[1]} lies at p = {worst[0]:.1e} of the "
                     "posterior predictive")
    if frequency is not None:
        statement += (f"; the model-discrepancy term of the resonance, {100 * frequency['median']:.2g} % (posterior "
                      f"median; its prior's {100 * frequency['prior_median']:.2g} %), widens every prediction")
    return {"plates": plates, "passed": passed, "alpha": CHECK_ALPHA,
            "worst": {"p": worst[0], "where": worst[1]}, "discrepancy": terms, "statement": statement}
