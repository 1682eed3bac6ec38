"""The sparsity pattern of a mesh topology (what a first evaluation builds once per level), against another checkout.

For each degree, the pattern of the plate's mesh (`workflow.models.fem.assembly.reduced_pattern`) is built in a fresh
process of this checkout and of ``--against``, alternating, ``--rounds`` times (a fresh process: its arrays are new
memory, as in a first evaluation).  Prints one JSON object: per degree the times of each and the ratio of their
medians.  docs/fem.md, "Speed".

    python bench/bench_pattern.py --against /tmp/fem-before [--degrees 4 5] [--rounds 3] [--width-mm 49]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

CHILD = """
import sys, time
from workflow.models.fem import assembly
from workflow.models.fem.accuracy import mesh_for_level
from workflow.models.fem.mesh import quarter_plate_mesh
from workflow.models.plate import ORIGINAL_PLATE
plate = ORIGINAL_PLATE.with_(width=float(sys.argv[2]) * 1e-3)
mesh = quarter_plate_mesh(plate, mesh_for_level(plate, int(sys.argv[1])))
free = assembly.free_dofs(mesh)
start = time.perf_counter()
assembly.reduced_pattern(mesh, free)
print(time.perf_counter() - start, assembly.__file__)
"""
HERE = Path(__file__).resolve().parent.parent


def pattern_time(tree: Path, degree: int, width_mm: float) -> float:
    """Seconds to build the pattern in a fresh process importing ``workflow`` from ``tree``."""
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    output = subprocess.run([sys.executable, "-c", CHILD, str(degree), str(width_mm)], env=environment, cwd=tree,
                            capture_output=True, text=True, check=True).stdout  # cwd: "-c" puts it first on the path
    seconds, source = output.split()[-2:]
    if not Path(source).resolve().is_relative_to(tree):
        raise SystemExit(f"bench_pattern: {tree} imported workflow from {source}")
    return float(seconds)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", type=Path, required=True, help="another checkout of the code")
    parser.add_argument("--degrees", type=int, nargs="+", default=[4, 5])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--width-mm", type=float, default=49.0, help="plate width [mm] (the others: the original plate)")
    args = parser.parse_args()
    report = {"cpu_load_1min": os.getloadavg()[0], "width_mm": args.width_mm}
    for degree in args.degrees:
        this, previous = [], []
        for _ in range(args.rounds):
            this.append(pattern_time(HERE, degree, args.width_mm))
            previous.append(pattern_time(args.against.resolve(), degree, args.width_mm))
        report[f"degree_{degree}"] = {"this_s": this, "previous_s": previous,
                                      "previous_over_this": statistics.median(previous) / statistics.median(this)}
    print(json.dumps(report))


if __name__ == "__main__":
    main()
