"""Posterior predictive misfit checks of a fitted Q(v) law, per sweep.

Residuals are taken against the pointwise posterior median prediction v_model and
standardised by the fitted noise, z = (v - v_model) / sqrt((sigma_rel v_model)^2 + sigma_abs^2)
(posterior medians), in each sweep ordered by frequency.

1. **Structure left in the residuals.**  A law that fits leaves z uncorrelated from one
   frequency to the next; a wrong Q(v) leaves runs of one sign around the resonance, even
   when the fit has inflated its noise to absorb them.
   - Binned chi^2: consecutive groups of :data:`BIN_POINTS` rows, chi^2 = sum over groups of
     (sum z)^2 / n_group, is chi^2-distributed with one degree of freedom per group when the
     rows are independent with unit variance; correlated residuals make it large.  Fails when
     its p (all sweeps together) is below :data:`ALPHA`.
   - Runs test on the signs of z (Wald & Wolfowitz 1940): with n1 positive and n2 negative
     residuals (n = n1 + n2) the number of runs R has mean 1 + 2 n1 n2 / n and variance
     2 n1 n2 (2 n1 n2 - n) / (n^2 (n - 1)); z_R = (R - mean) / sd, one-sided p = Phi(z_R)
     (too few runs), per sweep and combined (Stouffer, sum z_R / sqrt(n_sweeps)).  Fails when
     the combined p is below :data:`ALPHA`.
2. **The flexible law as the alternative** (when given): twice the gain in log-likelihood at
   the MAP of the flexible law over this law, against chi^2 with the difference in the
   number of parameters (a likelihood-ratio test; approximate, the flexible law nesting
   the other laws only up to its knot spacing).  Fails when p < :data:`ALPHA`.
3. **Noise against the instrument** (when the log states it): the fitted relative noise
   sigma_rel (posterior median) must not exceed :data:`NOISE_RATIO_LIMIT` times the
   instrument's stated relative noise; a law that misses the shape of the curves is
   forced to call the misfit noise.  Without a stated noise this check is skipped (and
   says so).

On simulated campaigns (6 sweeps x 50 rows, 2 % noise; MAP residuals) the true law gives
binned-chi^2 p of 0.7-1 and a noise ratio of 0.95-1.07; a wrong law (quadratic or linear
fitted to a threshold or linear truth) p of 0.0008-0.03 and a ratio of 1.1-1.75, and the
flexible law gains 40-46 in log-likelihood over it (likelihood-ratio p < 1e-15); the residual
tests alone miss some wrong laws, which is why there are three checks.
"""

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np
from scipy import stats

from workflow.damping.likelihood import FitData, predicted_velocity

ALPHA = 0.01
"""Significance level of the residual tests [-]: a law that fits fails each about once in a hundred campaigns."""
BIN_POINTS = 5
"""Rows per group of the binned chi^2 [-]."""
NOISE_RATIO_LIMIT = 1.2
"""Largest accepted ratio of the fitted to the stated relative noise [-]."""
PREDICTIVE_DRAWS = 200
"""Posterior draws used for the median prediction [-]."""


@dataclass(frozen=True)
class MisfitCheck:
    """Result of :func:`misfit_check`.

    Attributes
    ----------
    runs_z, runs_p : numpy.ndarray
        Runs-test z and one-sided p per sweep [-].
    combined_p : float
        Stouffer-combined runs-test p over the sweeps [-].
    binned_p : numpy.ndarray
        Binned chi^2 p per sweep [-].
    binned_p_all : float
        Binned chi^2 p of all sweeps together [-].
    sigma_rel : float
        Fitted relative noise, posterior median [-].
    stated_noise : float or None
        The instrument's stated relative noise [-], None when not known.
    alternative_p : float or None
        Likelihood-ratio p of the flexible law against this law [-], None when not tested.
    passed : bool
    reasons : tuple of str
        One line per failed check, and one when the noise check was skipped.
    """

    runs_z: np.ndarray
    runs_p: np.ndarray
    combined_p: float
    binned_p: np.ndarray
    binned_p_all: float
    sigma_rel: float
    stated_noise: Optional[float]
    alternative_p: Optional[float]
    passed: bool
    reasons: Tuple[str, ...]

    def summary(self) -> dict:
        """JSON-able form."""
        return {
            "passed": self.passed,
            "runs_test_p_per_sweep": [float(p) for p in self.runs_p],
            "runs_test_combined_p": self.combined_p,
            "binned_chi2_p_per_sweep": [float(p) for p in self.binned_p],
            "binned_chi2_p": self.binned_p_all,
            "sigma_rel_fitted": self.sigma_rel,
            "sigma_rel_stated": self.stated_noise,
            "flexible_law_likelihood_ratio_p": self.alternative_p,
            "noise_ratio_limit": NOISE_RATIO_LIMIT,
            "alpha": ALPHA,
            "notes": list(self.reasons),
        }


