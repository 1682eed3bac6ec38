"""Benchmark of the joint fit of sweeps and ring-downs with softening and drift; prints one JSON object.

The campaign of docs/damping.md ("Measured: softening, drift and ring-down"): the simulated bench
with seed 4, softening 0.08 s^2/m^2 and drift -0.3 Hz/s, its 6 sweeps x 51 points and ring-downs at
3, 6, 9, 12 and 15 V (100 samples 40 us apart).  Timed:

- ``log_probability``: one call on 21 walkers (what emcee's red-blue moves pass with 42 walkers),
  best of 50, and its sweep and ring-down parts;
- ``autocorrelation``: the integrated autocorrelation time of a 6500 x 42 x 20 chain, this code's
  estimator against emcee's ``integrated_time`` (the reference), in the same run;
- ``fit``: what ``tactile fit-damping SWEEPS RINGDOWNS --law quadratic --softening --drift --out DIR``
  runs (MAP of every law, sampling, LOO, checks, then the files and figures), CPU and wall time.

With ``--reference DIR`` (a checkout of an earlier commit, e.g. ``git worktree add /tmp/ref COMMIT``)
the log-probability and the fit are measured on that code too, in a subprocess of the same run, and
the ratios reference / this are given.

    python bench/bench_joint.py [--reference DIR] [--no-fit]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from timing import best_time

from instruments.procedures.simulated import simulate_campaign, simulate_ringdown
from instruments.simulator import default_bench_settings
from workflow.damping.fit import fit_damping, initial_walkers, laplace_covariance, map_fit
from workflow.damping.likelihood import ForwardModel, log_probability, predicted_decay, predicted_velocity
from workflow.damping.logs import read_logs
from workflow.pipeline.damping_files import write_fit

SOFTENING, DRIFT = 0.08, -0.3
"""The campaign's softening [s^2/m^2] and drift [Hz/s]."""
RINGDOWN_VOLTAGES = (3.0, 6.0, 9.0, 12.0, 15.0)
HALF_ENSEMBLE = 21


def campaign(folder: Path) -> list:
    """The sweep and ring-down logs of the benchmark campaign, written into ``folder``."""
    settings = default_bench_settings(seed=4, softening=SOFTENING, drift_rate=DRIFT)
    simulate_campaign(folder / "sweeps.csv", settings)
    simulate_ringdown(folder / "ringdowns.csv", settings, voltages=RINGDOWN_VOLTAGES, interval=40e-6)
    return [folder / "sweeps.csv", folder / "ringdowns.csv"]


def measure(folder: Path, fit: bool) -> dict:
    """Log-probability and (optionally) fit timings of the code on ``sys.path``."""
    log = read_logs(campaign(folder))
    forward = ForwardModel(softening=True, drift=True)
    data, theta, scale, _ = map_fit(log, "quadratic", forward=forward)
    walkers = initial_walkers(data, theta, laplace_covariance(data, theta, scale), HALF_ENSEMBLE, np.random.default_rng(0))
    layout = data.layout
    result = {
        "log_probability_ms": 1e3 * best_time(lambda: log_probability(walkers, data), 50),
        "sweeps_ms": 1e3 * best_time(lambda: predicted_velocity(walkers, layout, data.frequency, data.voltage, data.sweep,
                                                                data.time_offset, data.mode_factor), 50),
        "ringdowns_ms": 1e3 * best_time(lambda: predicted_decay(walkers, layout, data.decays), 50),
    }
    if fit:
        cpu, wall = time.process_time(), time.perf_counter()
        answer = fit_damping(log, laws=("quadratic",), seed=0, forward=forward, stated_noise=0.005)
        result["fit_cpu_s"], result["fit_wall_s"] = time.process_time() - cpu, time.perf_counter() - wall
        write_fit(answer, folder / "fit", figures=True)
        result["command_cpu_s"], result["command_wall_s"] = time.process_time() - cpu, time.perf_counter() - wall
        best = answer.best
        q0 = np.exp(best.samples[:, 0])
        result["n_steps"], result["tau_max"] = best.diagnostics.n_steps, best.diagnostics.tau_max
        result["q0_p05_p50_p95"] = [float(q) for q in np.quantile(q0, (0.05, 0.5, 0.95))]
    return result


def autocorrelation() -> dict:
    """This code's autocorrelation estimate against emcee's on an AR(1) chain of the joint fit's size."""
    from emcee.autocorr import integrated_time

    from workflow.sampling import autocorrelation_times

    rng = np.random.default_rng(0)
    noise = rng.standard_normal((6500, 42, 20))
    chain = np.empty_like(noise)
    chain[0] = noise[0]
    for step in range(1, len(chain)):
        chain[step] = 0.98 * chain[step - 1] + noise[step]
    ours = best_time(lambda: autocorrelation_times(chain), 3)
    emcee_s = best_time(lambda: integrated_time(chain, tol=0), 3)
    difference = np.max(np.abs(autocorrelation_times(chain) / integrated_time(chain, tol=0) - 1))
    return {"seconds": ours, "emcee_seconds": emcee_s, "speed_up": emcee_s / ours, "max_relative_difference": float(difference)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", metavar="DIR", help="checkout of the code to compare with")
    parser.add_argument("--no-fit", action="store_true", help="time the log-probability only")
    parser.add_argument("--measure-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        if args.measure_only:
            print(json.dumps(measure(Path(folder), not args.no_fit)))
            return
        result = {"campaign": {"softening_s2_m2": SOFTENING, "drift_hz_s": DRIFT, "ringdown_voltages": RINGDOWN_VOLTAGES}}
        if args.reference:
            environment = dict(os.environ, PYTHONPATH=str(Path(args.reference).resolve()))
            command = [sys.executable, __file__, "--measure-only"] + (["--no-fit"] if args.no_fit else [])
            reply = subprocess.run(command, env=environment, capture_output=True, text=True, check=True)
            result["reference"] = dict(json.loads(reply.stdout.strip().splitlines()[-1]), path=args.reference)
        result["this"] = measure(Path(folder), not args.no_fit)
        result["autocorrelation"] = autocorrelation()
        if args.reference:
            result["ratio_reference_over_this"] = {
                key: result["reference"][key] / value
                for key, value in result["this"].items() if key.endswith(("_ms", "_s"))
            }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
