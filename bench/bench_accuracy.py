"""FEM accuracy: the levels of accuracy control against their converged limit, plate by plate.

For each plate, the FEM (eigenstrain, or ``--piezo coupled``) on the levels 2 to 6 (the polynomial degree
of the spectral elements on the mesh that follows the geometry), the converged frequency and deflection
extrapolated from the three highest levels with the rate fitted to them
(:func:`~workflow.models.fem.accuracy.extrapolated_limit`: independent of the estimator's assumed rate),
and for each level its true relative error against that limit beside the estimate accuracy control gives
it (from the level below).  Prints one JSON object; ``--write-references FILE`` also stores the limits,
the converged values bench/bench_fem.py measures both discretisations against; ``--references FILE``
measures the levels against stored limits instead (e.g. lower levels of another mesh rule against the limits
of a run to degree 6).  Slow (the level-6
meshes have 10^5 unknowns and more): run it on purpose.

    python bench/bench_accuracy.py [--levels 2 3 4 5 6] [--piezo eigenstrain|coupled] [--plates NAME ...]
                                   [--memory-gib 16] [--write-references FILE | --references FILE]

The degree-6 meshes of the thin plates take more than the 8 GiB an evaluation may use by default
(:data:`~workflow.models.fem.mesh.MEMORY_BUDGET`, about 11 GiB for P2); ``--memory-gib`` raises it for
this study only.
"""

import argparse
import json
import os
import time
from pathlib import Path

from workflow.errors import TactileError
from workflow.models.fem import evaluate_fem, mesh
from workflow.models.fem.accuracy import estimate_error, extrapolated_limit, mesh_for_level
from workflow.models.plate import ORIGINAL_PLATE, Plate

PLATES = {
    "original": ORIGINAL_PLATE,
    "original_b55": ORIGINAL_PLATE.with_(width=55e-3),
    "hp1_optimum": Plate(21.515e-3, 0.916e-3, 1e-3, 49e-3),
    "P2": Plate(15.66e-3, 0.5e-3, 0.5e-3, 49e-3),
}
"""The plates of the study: the original plate (mixed working mode at b = 49 mm), the same plate at
b = 55 mm (a clean mode), the h_p = 1 mm FEM optimum of the former quadratic meshes, and the published P2
(a transverse mode mixes in)."""


def limit(results: dict, levels, name: str) -> float | None:
    """The extrapolated limit of a result attribute over the three highest ``levels`` (None if not monotone)."""
    top = levels[-3:]
    try:
        return extrapolated_limit([getattr(results[k], name) for k in top], top)[0]
    except TactileError:
        return None


def study(plate: Plate, levels, piezo: str, reference: dict | None = None) -> dict:
    results, seconds = {}, {}
    for level in levels:
        start = time.perf_counter()
        results[level] = evaluate_fem(plate, 54.0, 15.0, mesh_for_level(plate, level, piezo=piezo))
        seconds[level] = time.perf_counter() - start
    if reference is None:
        f_converged, w_converged = limit(results, levels, "frequency"), limit(results, levels, "deflection")
    else:
        f_converged = reference["f_converged_hz"]
        w_converged = None if reference["w_converged_um"] is None else reference["w_converged_um"] * 1e-6
    rows = []
    for previous, level in zip(levels[:-1], levels[1:]):
        estimate = estimate_error(results[level], results[previous], level, previous)
        result = results[level]
        rows.append({
            "level": level,
            "dofs": result.n_dofs,
            "seconds": round(seconds[level], 2),
            "f_hz": round(result.frequency, 3),
            "w_um": round(result.deflection * 1e6, 5),
            "indicator": round(result.best.transverse_indicator, 3),
            "f_error_true": None if f_converged is None else result.frequency / f_converged - 1,
            "f_error_estimate": estimate.frequency,
            "w_error_true": None if w_converged is None else result.deflection / w_converged - 1,
            "w_error_estimate": estimate.deflection,
            "mode_match": round(estimate.mode_match, 4),
        })
    return {
        "plate_mm": {"lambda": plate.wavelength * 1e3, "h_i": plate.resonator_thickness * 1e3,
                     "h_p": plate.ceramic_thickness * 1e3, "b": plate.width * 1e3},
        "f_converged_hz": f_converged,
        "w_converged_um": None if w_converged is None else w_converged * 1e6,
        "levels": rows,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[2, 3, 4, 5, 6])
    parser.add_argument("--piezo", choices=("eigenstrain", "coupled"), default="eigenstrain")
    parser.add_argument("--plates", nargs="+", choices=sorted(PLATES), default=sorted(PLATES))
    parser.add_argument("--write-references", type=Path, help="store the converged values in this JSON file")
    parser.add_argument("--references", type=Path, help="measure the levels against the converged values of this file")
    parser.add_argument("--memory-gib", type=float, help="memory budget of one evaluation for this study [GiB]")
    args = parser.parse_args()
    if args.memory_gib:
        mesh.MEMORY_BUDGET = args.memory_gib * 2**30
    figures = {"piezo": args.piezo, "cpu_load_1min": os.getloadavg()[0]}
    stored = json.loads(args.references.read_text()) if args.references else {}
    figures.update({name: study(PLATES[name], sorted(args.levels), args.piezo, stored.get(name, {}).get(args.piezo))
                    for name in args.plates})
    if args.write_references:
        stored = json.loads(args.write_references.read_text()) if args.write_references.is_file() else {}
        for name in args.plates:
            stored.setdefault(name, {})[args.piezo] = {key: figures[name][key] for key in ("f_converged_hz", "w_converged_um")}
            stored[name][args.piezo]["levels"] = sorted(args.levels)[-3:]
        args.write_references.write_text(json.dumps(stored, indent=1) + "\n")
    print(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