def runs_test(residual: np.ndarray) -> Tuple[float, float]:
    """Wald-Wolfowitz runs test on the signs of ``residual`` (in sweep order): (z, one-sided p of too few runs)."""
    signs = residual > 0
    n1, n2 = int(signs.sum()), int((~signs).sum())
    n = n1 + n2
    if n1 == 0 or n2 == 0:
        return -np.inf, 0.0
    runs = 1 + int(np.count_nonzero(signs[1:] != signs[:-1]))
    mean = 1 + 2 * n1 * n2 / n
    variance = 2 * n1 * n2 * (2 * n1 * n2 - n) / (n**2 * (n - 1))
    z = (runs - mean) / np.sqrt(variance)
    return float(z), float(stats.norm.cdf(z))


def binned_chi2(z: np.ndarray, size: int = BIN_POINTS) -> tuple:
    """(chi^2, degrees of freedom) of standardised residuals ``z`` grouped ``size`` at a time, in order."""
    groups = [z[i : i + size] for i in range(0, len(z), size)]
    return float(sum(np.sum(g) ** 2 / len(g) for g in groups)), len(groups)


def misfit_check(
    samples: np.ndarray,
    data: FitData,
    stated_noise: Optional[float] = None,
    seed: int = 0,
    alternative: Optional[Tuple[float, int]] = None,
) -> MisfitCheck:
    """Runs test per sweep and the fitted against the stated noise, for one law's posterior.

    Parameters
    ----------
    samples : numpy.ndarray (M, D)
        Posterior samples in the sampled coordinates.
    data : FitData
    stated_noise : float, optional
        The instrument's relative velocity noise [-].
    seed : int
        Picks the predictive draws.
    alternative : (float, int), optional
        The flexible law's log-likelihood gain over this law at the MAPs and its number of
        extra parameters.
    """
    rng = np.random.default_rng(seed)
    chosen = samples[rng.choice(len(samples), size=min(PREDICTIVE_DRAWS, len(samples)), replace=False)]
    layout = data.layout
    if not layout.n_sweeps:
        return MisfitCheck(np.zeros(0), np.zeros(0), 1.0, np.zeros(0), 1.0, float("nan"), stated_noise, None, True,
                           ("no sweeps: the residual and noise checks apply to sweeps only",))
    model = np.median(predicted_velocity(chosen, layout, data.frequency, data.voltage, data.sweep, data.time_offset,
                                         data.mode_factor, heat=data.heat), axis=0)
    sigma_rel, sigma_abs = (float(np.median(np.exp(layout.column(chosen, name)))) for name in ("ln_sigma_rel", "ln_sigma_abs"))
    standardised = (data.velocity[: data.n_rows] - model) / np.sqrt((sigma_rel * model) ** 2 + sigma_abs**2)
    z, p, chi2, dof = [], [], [], []
    for k in range(layout.n_sweeps):
        mine = np.nonzero(data.sweep == k)[0]
        ordered = standardised[mine[np.argsort(data.frequency[mine])]]
        zk, pk = runs_test(ordered)
        ck, nk = binned_chi2(ordered)
        z.append(zk)
        p.append(pk)
        chi2.append(ck)
        dof.append(nk)
    z, p, chi2, dof = (np.array(x) for x in (z, p, chi2, dof))
    combined = float(stats.norm.cdf(np.sum(z) / np.sqrt(len(z))))
    binned_all = float(stats.chi2.sf(chi2.sum(), dof.sum()))
    reasons = []
    if binned_all < ALPHA or combined < ALPHA:
        reasons.append(
            f"residuals correlated along the sweeps (binned chi^2 p = {binned_all:.1e}, runs test p = {combined:.1e}, "
            f"threshold {ALPHA:g}): the law misses the shape of the curves"
        )
    alternative_p = None
    if alternative is not None:
        gain, extra = alternative
        alternative_p = float(stats.chi2.sf(2 * max(gain, 0.0), max(extra, 1)))
        if alternative_p < ALPHA:
            reasons.append(
                f"the flexible law fits the sweeps better by {gain:.1f} in log-likelihood with {extra} more "
                f"parameters (likelihood ratio p = {alternative_p:.1e})"
            )
    if stated_noise is None:
        note = "noise check skipped: the logs state no instrument noise"
    elif sigma_rel > NOISE_RATIO_LIMIT * stated_noise:
        note = (
            f"fitted relative noise {sigma_rel:.3g} is {sigma_rel / stated_noise:.1f} x the instrument's stated "
            f"{stated_noise:.3g} (limit {NOISE_RATIO_LIMIT:g} x): the misfit is absorbed as noise"
        )
        reasons.append(note)
    passed = not reasons
    if stated_noise is None:
        reasons.append(note)
    binned = stats.chi2.sf(chi2, dof)
    return MisfitCheck(z, p, combined, binned, binned_all, sigma_rel, stated_noise, alternative_p, passed, tuple(reasons))
