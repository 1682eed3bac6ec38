"""Benchmark of the Q(v) fit on the shipped campaign; prints one JSON object.

Times the whole fit of each law (MAP, Laplace start, emcee to convergence) and reports
tau, steps and acceptance.  The vectorised log-probability is compared, in the same run,
with a per-walker loop over the same function (the reference), so the ratio is meaningful on a
noisy machine; the harmonic solve of the same walkers is timed alone.

    python bench/bench_fit.py [LOG.csv] [--seed N]
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
from timing import best_time

from workflow.damping.fit import fit_law
from workflow.damping.harmonic import self_consistent_amplitude
from workflow.damping.likelihood import fit_data, log_probability, log_probability_single
from workflow.damping.logs import read_logs

SHIPPED = Path(__file__).resolve().parent.parent / "data" / "sample_campaign.csv"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="*", default=[str(SHIPPED)])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    log = read_logs(args.logs)
    result = {"logs": args.logs, "n_points": int(len(log.velocity)), "n_sweeps": log.n_sweeps, "laws": {}}
    for law_name in ("quadratic", "linear"):
        start = time.perf_counter()
        law_fit = fit_law(log, law_name, seed=args.seed)
        d = law_fit.diagnostics
        result["laws"][law_name] = {
            "seconds_total": time.perf_counter() - start,
            "seconds_sampling": d.seconds,
            "tau_max": d.tau_max,
            "n_steps": d.n_steps,
            "n_walkers": d.n_walkers,
            "steps_over_tau": d.n_steps / d.tau_max,
            "acceptance": d.acceptance,
            "converged": d.converged,
            "waic": law_fit.waic,
        }
    data = fit_data(log, "quadratic")
    walkers = law_fit_walkers(log, args.seed)
    vectorised = best_time(lambda: log_probability(walkers, data), 20)
    loop = best_time(lambda: [log_probability_single(w, data) for w in walkers], 5)
    law = data.layout.law(walkers)
    gain = np.exp(walkers[:, 2:3]) * data.voltage
    resonance = walkers[:, data.layout.resonance_slice][:, data.sweep]
    solve = best_time(lambda: self_consistent_amplitude(gain, data.frequency, resonance, law.quality_factor), 20)
    result["log_probability"] = {
        "walkers": len(walkers),
        "vectorised_s": vectorised,
        "per_walker_loop_s": loop,
        "speedup": loop / vectorised,
    }
    result["harmonic_solve_s"] = solve
    print(json.dumps(result))


def law_fit_walkers(log, seed, n_walkers=44):
    """A realistic batch of walkers: the MAP of the quadratic law plus a small spread."""
    from workflow.damping.fit import map_fit

    data, theta, scale, _ = map_fit(log, "quadratic")
    rng = np.random.default_rng(seed)
    return theta + 0.1 * scale * rng.standard_normal((n_walkers, len(theta)))


if __name__ == "__main__":
    main()
