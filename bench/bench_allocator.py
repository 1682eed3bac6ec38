"""The C allocator's thresholds (workflow.execution.memory.keep_freed_memory) against glibc's defaults.

Each round starts two fresh processes one after the other, one with the raised thresholds and one without, each
evaluating the plates of bench/bench_fem.py's ``PLATES`` to the default accuracy (0.2 %) ``--repeat`` times: the first
evaluation in a process pays the sparsity patterns and PARDISO's first analyses, the later ones are repeated
evaluations.  Prints one JSON object: per plate the median wall and system time of the first and of the repeated
evaluations with each allocator setting, the ratios (default / kept), and each process's peak resident memory.
docs/fem.md, "Speed".

    python bench/bench_allocator.py [--rounds 4] [--repeat 3] [--plates original hp1_optimum P2]
"""

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

CHILD = """
import json, resource, sys, time
from workflow.execution.memory import keep_freed_memory
kept = sys.argv[1] == "kept" and keep_freed_memory()
sys.path.insert(0, sys.argv[4])
from bench_fem import PLATES
from workflow.models.fem import evaluate_fem
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.plate import ORIGINAL_PLATE
plate = ORIGINAL_PLATE.with_(**PLATES[sys.argv[2]])
runs = []
for _ in range(int(sys.argv[3])):
    before, start = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    evaluate_fem(plate, 54.0, 15.0, FemAccuracy())
    after = resource.getrusage(resource.RUSAGE_SELF)
    runs.append({"wall_s": time.perf_counter() - start, "system_s": after.ru_stime - before.ru_stime,
                 "page_faults": after.ru_minflt - before.ru_minflt})
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
print(json.dumps({"kept": kept, "runs": runs, "peak_gb": peak}))
"""
HERE = Path(__file__).resolve().parent


def process(setting: str, plate: str, repeat: int) -> dict:
    """One fresh process's evaluations of ``plate`` with the allocator ``setting`` ("kept" or "default")."""
    output = subprocess.run([sys.executable, "-c", CHILD, setting, plate, str(repeat), str(HERE)],
                            capture_output=True, text=True, check=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def summary(processes: list) -> dict:
    """Medians over the processes: first evaluation, repeated evaluations, peak memory."""
    first = [p["runs"][0] for p in processes]
    repeated = [r for p in processes for r in p["runs"][1:]]
    figures = {"first_wall_s": statistics.median(r["wall_s"] for r in first),
               "first_system_s": statistics.median(r["system_s"] for r in first),
               "peak_gb": statistics.median(p["peak_gb"] for p in processes)}
    if repeated:
        figures["repeated_wall_s"] = statistics.median(r["wall_s"] for r in repeated)
        figures["repeated_system_s"] = statistics.median(r["system_s"] for r in repeated)
        figures["repeated_page_faults"] = statistics.median(r["page_faults"] for r in repeated)
    return figures


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=4, help="fresh processes per setting and plate")
    parser.add_argument("--repeat", type=int, default=3, help="evaluations per process (the first is cold)")
    parser.add_argument("--plates", nargs="+", default=["original", "hp1_optimum", "P2"])
    args = parser.parse_args(argv)
    figures = {}
    for plate in args.plates:
        runs = {"kept": [], "default": []}
        for _ in range(args.rounds):
            for setting in runs:
                runs[setting].append(process(setting, plate, args.repeat))
                print(plate, setting, json.dumps(runs[setting][-1]["runs"][0]), file=sys.stderr)
        if not all(p["kept"] for p in runs["kept"]):
            raise SystemExit("keep_freed_memory() did not apply here (not glibc?): nothing to compare")
        kept, default = summary(runs["kept"]), summary(runs["default"])
        figures[plate] = {"kept": kept, "default": default,
                          **{f"{key}_default_over_kept": default[key] / kept[key]
                             for key in ("first_wall_s", "repeated_wall_s") if key in kept}}
    print(json.dumps(figures))
    return figures


if __name__ == "__main__":
    main()
