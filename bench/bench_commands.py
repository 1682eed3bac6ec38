"""Wall and CPU time of the commands that evaluate the FEM many times, cold (an empty cache, a fresh process).

``tactile optimize --model fem --hp-mm 1``, ``tactile calibrate`` on the two published plates, a 12 x 12 FEM map
(``tactile maps --model fem --hp-mm 1 --grid 12``) and ``tactile run`` on the embedded defaults, each in a fresh
process of this checkout with its own empty ``TACTILE_CACHE``; with ``--against TREE`` the same commands of another
checkout (e.g. the previous FEM discretisation) run right after each, for the ratio of times on a noisy machine.
Prints one JSON object on the last line.  Slow (minutes per command): run it on purpose.

    python bench/bench_commands.py [--commands optimize calibrate maps run] [--against TREE]
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from importlib import resources
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
PUBLISHED = resources.files("workflow.calibration.published")


def commands(out: Path) -> dict:
    """The timed commands by name (arguments after ``tactile``), writing under ``out``."""
    logs = [str(PUBLISHED / name) for name in ("paper_P1.csv", "paper_P2.csv")]
    return {
        "optimize": ["optimize", "--model", "fem", "--hp-mm", "1", "--json"],
        "calibrate": ["calibrate", *logs, "--out", str(out / "calibration"), "--no-figures", "--json"],
        "maps": ["maps", "--model", "fem", "--hp-mm", "1", "--grid", "12", "--out", str(out / "maps"), "--json"],
        "run": ["run", "--out", str(out / "run")],
    }


def timed_command(tree: Path, arguments: list) -> dict:
    """Wall and CPU time [s] of ``tactile ARGUMENTS`` run by the code of ``tree`` in a fresh process, empty cache."""
    with tempfile.TemporaryDirectory() as cache:
        environment = {**os.environ, "PYTHONPATH": str(tree), "TACTILE_CACHE": cache, "MPLBACKEND": "Agg"}
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", "import sys; from workflow.cli import main; sys.exit(main())",
                               *arguments], capture_output=True, text=True, env=environment, cwd=tree)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    figures = {"s": round(wall, 1), "cpu_s": round(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, 1),
               "exit": done.returncode}
    if done.returncode:
        figures["error"] = done.stderr.strip().splitlines()[-1:]
    elif "--json" in arguments:
        figures["json"] = json.loads(done.stdout.strip().splitlines()[-1])
    return figures


def summary(name: str, record: dict) -> dict:
    """The few numbers of a command's JSON worth keeping beside its time."""
    if name == "optimize":
        (optimum,) = record if isinstance(record, list) else record.get("optima", [record])
        return {key: optimum.get(key) for key in ("lambda_mm", "h_i_mm", "f_r_khz", "w_dyn_um", "fine_evaluations",
                                                  "f_error_estimate")}
    if name == "calibrate":
        return {"plates": [{key: p.get(key) for key in ("log", "measured_f_khz", "predicted_f_khz")} for p in record["plates"]]}
    return {}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commands", nargs="+", choices=("optimize", "calibrate", "maps", "run"),
                        default=["optimize", "calibrate", "maps", "run"])
    parser.add_argument("--against", type=Path, help="another checkout, timed right after this one")
    args = parser.parse_args()
    figures = {"cpu_load_1min": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as out:
        for name in args.commands:
            for label, tree in (("this", HERE), ("previous", args.against)):
                if tree is None:
                    continue
                entry = timed_command(tree, commands(Path(out) / label)[name])
                record = entry.pop("json", None)
                if record is not None:
                    entry.update(summary(name, record))
                figures.setdefault(name, {})[label] = entry
            if args.against is not None and "s" in figures[name].get("previous", {}):
                figures[name]["previous_over_this"] = figures[name]["previous"]["s"] / figures[name]["this"]["s"]
    figures["cpu_load_1min_after"] = os.getloadavg()[0]
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
