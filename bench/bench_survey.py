"""The survey accuracy's refinement rule against the previous one, on the geometries of `tactile run`'s FEM maps and
width sweep.

A survey evaluation (maps and the width sweep, 0.5 %) starts at degree 3 against 2.  When that estimate misses the
target, the previous rule jumped to the degree its Richardson estimate predicted (often 5), though degree 2 is not
yet asymptotic and degree 4 usually met the target; the current rule steps one degree after an estimate against
degree 2 (``accuracy.ASYMPTOTIC_LEVEL``) and extrapolates from there on.  Each rule runs in a fresh process, one after
the other, ``--rounds`` times, evaluating every geometry in turn (in process, the default MKL threads).  Prints one
JSON object: per rule the median total time, the degrees the evaluations ended on, the largest estimate, and each
geometry's frequency difference between the rules against their estimates.  docs/fem.md, "Accuracy control".

    python bench/bench_survey.py [--rounds 2] [--sweep-only]
"""

import argparse
import json
import statistics
import subprocess
import sys
from collections import Counter

CHILD = """
import json, sys, time
import numpy as np
from workflow.models.fem import accuracy, evaluate_fem
from workflow.optimise.maps import grid_axes
from workflow.pipeline.config import default_config
from workflow.pipeline.domain import build_plate, design_problems, fem_settings
from workflow.pipeline.steps import sweep_widths
if sys.argv[1] == "previous":
    accuracy.ASYMPTOTIC_LEVEL = accuracy.LEVELS[0]  # every estimate extrapolated: the previous rule
config = default_config()
plate = build_plate(config)
plates = [plate.with_(width=float(b)) for b in sweep_widths(config["fem"], plate.width)]
if sys.argv[2] == "all":
    for problem in design_problems(config, config["maps"]["fem_ceramic_thicknesses_mm"]).values():
        wavelength, thickness = grid_axes(problem, config["maps"]["fem_grid"])
        plates += [problem.plate(float(w), float(t)) for w in wavelength for t in thickness]
settings = fem_settings(config, "survey_accuracy")
start, rows = time.perf_counter(), []
for each in plates:
    result = evaluate_fem(each, config["design"]["q"], config["design"]["voltage_v"], settings)
    rows.append([result.frequency, result.error.frequency, result.error.level, result.error.met])
print(json.dumps({"seconds": time.perf_counter() - start, "rows": rows}))
"""


def run(rule: str, which: str) -> dict:
    output = subprocess.run([sys.executable, "-c", CHILD, rule, which], capture_output=True, text=True,
                            check=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2, help="fresh processes per rule")
    parser.add_argument("--sweep-only", action="store_true", help="the width sweep's geometries only, not the maps'")
    args = parser.parse_args(argv)
    which = "sweep" if args.sweep_only else "all"
    runs = {"current": [], "previous": []}
    for _ in range(args.rounds):
        for rule in runs:
            runs[rule].append(run(rule, which))
            print(rule, round(runs[rule][-1]["seconds"], 1), file=sys.stderr)
    figures = {}
    for rule, done in runs.items():
        rows = done[-1]["rows"]
        figures[rule] = {"seconds": statistics.median(d["seconds"] for d in done),
                         "geometries": len(rows),
                         "degrees": dict(sorted(Counter(r[2] for r in rows).items())),
                         "largest_estimate": max(abs(r[1]) for r in rows),
                         "missed": sum(not r[3] for r in rows)}
    current, previous = runs["current"][-1]["rows"], runs["previous"][-1]["rows"]
    figures["previous_over_current"] = figures["previous"]["seconds"] / figures["current"]["seconds"]
    differences = [abs(c[0] / p[0] - 1) / max(abs(c[1]), abs(p[1])) for c, p in zip(current, previous)]
    figures["largest_difference_over_estimate"] = max(differences)
    print(json.dumps(figures))
    return figures


if __name__ == "__main__":
    main()
