"""Would the robust design have put the published plates above 25 kHz?  (issue 29, point 5)

For each direction (P1 -> P2's h_p, P2 -> P1's h_p): calibrate on one published plate alone (``tactile
calibrate``), robust-design the other plate's ceramic thickness under that calibration (``tactile optimize --model
fem --calibration``: P(f_r >= 25 kHz) >= the reliability under its posterior and the manufacturing tolerances), then
predict that design with the calibration on both plates (``tactile evaluate --calibration``), the best knowledge of
what the design would resonate at without building it.  Everything runs through the command line a user has, with
the defaults, in a fresh process per command; FEM results are cached in ``--cache`` (shared between the commands:
the calibration on both reuses the single-plate surrogates).  Prints one JSON object.  docs/calibration.md.

    python bench/bench_published_robust.py --work DIR [--cache DIR] [--accuracy 0.002]
"""

import argparse
import json
import os
import subprocess
import sys
import time
from importlib import resources
from pathlib import Path

PLATES = {"P1": ("paper_P1.csv", 1.0), "P2": ("paper_P2.csv", 0.5)}
"""Published plate -> (its log in workflow.calibration.published, its ceramic thickness h_p [mm])."""


def tactile(arguments: list, cache: Path) -> dict:
    """Run ``tactile ARGUMENTS --json`` in a fresh process; its JSON record and wall time [s]."""
    environment = {**os.environ, "TACTILE_CACHE": str(cache), "MPLBACKEND": "Agg"}
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "workflow", *arguments, "--json"], capture_output=True, text=True,
                          env=environment)
    if done.returncode != 0:  # e.g. no admissible robust design: the command's one-line error is the answer
        return {"error": done.stderr.strip().splitlines()[-1], "wall_s": time.perf_counter() - started}
    return {**json.loads(done.stdout.strip().splitlines()[-1]), "wall_s": time.perf_counter() - started}


def main() -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, required=True, help="folder for the calibrations")
    parser.add_argument("--cache", type=Path, help="FEM cache (default: WORK/cache)")
    parser.add_argument("--accuracy", type=float, default=0.002, help="FEM accuracy of the calibrations (default 0.002)")
    args = parser.parse_args()
    cache = args.cache or args.work / "cache"
    args.work.mkdir(parents=True, exist_ok=True)
    published = resources.files("workflow.calibration.published")
    logs = {name: str(published / log) for name, (log, _) in PLATES.items()}
    calibrations = {}
    for names in (("P1",), ("P2",), ("P1", "P2")):  # a calibration that fails stops the study (SystemExit below)
        folder = args.work / ("cal_" + "_".join(names))
        record = tactile(["calibrate", *(logs[n] for n in names), "--out", str(folder), "--force",
                          "--accuracy", str(args.accuracy)], cache)
        if "error" in record:
            raise SystemExit(f"bench_published_robust: calibrating on {names}: {record['error']}")
        calibrations[names] = (folder, record)
    report = {"accuracy": args.accuracy, "calibrations": {"+".join(k): v[1]["wall_s"] for k, v in calibrations.items()},
              "directions": []}
    for source, target in (("P1", "P2"), ("P2", "P1")):
        hp = PLATES[target][1]
        robust = tactile(["optimize", "--model", "fem", "--hp-mm", f"{hp:g}", "--calibration",
                          str(calibrations[(source,)][0])], cache)
        predicted = None if "error" in robust else tactile(
            ["evaluate", "--model", "fem", "--lambda-mm", f"{robust['lambda_mm']:.6f}", "--hi-mm", f"{robust['h_i_mm']:g}",
             "--hp-mm", f"{hp:g}", "--calibration", str(calibrations[("P1", "P2")][0])], cache)
        report["directions"].append({"calibrated_on": source, "designed_h_p_mm": hp, "robust": robust,
                                     "predicted_by_both": predicted})
    print(json.dumps(report))
    return report


if __name__ == "__main__":
    main()
