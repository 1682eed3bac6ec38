"""Posterior predictive misfit checks of a fitted Q(v) law, per sweep.

1. **Structure left in the residuals** (runs test): in each sweep, ordered by frequency,
   the signs of v_measured - v_model (v_model the pointwise posterior median prediction) of
   a law that fits alternate like coin flips; a wrong Q(v) leaves long runs of one sign
   around the resonance.  With n1 positive and n2 negative residuals (n = n1 + n2) the
   number of runs R has mean 1 + 2 n1 n2 / n and variance 2 n1 n2 (2 n1 n2 - n) / (n^2 (n - 1))
   (Wald & Wolfowitz 1940); z = (R - mean) / sd, and the one-sided p = Phi(z) (too few runs).
   The check fails when a sweep's p is below :data:`ALPHA` / n_sweeps (Bonferroni) or the
   sweeps' combined z (Stouffer, sum z / sqrt(n_sweeps)) has p below :data:`ALPHA`.
2. **Noise against the instrument** (when the log states it): the fitted relative noise
   sigma_rel (posterior median) must not exceed :data:`NOISE_RATIO_LIMIT` times the
   instrument's stated relative noise; a law that misses the shape of the curves is
   forced to call the misfit noise.  Without a stated noise this check is skipped (and
   says so).
"""

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np
from scipy import stats

from workflow.damping.likelihood import FitData, predicted_velocity

ALPHA = 1e-3
"""Significance level of the runs test [-]: a law that fits fails it once in a thousand campaigns."""
NOISE_RATIO_LIMIT = 1.5
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
        Stouffer-combined p over the sweeps [-].
    sigma_rel : float
        Fitted relative noise, posterior median [-].
    stated_noise : float or None
        The instrument's stated relative noise [-], None when not known.
    passed : bool
    reasons : tuple of str
        One line per failed check, and one when the noise check was skipped.
    """

    runs_z: np.ndarray
    runs_p: np.ndarray
    combined_p: float
    sigma_rel: float
    stated_noise: Optional[float]
    passed: bool
    reasons: Tuple[str, ...]

    def summary(self) -> dict:
        """JSON-able form."""
        return {
            "passed": self.passed,
            "runs_test_p_per_sweep": [float(p) for p in self.runs_p],
            "runs_test_combined_p": self.combined_p,
            "sigma_rel_fitted": self.sigma_rel,
            "sigma_rel_stated": self.stated_noise,
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


def misfit_check(samples: np.ndarray, data: FitData, stated_noise: Optional[float] = None, seed: int = 0) -> MisfitCheck:
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
    """
    rng = np.random.default_rng(seed)
    chosen = samples[rng.choice(len(samples), size=min(PREDICTIVE_DRAWS, len(samples)), replace=False)]
    model = np.median(predicted_velocity(chosen, data.layout, data.frequency, data.voltage, data.sweep), axis=0)
    residual = data.velocity - model
    z, p = [], []
    for k in range(data.layout.n_sweeps):
        mine = np.nonzero(data.sweep == k)[0]
        zk, pk = runs_test(residual[mine[np.argsort(data.frequency[mine])]])
        z.append(zk)
        p.append(pk)
    z, p = np.array(z), np.array(p)
    combined = float(stats.norm.cdf(np.sum(z) / np.sqrt(len(z))))
    sigma_rel = float(np.median(np.exp(chosen[:, data.layout.names.index("ln_sigma_rel")])))
    reasons = []
    if np.min(p) < ALPHA / len(p) or combined < ALPHA:
        worst = int(np.argmin(p))
        reasons.append(
            f"residuals keep their sign in long runs (runs test: sweep {worst} p = {p[worst]:.1e}, "
            f"all sweeps p = {combined:.1e}, threshold {ALPHA:g}): the law misses the shape of the curves"
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
    return MisfitCheck(z, p, combined, sigma_rel, stated_noise, passed, tuple(reasons))
