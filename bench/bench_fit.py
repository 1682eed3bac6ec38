"""Benchmark of the Q(v) fit on the shipped campaign; prints one JSON object.

Times the whole fit of each law (MAP, Laplace start, emcee to convergence) and reports
tau, steps, acceptance and elpd_loo.  The vectorised log-probability is compared, in the same
run, with a per-walker loop over the same function (the reference), so the ratio is meaningful
on a noisy machine; the harmonic solve of the same walkers is timed alone.

With ``--truths``, instead: for campaigns simulated from the quadratic, linear and threshold
laws (seeded, 2 % noise, stated to the fit), the whole choice (MAP screening, sampling side by
side, PSIS-LOO, checks) with the chosen law, the selection, the coverage of the true Q(v) by the
answer's 90 % band on 50 velocities spanning the measured ones, the band's median relative
width and the fit time; one JSON line per truth.  With ``--flexible``, the same figures of the
flexible law alone (``fit_law``, converged by the 50 tau rule) with its tau and steps.

    python bench/bench_fit.py [LOG.csv] [--seed N]
    python bench/bench_fit.py --truths [quadratic linear threshold] [--seed N]
    python bench/bench_fit.py --flexible [quadratic linear threshold] [--seed N]
"""

import argparse
import json
import time
from functools import partial
from pathlib import Path

import arviz as az
import numpy as np
from timing import best_time

from workflow.damping.fit import fit_damping, fit_law, fit_summary, velocity_grid
from workflow.damping.harmonic import self_consistent_amplitude
from workflow.damping.laws import LinearLoss, ThresholdLoss
from workflow.damping.likelihood import fit_data, log_probability, log_probability_single
from workflow.damping.logs import read_logs
from workflow.damping.synthetic import TRUE_LAW, simulate_campaign
from workflow.execution.parallel import map_evaluations

SHIPPED = Path(__file__).resolve().parent.parent / "data" / "sample_campaign.csv"
TRUTHS = {
    "quadratic": TRUE_LAW,
    "linear": LinearLoss(q0=150.0, alpha=0.06),
    "threshold": ThresholdLoss(q0=140.0, alpha=0.45, v_t=0.1),
}
NOISE = 0.02
"""Relative noise of the simulated campaigns [-] (also given to the fit as the stated noise)."""


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="*", default=[str(SHIPPED)])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--truths", nargs="*", choices=list(TRUTHS), help="study the law choice on simulated campaigns")
    parser.add_argument("--flexible", nargs="*", choices=list(TRUTHS), help="the flexible law alone on simulated campaigns")
    args = parser.parse_args()
    for study, names in ((law_choice, args.truths), (flexible_coverage, args.flexible)):
        if names is not None:
            for name in names or TRUTHS:
                print(json.dumps(study(name, args.seed)), flush=True)
            return
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
            "elpd_loo": float(az.loo(law_fit.inference_data).elpd_loo),
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


def law_choice(name: str, seed: int) -> dict:
    """The whole fit of a campaign simulated from ``TRUTHS[name]``: choice, coverage, band width, time."""
    truth = TRUTHS[name]
    log = simulate_campaign(law=truth, relative_noise=NOISE, seed=seed)
    start = time.perf_counter()
    fit = fit_damping(log, seed=seed, stated_noise=NOISE, mapper=partial(map_evaluations, progress=False))
    seconds = time.perf_counter() - start
    summary = fit_summary(fit)
    q = summary["q_of_v"]
    true_q = truth.quality_factor(np.asarray(q["v_m_s"]))
    return {
        "truth": name,
        "preferred": summary["law"],
        "selection": summary["selection"],
        "design_law": summary["design_law"],
        "weights": summary["weights"],
        "warning": summary["warning"],
        "sampled": {
            k: {"steps": f.diagnostics.n_steps, "tau_max": f.diagnostics.tau_max, "seconds": f.diagnostics.seconds,
                "converged": f.diagnostics.converged}
            for k, f in fit.fits.items()
        },
        "checks_passed": {k: c.passed for k, c in fit.checks.items()},
        **band_figures(true_q, *(np.asarray(q[k]) for k in ("q_p05", "q_p50", "q_p95"))),
        "fit_seconds": seconds,
    }


def band_figures(true_q, low, mid, high) -> dict:
    """Coverage of the true Q by the band [low, high] and the band's median width relative to ``mid``."""
    return {"coverage": float(np.mean((true_q >= low) & (true_q <= high))),
            "band_width_rel_median": float(np.median((high - low) / mid))}


def flexible_coverage(name: str, seed: int) -> dict:
    """The flexible law alone on a campaign simulated from ``TRUTHS[name]``: coverage, band width, tau, time."""
    truth = TRUTHS[name]
    log = simulate_campaign(law=truth, relative_noise=NOISE, seed=seed)
    start = time.perf_counter()
    law_fit = fit_law(log, "flexible", seed=seed)
    seconds = time.perf_counter() - start
    velocity = velocity_grid(log)
    d = law_fit.diagnostics
    return {"truth": name, "seed": seed, **band_figures(truth.quality_factor(velocity), *law_fit.quality_factor_quantiles(velocity)),
            "tau_max": d.tau_max, "steps": d.n_steps, "walkers": d.n_walkers, "converged": d.converged, "fit_seconds": seconds}


def law_fit_walkers(log, seed, n_walkers=44):
    """A realistic batch of walkers: the MAP of the quadratic law plus a small spread."""
    from workflow.damping.fit import map_fit

    data, theta, scale, _ = map_fit(log, "quadratic")
    rng = np.random.default_rng(seed)
    return theta + 0.1 * scale * rng.standard_normal((n_walkers, len(theta)))


if __name__ == "__main__":
    main()
