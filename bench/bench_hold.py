"""The demonstration of ``tactile measure hold`` (docs/instruments.md, "Holding resonance and amplitude"): prints one
JSON object and writes the figures.

Ten simulated minutes at the original plate's working amplitude (0.216 m/s, 1.07 um at 15 V) on the default bench,
closed loop and open loop (frozen once locked), with the literature frequency coefficient of the plate and with it
times 25 (a warm-up of several bandwidths); the lock-in at its default 30 ms.  The simulator's truth (the plate's
resonance and antinode velocity at each reading) is recorded beside the logs.

    python bench/bench_hold.py [--figures docs/figures] [--factor 25]
"""

import argparse
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from instruments.procedures.hold import HoldPlan, hold
from instruments.procedures.simulated import simulated_station, simulation_metadata
from instruments.simulator import default_bench_settings
from instruments.simulator.physics import working_point_velocity
from workflow.pipeline.figures.hold import hold_figure
from workflow.pipeline.hold_logs import read_hold_log
from workflow.pipeline.rendering import save_figure


def run(folder: Path, factor: float, closed: bool) -> dict:
    """One hold; its summary, the truth's figures of merit, the log."""
    settings = default_bench_settings()
    settings = replace(settings, response=replace(settings.response, thermal=settings.response.thermal.scaled(factor)))
    station, bench = simulated_station(settings)
    truth, read = [], station.read_velocity

    def recorded():
        reading = read()
        truth.append((bench.time, bench.resonance(), bench.steady()[0], bench.generator.state.frequency))
        return reading

    station.read_velocity = recorded
    target, law = working_point_velocity(), settings.response.law
    path = folder / f"hold-{factor:g}-{'closed' if closed else 'open'}.csv"
    start = time.perf_counter()
    result = hold(station, path, HoldPlan(round(settings.response.resonance_frequency), target, 600.0, 1.0, law, closed),
                  simulation_metadata(settings), fsync=False)
    seconds = time.perf_counter() - start
    truth = np.array(truth)
    bandwidth = settings.response.resonance_frequency / float(law.quality_factor(target))
    held = truth[:, 0] > 30.0
    return {"log": path, "truth": truth, "summary": result.summary, "seconds": seconds,
            "resonance_drift_bandwidths": float((truth[0, 1] - truth[-1, 1]) / bandwidth),
            "true_max_velocity_error": float(np.max(np.abs(truth[held, 2] / target - 1))),
            "true_final_velocity_error": float(truth[-1, 2] / target - 1),
            "max_frequency_error_bandwidths": float(np.max(np.abs(truth[held, 3] - truth[held, 1])) / bandwidth),
            "final_temperature_rise_k": float(bench.heating())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--figures", type=Path, help="folder to write hold.png and hold_literature.png into")
    parser.add_argument("--factor", type=float, default=25.0, help="the stress case's frequency coefficient factor")
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        for factor in (1.0, args.factor):
            runs = {closed: run(Path(folder), factor, closed) for closed in (True, False)}
            results[factor] = runs
            if args.figures:
                name = "hold_literature.png" if factor == 1.0 else "hold.png"
                records = [replace(read_hold_log(runs[closed]["log"]), label=f"{'closed' if closed else 'open'} loop")
                           for closed in (True, False)]
                resonances = [(f"plate's resonance, {'closed' if closed else 'open'} loop", runs[closed]["truth"][:, 0],
                               runs[closed]["truth"][:, 1]) for closed in (True, False)]
                title = (f"10 min at 0.216 m/s (1.07 µm), frequency coefficient x{factor:g} of CuBe's: the resonance "
                         f"drifts {runs[True]['resonance_drift_bandwidths']:.2f} bandwidths under the closed loop")
                save_figure(hold_figure(records, title, resonances), args.figures / name)
    print(json.dumps({f"{factor:g}": {("closed" if closed else "open"): {key: value for key, value in run.items()
                                                                          if key not in ("log", "truth")}
                                       for closed, run in runs.items()} for factor, runs in results.items()},
                     indent=1))


if __name__ == "__main__":
    main()
