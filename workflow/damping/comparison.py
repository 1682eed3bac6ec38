"""Comparison of Q(v) laws by PSIS-LOO (ArviZ) and the choice: the best law or stacking.

Each sampled law's expected log pointwise predictive density elpd_loo (Pareto-smoothed
importance-sampling leave-one-out; higher is better) comes with its standard error ``se``;
between two laws the difference has its own standard error ``dse``.  The design uses the best
law when every other law is behind by more than :data:`CLOSE_DSE` dse, else the
stacking-weighted mixture of the laws (Yao et al. 2018), the weights maximising the LOO
predictive density of the mixture.  Pareto k above :data:`PARETO_K_BAD` marks rows where
the LOO estimate is unreliable (a warning, counted per law).
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
    f"higher is better; stacking when a law is within {CLOSE_DSE:g} dse of the best"
)


@dataclass(frozen=True)
class LawComparison:
    """PSIS-LOO of the sampled laws and the choice made from it.

    Attributes
    ----------
    laws : dict
        Law name -> {elpd_loo, se, p_loo, elpd_diff, dse, weight, n_pareto_k_bad, warning}.
    best : str
        The law with the highest elpd_loo.
    selection : str
        ``"best"`` or ``"stacking"``.
    weights : dict
        Law name -> stacking weight [-] (sums to 1).
    """

    laws: Dict[str, dict]
    best: str
    selection: str
    weights: Dict[str, float]

    @property
    def pareto_warning(self) -> bool:
        """Whether some law has rows with Pareto k above :data:`PARETO_K_BAD`."""
        return any(entry["n_pareto_k_bad"] > 0 for entry in self.laws.values())


def compare_laws(idatas: Dict[str, az.InferenceData]) -> LawComparison:
    """PSIS-LOO of every law's InferenceData, their stacking weights and the selection."""
    with warnings.catch_warnings(), np.errstate(over="ignore", invalid="ignore"):
        # ArviZ warns of Pareto k > 0.7 on stderr; it is counted per law (n_pareto_k_bad) and reported instead
        warnings.simplefilter("ignore")
        loos = {name: az.loo(idata, pointwise=True) for name, idata in idatas.items()}
    bad = {name: int(np.sum(np.asarray(loo.pareto_k) > PARETO_K_BAD)) for name, loo in loos.items()}
    if len(loos) == 1:
        (name, loo), = loos.items()
        entry = {"elpd_loo": float(loo.elpd_loo), "se": float(loo.se), "p_loo": float(loo.p_loo),
                 "elpd_diff": 0.0, "dse": 0.0, "weight": 1.0, "n_pareto_k_bad": bad[name], "warning": bool(loo.warning)}
        return LawComparison({name: entry}, name, "best", {name: 1.0})
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
    close = [name for name, entry in laws.items() if name != best and entry["elpd_diff"] < CLOSE_DSE * entry["dse"]]
    total = sum(entry["weight"] for entry in laws.values())
    weights = {name: entry["weight"] / total for name, entry in laws.items()}
    return LawComparison(laws, best, "stacking" if close else "best", weights)
