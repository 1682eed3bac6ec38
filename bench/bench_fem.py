"""Benchmark of the FEM cost function; prints one JSON object on the last line.

The fast path (:func:`workflow.models.fem.evaluate_fem`: exact box integrals scattered in one
COO assembly, one real factorisation shared by the shift-invert eigen solve and the
modal harmonic responses) is timed against the plain reference path
(:func:`workflow.models.fem.reference.evaluate_fem_reference`: scikit-fem generic assembly with its
default quadrature, ARPACK's own factorisation, one complex direct solve per mode) on the
same mesh in the same run, so the ratio is meaningful on a noisy machine.  Then the evaluation at
the default accuracy (0.2 %: the mesh refined until its estimated error meets it, two or more
solves) with each installed sparse solver (SuperLU, PARDISO), and with the coupled piezoelectric
model, all in the same run: ratios of times, and the results' agreement.

    python bench/bench_fem.py [--repeat N] [--width-mm B] [--no-accurate]
"""

import argparse
import json
import os
import time

from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.fem.solvers import SOLVER_VARIABLE, available_solvers
from workflow.models.fem.reference import evaluate_fem_reference
from workflow.models.plate import ORIGINAL_PLATE
from workflow.units import KHZ, MM, UM


def timed(function, repeat):
    """(shortest wall time of ``repeat`` calls [s], last value)."""
    best, value = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        value = function()
        best = min(best, time.perf_counter() - start)
    return best, value


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed runs of the fast path (best is kept)")
    parser.add_argument("--width-mm", type=float, default=ORIGINAL_PLATE.width / MM, help="plate width [mm]")
    parser.add_argument("--no-accurate", action="store_true", help="skip the evaluations at the default accuracy")
    args = parser.parse_args(argv)
    plate = ORIGINAL_PLATE.with_(width=args.width_mm * MM)
    settings = FemSettings()
    fast_time, fast = timed(lambda: evaluate_fem(plate, 54.0, 15.0, settings), args.repeat)
    reference_time, reference = timed(lambda: evaluate_fem_reference(plate, 54.0, 15.0, settings), 1)
    figures = {
        "plate": {"lambda_mm": plate.wavelength / MM, "h_i_mm": plate.resonator_thickness / MM,
                  "h_p_mm": plate.ceramic_thickness / MM, "b_mm": plate.width / MM, "q": 54.0, "voltage_v": 15.0},
        "settings": settings.as_dict(),
        "n_dofs": fast.n_dofs,
        "fast_s": fast_time,
        "reference_s": reference_time,
        "speedup": reference_time / fast_time,
        "fast": {"f_khz": fast.frequency / KHZ, "w_um": fast.deflection / UM},
        "reference": {"f_khz": reference.frequency / KHZ, "w_um": reference.deflection / UM},
        "max_mode_frequency_rel_diff": max(
            abs(a.frequency / b.frequency - 1) for a, b in zip(fast.modes, reference.modes)
        ),
        "best_deflection_rel_diff": abs(fast.deflection / reference.deflection - 1),
    }
    if not args.no_accurate:
        figures["accurate"] = accurate_paths(plate)
    print(json.dumps(figures))
    return figures


def _with_solver(name: str, function):
    previous = os.environ.get(SOLVER_VARIABLE)
    os.environ[SOLVER_VARIABLE] = name
    try:
        return timed(function, 1)
    finally:
        if previous is None:
            del os.environ[SOLVER_VARIABLE]
        else:
            os.environ[SOLVER_VARIABLE] = previous


def accurate_paths(plate) -> dict:
    """The default accuracy (0.2 %) with each installed solver, and the coupled model with the fastest."""
    paths = {}
    for solver in available_solvers():
        seconds, result = _with_solver(solver, lambda: evaluate_fem(plate, 54.0, 15.0, FemAccuracy()))
        paths[solver] = {
            "s": seconds,
            "f_khz": result.frequency / KHZ,
            "w_um": result.deflection / UM,
            "f_error_estimate": result.error.frequency,
            "mesh_level": result.error.level,
            "n_dofs": result.n_dofs,
        }
    fastest = available_solvers()[0]
    seconds, coupled = _with_solver(fastest, lambda: evaluate_fem(plate, 54.0, 15.0, FemAccuracy(piezo="coupled")))
    paths["coupled_" + fastest] = {
        "s": seconds,
        "f_khz": coupled.frequency / KHZ,
        "f_a_khz": coupled.antiresonance / KHZ,
        "k_eff": coupled.coupling_factor,
        "w_um": coupled.deflection / UM,
        "f_error_estimate": coupled.error.frequency,
        "mesh_level": coupled.error.level,
    }
    if "pardiso" in paths:
        paths["superlu_over_pardiso"] = paths["superlu"]["s"] / paths["pardiso"]["s"]
        paths["pardiso_vs_superlu_f_rel_diff"] = abs(paths["pardiso"]["f_khz"] / paths["superlu"]["f_khz"] - 1)
    paths["coupled_over_eigenstrain"] = seconds / paths[fastest]["s"]
    return paths


if __name__ == "__main__":
    main()
