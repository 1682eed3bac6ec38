"""Benchmark of the Q(v) law choice on simulated campaigns; prints one JSON line per truth.

For campaigns drawn from the quadratic, linear and threshold laws (seeded), runs the whole
fit (MAP screening, sampling, PSIS-LOO, checks) and reports the chosen law, the selection,
the coverage of the true Q(v) by the answer's 90 % band on 50 velocities spanning the
measured ones, the band's median relative width, and the fit time.

    python bench/bench_laws.py [--truth NAME ...] [--seed N] [--laws a,b] [--stated-noise X]
"""

import argparse
import json
import time
from functools import partial

import numpy as np

from workflow.damping.fit import DEFAULT_LAWS, fit_damping, fit_summary
from workflow.damping.laws import LinearLoss, ThresholdLoss
from workflow.damping.synthetic import TRUE_LAW, simulate_campaign
from workflow.execution.parallel import map_evaluations

TRUTHS = {
    "quadratic": TRUE_LAW,
    "linear": LinearLoss(q0=150.0, alpha=0.06),
    "threshold": ThresholdLoss(q0=140.0, alpha=0.45, v_t=0.1),
}
NOISE = 0.02
"""Relative noise of the simulated campaigns [-] (also given to the fit as the stated noise)."""


def band_figures(summary: dict, truth) -> dict:
    """Coverage of ``truth`` by the 90 % band of the answer (fraction of the velocity grid) and the band's width."""
    q = summary["q_of_v"]
    true_q = truth.quality_factor(np.asarray(q["v_m_s"]))
    low, mid, high = (np.asarray(q[k]) for k in ("q_p05", "q_p50", "q_p95"))
    return {"coverage": float(np.mean((true_q >= low) & (true_q <= high))), "band_width_rel_median": float(np.median((high - low) / mid))}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truth", nargs="*", default=list(TRUTHS), choices=list(TRUTHS))
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--laws", default=",".join(DEFAULT_LAWS))
    args = parser.parse_args()
    for name in args.truth:
        log = simulate_campaign(law=TRUTHS[name], relative_noise=NOISE, seed=args.seed)
        start = time.perf_counter()
        fit = fit_damping(log, laws=tuple(args.laws.split(",")), seed=args.seed, stated_noise=NOISE,
                          mapper=partial(map_evaluations, progress=False))
        seconds = time.perf_counter() - start
        summary = fit_summary(fit)
        result = {
            "truth": name,
            "preferred": summary["law"],
            "selection": summary["selection"],
            "design_law": summary["design_law"],
            "weights": summary["weights"],
            "warning": summary["warning"],
            "sampled": {k: {"steps": f.diagnostics.n_steps, "tau_max": f.diagnostics.tau_max, "seconds": f.diagnostics.seconds,
                            "converged": f.diagnostics.converged} for k, f in fit.fits.items()},
            "checks_passed": {k: c.passed for k, c in fit.checks.items()},
            **band_figures(summary, TRUTHS[name]),
            "fit_seconds": seconds,
        }
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
