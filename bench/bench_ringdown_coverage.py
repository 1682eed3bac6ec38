"""Coverage of the Q(v) intervals from ring-downs alone, with and without the magnitude reading's floor; one JSON object.

Each seed simulates the ring-downs of the bench (softening 0.08 s^2/m^2, drift -0.3 Hz/s, the plate not warming: a
truth the quadratic law holds exactly) at 3, 6, 9, 12 and 15 V, 100 samples 51.2 us apart through the lock-in's capture,
and fits the quadratic law to them.  Printed per parameter (Q0, alpha): the share of seeds whose 90 % interval holds
the truth, the mean and standard deviation of the truth's z-score inside the interval ((position - 0.5) x 3.29; 0 and 1
for honest intervals) and the intervals' median relative width.

Two fits of the same logs in the same run: ``shipped`` (the ring-down likelihood reads the envelope as a magnitude
detector does in a noise floor, :func:`~workflow.damping.likelihood.envelope_reading`) and ``reference`` (the envelope
read as it is, the likelihood before that correction).

    python bench/bench_ringdown_coverage.py [--seeds N] [--steps S]    # 40 seeds x 1000 steps, both fits: ~2 min
"""

import argparse
import json
import tempfile
from pathlib import Path
from unittest import mock

import numpy as np

from instruments.procedures.simulated import simulate_ringdown
from instruments.simulator import default_bench_settings
from workflow.damping import likelihood
from workflow.damping.fit import fit_law, parameter_summary
from workflow.damping.logs import read_logs

VOLTAGES = (3.0, 6.0, 9.0, 12.0, 15.0)
Z_90 = 3.29
"""Width of a normal 90 % interval in standard deviations [-]."""


def positions(log, truth: dict, seed: int, steps: int) -> dict:
    """Parameter -> (truth's position in the 90 % interval, 0 at p05 and 1 at p95; relative width)."""
    summary = parameter_summary(fit_law(log, "quadratic", seed=seed, max_steps=steps, chain_taus=25))
    return {name: ((value - summary[name]["p05"]) / (summary[name]["p95"] - summary[name]["p05"]),
                   (summary[name]["p95"] - summary[name]["p05"]) / summary[name]["median"]) for name, value in truth.items()}


def coverage(rows: list) -> dict:
    result = {}
    for name in rows[0]:
        position = np.array([row[name][0] for row in rows])
        z = (position - 0.5) * Z_90
        result[name] = {"inside_share": float(np.mean((position >= 0) & (position <= 1))), "z_mean": float(z.mean()),
                        "z_std": float(z.std()), "median_relative_width": float(np.median([row[name][1] for row in rows]))}
    return result


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--steps", type=int, default=1000, help="chain cap per fit (the intervals' place is the same at 3000)")
    args = parser.parse_args(argv)
    shipped, reference = [], []
    with tempfile.TemporaryDirectory() as folder:
        for seed in range(args.seeds):
            settings = default_bench_settings(seed=100 + seed, softening=0.08, drift_rate=-0.3, heating=False)
            path = Path(folder) / f"ringdown{seed}.csv"
            simulate_ringdown(path, settings, voltages=VOLTAGES, interval=40e-6)
            truth = {"q0": float(settings.response.law.q0), "alpha": float(settings.response.law.alpha)}
            log = read_logs([path])
            shipped.append(positions(log, truth, seed, args.steps))
            with mock.patch.object(likelihood, "envelope_reading", lambda envelope, sigma_abs: envelope):
                reference.append(positions(log, truth, seed, args.steps))
    result = {"seeds": args.seeds, "steps": args.steps, "shipped": coverage(shipped), "reference": coverage(reference)}
    result["inside_ratio_shipped_over_reference"] = {
        name: result["shipped"][name]["inside_share"] / max(result["reference"][name]["inside_share"], 1e-9)
        for name in result["shipped"]}
    print(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
