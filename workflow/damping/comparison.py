"""Comparison of Q(v) laws by PSIS-LOO (ArviZ) and the answer's shares: the best law, or the close laws mixed.

Each sampled law's expected log pointwise predictive density elpd_loo (Pareto-smoothed
importance-sampling leave-one-out; higher is better) comes with its standard error ``se``;
between two laws the difference has its own standard error ``dse``.  The design uses the best
law when every other law is behind by more than :data:`CLOSE_DSE` dse; otherwise the data do not tell
the close laws apart, and the answer mixes them in equal shares (:func:`answer_shares`), so that where
they disagree on Q(v) its band covers each (issue 29: a band conditioned on one of several laws that
predict the data equally well excluded the truth at half the velocities).  The stacking weights (Yao
et al. 2018: those maximising the LOO predictive density of the mixture) are reported beside them: they
rank laws by how well they predict the rows, which says little about Q(v) when the laws' misfits are
below the noise.  Pareto k above :data:`PARETO_K_BAD` marks rows where the LOO estimate is unreliable
(a warning, counted per law).
"""

import warnings
from dataclasses import dataclass
from typing import Dict

import arviz as az
import numpy as np

CLOSE_DSE = 2.0
"""Laws closer to the best than this many standard errors of the difference are averaged [-]."""
PARETO_K_BAD = 0.7
"""Pareto k above which a row's LOO estimate is unreliable [-] (ArviZ's threshold)."""
CRITERION = (
    "PSIS-LOO (ArviZ): elpd_loo with its standard error se, and dse of the difference to the best law; "
    f"higher is better; the laws within {CLOSE_DSE:g} dse of the best that pass their misfit checks are mixed in equal shares"
)


@dataclass(frozen=True)
class LawComparison:
    """PSIS-LOO of the sampled laws and their stacking weights.

    Attributes
    ----------
    laws : dict
        Law name -> {elpd_loo, se, p_loo, elpd_diff, dse, weight, n_pareto_k_bad, warning}.
    best : str
        The law with the highest elpd_loo.
    weights : dict
        Law name -> stacking weight [-] (sums to 1).
    """

    laws: Dict[str, dict]
    best: str
    weights: Dict[str, float]

    @property
    def close(self) -> tuple:
        """The best law and those within :data:`CLOSE_DSE` standard errors of the difference of it, best first."""
        return tuple(name for name, entry in self.laws.items()
                     if name == self.best or entry["elpd_diff"] < CLOSE_DSE * entry["dse"])

    @property
    def pareto_warning(self) -> bool:
        """Whether some law has rows with Pareto k above :data:`PARETO_K_BAD`."""
        return any(entry["n_pareto_k_bad"] > 0 for entry in self.laws.values())


def compare_laws(idatas: Dict[str, az.InferenceData]) -> LawComparison:
    """PSIS-LOO of every law's InferenceData and their stacking weights."""
    with warnings.catch_warnings(), np.errstate(over="ignore", invalid="ignore"):
        # ArviZ warns of Pareto k > 0.7 on stderr; it is counted per law (n_pareto_k_bad) and reported instead
        warnings.simplefilter("ignore")
        loos = {name: az.loo(idata, pointwise=True) for name, idata in idatas.items()}
    bad = {name: int(np.sum(np.asarray(loo.pareto_k) > PARETO_K_BAD)) for name, loo in loos.items()}
    if len(loos) == 1:
        (name, loo), = loos.items()
        entry = {"elpd_loo": float(loo.elpd_loo), "se": float(loo.se), "p_loo": float(loo.p_loo),
                 "elpd_diff": 0.0, "dse": 0.0, "weight": 1.0, "n_pareto_k_bad": bad[name], "warning": bool(loo.warning)}
        return LawComparison({name: entry}, name, {name: 1.0})
    with warnings.catch_warnings(), np.errstate(over="ignore", invalid="ignore"):
        warnings.simplefilter("ignore")  # and its pandas deprecations are not the user's business
        table = az.compare(loos, ic="loo", method="stacking", scale="log")
    laws = {
        str(name): {
            "elpd_loo": float(row["elpd_loo"]),
            "se": float(row["se"]),
            "p_loo": float(row["p_loo"]),
            "elpd_diff": float(row["elpd_diff"]),
            "dse": float(row["dse"]),
            "weight": float(row["weight"]),
            "n_pareto_k_bad": bad[str(name)],
            "warning": bool(row["warning"]),
        }
        for name, row in table.iterrows()
    }
    best = str(table.index[0])
    total = sum(entry["weight"] for entry in laws.values())
    weights = {name: entry["weight"] / total for name, entry in laws.items()}
    return LawComparison(laws, best, weights)


def answer_shares(comparison: LawComparison, passed: Dict[str, bool]) -> Dict[str, float]:
    """Law name -> its share of the answer: equal shares among the laws the data do not tell apart from the best
    (:attr:`LawComparison.close`) whose misfit checks ``passed``; the best law alone when no other qualifies."""
    mixed = [name for name in comparison.close if passed.get(name, False)] or [comparison.best]
    return {name: 1.0 / len(mixed) for name in mixed}
