"""FEM optimum by direct NLopt vs space mapping: fine evaluations, distance, time (JSON on stdout).

Three runs per h_p: the direct run, space mapping with the FEM's design sensitivities (what
``optimise_fem`` does) and the responses-only space mapping (what it does for the FEM with
Q(v)); distances are to the direct run, time ratios against it.

Usage: python bench/bench_space_mapping.py [h_p_mm ...] [--width-mm B]   (default h_p 1 mm, b 49 mm).
Uncached, in-process FEM.
"""

import argparse
import json
import time
from dataclasses import replace

import numpy as np

from workflow.optimise.fem_model import FemModel
from workflow.optimise.fem_optimum import optimise_fem
from workflow.optimise.problem import DesignProblem, analytical_model
from workflow.optimise.space_mapping import ResponseMapping, space_mapping_optimum
from workflow.units import MM, UM


def compare(ceramic_thickness_mm: float, width_mm: float | None = None) -> dict:
    problem = DesignProblem(ceramic_thickness_mm * MM)
    if width_mm is not None:
        problem = replace(problem, width=width_mm * MM)
    record = {"h_p_mm": ceramic_thickness_mm, "b_mm": problem.width / MM}
    designs = {}

    for method in ("nlopt", "space-mapping", "space-mapping-responses-only"):
        start = time.perf_counter()
        fem_model = FemModel(scheduler="synchronous")
        if method == "space-mapping-responses-only":
            coarse = analytical_model(fem_model.q, problem.voltage)
            found = space_mapping_optimum(fem_model.responses, coarse, problem, ResponseMapping)
        else:
            found = optimise_fem(problem, fem_model, method)
        plate = found.optimum.plate
        designs[method] = np.array([plate.wavelength, plate.resonator_thickness]) / MM
        record[method] = {
            "seconds": round(time.perf_counter() - start, 2),
            "fine_evaluations": found.fine_evaluations,
            "coarse_evaluations": found.coarse_evaluations,
            "lambda_mm": float(designs[method][0]),
            "h_i_mm": float(designs[method][1]),
            "w_dyn_um": found.optimum.deflection / UM,
            "f_r_khz": found.optimum.frequency / 1e3,
        }
        if method != "nlopt":
            record[method]["distance_mm"] = float(np.max(np.abs(designs["nlopt"] - designs[method])))
            record[method]["time_ratio_to_direct"] = round(record[method]["seconds"] / record["nlopt"]["seconds"], 3)
    return record


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("hp_mm", type=float, nargs="*", default=[1.0], help="ceramic thicknesses h_p [mm] (default 1)")
    parser.add_argument("--width-mm", type=float, default=None, help="plate width b [mm] (default 49)")
    arguments = parser.parse_args()
    print(json.dumps([compare(size, arguments.width_mm) for size in arguments.hp_mm]))
