"""FEM accuracy on the thin designs: the mesh levels of accuracy control against their converged limit.

For each plate, the eigenstrain FEM on the levels 6, 8, 10, 12, 16 (elements per ceramic, the mesh
following the geometry), the converged frequency and deflection by Richardson extrapolation of the
two finest levels at the estimator's rate, and for each level its true relative error against that
limit beside the estimate accuracy control gives it (from the level before), and the old fixed default
mesh for reference.  Prints one JSON object.  Slow (minutes): run it on purpose.

    python bench/bench_accuracy.py [--levels 6 8 10 12 16]
"""

import argparse
import json
import time

from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.accuracy import estimate_error, mesh_for_level
from workflow.models.plate import ORIGINAL_PLATE, Plate

PLATES = {
    "original plate (lambda 24, h_i 2, h_p 1, b 49 mm)": ORIGINAL_PLATE,
    "original plate at b 55 mm (clean mode)": ORIGINAL_PLATE.with_(width=55e-3),
    "h_p 1 mm FEM optimum of the fixed mesh (lambda 21.52, h_i 0.897)": Plate(21.52e-3, 0.897e-3, 1e-3, 49e-3),
    "P2 / h_p 0.5 mm design (lambda 15.66, h_i 0.5)": Plate(15.66e-3, 0.5e-3, 0.5e-3, 49e-3),
}


def study(plate: Plate, levels) -> dict:
    results, seconds = {}, {}
    for level in levels:
        start = time.perf_counter()
        results[level] = evaluate_fem(plate, 54.0, 15.0, mesh_for_level(plate, level))
        seconds[level] = time.perf_counter() - start
    fine, coarse = levels[-1], levels[-2]
    limit = estimate_error(results[fine], results[coarse], fine, coarse)
    f_converged = results[fine].frequency / (1 + limit.frequency)
    w_converged = results[fine].deflection / (1 + limit.deflection)
    default = evaluate_fem(plate, 54.0, 15.0, FemSettings())
    rows = []
    for previous, level in zip(levels[:-1], levels[1:]):
        estimate = estimate_error(results[level], results[previous], level, previous)
        rows.append(
            {
                "level": level,
                "dofs": results[level].n_dofs,
                "seconds": round(seconds[level], 2),
                "f_hz": round(results[level].frequency, 2),
                "w_um": round(results[level].deflection * 1e6, 5),
                "indicator": round(results[level].best.transverse_indicator, 3),
                "f_error_true": results[level].frequency / f_converged - 1,
                "f_error_estimate": estimate.frequency,
                "w_error_true": results[level].deflection / w_converged - 1,
                "w_error_estimate": estimate.deflection,
            }
        )
    return {
        "f_converged_hz": f_converged,
        "w_converged_um": w_converged * 1e6,
        "levels": rows,
        "old_default_mesh": {
            "dofs": default.n_dofs,
            "f_hz": default.frequency,
            "w_um": default.deflection * 1e6,
            "indicator": default.best.transverse_indicator,
            "f_error": default.frequency / f_converged - 1,
            "w_error": default.deflection / w_converged - 1,
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[6, 8, 10, 12, 16])
    args = parser.parse_args()
    print(json.dumps({name: study(plate, args.levels) for name, plate in PLATES.items()}, indent=1))


if __name__ == "__main__":
    main()
