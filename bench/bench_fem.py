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

``--stages`` times the converged (0.2 %) evaluation stage by stage (mesh, assembly with its
sparsity-pattern build, factorisation, eigen solve and its number of solves, responses; levels used;
wall and CPU time), cold (first in the process) and warm (again: sparsity patterns cached), on
the original plate, the h_p = 1 mm optimum and P2, for both piezo models, with each result's error
against the converged values of ``bench/fem_references.json`` (bench/bench_accuracy.py); with
``--against TREE`` one evaluation runs in a fresh process with this code and one with another checkout
(e.g. the previous discretisation), giving the ratio of times (wall and CPU: on a loaded machine the CPU
time is the steadier) and both results' errors.  ``floor`` is the cost of the final level alone (one
assembly, one factorisation and the solves ARPACK needs there): what an evaluation that guessed its
level would still pay.

    python bench/bench_fem.py [--repeat N] [--width-mm B] [--no-accurate] [--stages [--against TREE]]
"""

import argparse
import cProfile
import json
import os
import pstats
import subprocess
import sys
import time
from pathlib import Path

from workflow.models import analytical
from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.accuracy import FemAccuracy, evaluate_to_accuracy, mesh_for_level
from workflow.models.fem.evaluate import discretise
from workflow.models.fem.modes import nearest_modes
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
    parser.add_argument("--stages", action="store_true", help="only the stage-by-stage timing of converged evaluations")
    parser.add_argument("--against", type=Path, help="with --stages: another checkout of the code to compare with")
    args = parser.parse_args(argv)
    if args.stages:
        figures = stage_figures(args.against)
        print(json.dumps(figures))
        return figures
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


PLATES = {
    "original": {},
    "hp1_optimum": {"wavelength": 21.515 * MM, "resonator_thickness": 0.916 * MM, "ceramic_thickness": 1.0 * MM,
                    "width": 49 * MM},
    "P2": {"wavelength": 15.66 * MM, "resonator_thickness": 0.5 * MM, "ceramic_thickness": 0.5 * MM, "width": 49 * MM},
}
"""The plates of the stage timing, as changes of the original plate [m]: the h_p = 1 mm FEM optimum (docs/fem.md)
and the published P2 (a transverse mode mixes in), both thin."""
REFERENCES = Path(__file__).resolve().parent / "fem_references.json"
"""Converged frequency and deflection of each plate and piezo model (bench/bench_accuracy.py --write-references)."""
STAGES = {
    "mesh": ("mesh.py", "quarter_plate_mesh"),
    "assembly": ("assembly.py", "assemble_system"),
    "pattern_build": ("assembly.py", "_cached_pattern"),
    "electric_assembly": ("piezoelectric.py", "electromechanical_system"),
    "factorisation": ("solvers.py", "factorise"),
    "eigen": ("modes.py", "shift_invert_modes"),
    "solves": ("solvers.py", "solve"),
    "responses": ("harmonic.py", "probe_modal_model"),
}
"""Stage name -> (file, function) whose cumulative time it is."""
COLD_SNIPPET = """
import json, sys, time
from workflow.models.fem import evaluate_fem
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.plate import ORIGINAL_PLATE
plate = ORIGINAL_PLATE.with_(**json.loads(sys.argv[1]))
start, cpu = time.perf_counter(), time.process_time()
result = evaluate_fem(plate, 54.0, 15.0, FemAccuracy(piezo=sys.argv[2]))
print(json.dumps({"s": time.perf_counter() - start, "cpu_s": time.process_time() - cpu, "f": result.frequency,
                  "w": result.deflection, "f_error": result.error.frequency, "level": result.error.level}))
"""
"""A converged evaluation in a fresh process (nothing cached) of the code on ``PYTHONPATH``."""


def stage_times(profile: cProfile.Profile) -> dict:
    """Cumulative seconds of each of :data:`STAGES` in a profile, and the number of solves."""
    times = dict.fromkeys(STAGES, 0.0)
    times["n_solves"] = 0
    for (filename, _, function), (_, calls, _, cumulative, _) in pstats.Stats(profile).stats.items():
        for name, (file, wanted) in STAGES.items():
            if filename.endswith(file) and function == wanted:
                times[name] += cumulative
                if name == "solves":
                    times["n_solves"] += calls
    return times


def profiled_evaluation(plate, piezo: str) -> dict:
    """Stage times and levels of one converged evaluation in this process."""
    levels = []

    def evaluate_mesh(settings, trial):
        start = time.perf_counter()
        result = evaluate_fem(plate, 54.0, 15.0, settings, trial)
        levels.append({"element": settings.element, "n_dofs": result.n_dofs, "s": time.perf_counter() - start})
        return result

    profile = cProfile.Profile()
    start, cpu = time.perf_counter(), time.process_time()
    profile.enable()
    result = evaluate_to_accuracy(plate, FemAccuracy(piezo=piezo), evaluate_mesh)
    profile.disable()
    return {
        "s": time.perf_counter() - start,
        "cpu_s": time.process_time() - cpu,
        "stages": stage_times(profile),
        "levels": levels,
        "f_khz": result.frequency / KHZ,
        "w_um": result.deflection / UM,
        "f_error_estimate": result.error.frequency,
        "level": result.error.level,
    }


def final_level_floor(plate, level: int) -> dict:
    """Seconds of the final level alone: assembly, one factorisation and ARPACK's solves (eigenstrain)."""
    settings = mesh_for_level(plate, level)
    start = time.perf_counter()
    _, system, _ = discretise(plate, 15.0, settings)
    assembled = time.perf_counter()
    modes = nearest_modes(system, float(analytical.resonance_frequency(plate)), settings.n_modes)
    solved = time.perf_counter()
    modes.solve_shifted(system.load)
    one_solve = time.perf_counter() - solved
    return {"level": level, "n_dofs": system.stiffness.shape[0], "assembly_s": assembled - start,
            "factorisation_and_eigen_s": solved - assembled, "one_solve_s": one_solve, "s": solved - start}


def cold_evaluation(tree: Path, plate_changes: dict, piezo: str) -> dict:
    """A converged evaluation in a fresh process running the code of ``tree``."""
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run(
        [sys.executable, "-c", COLD_SNIPPET, json.dumps(plate_changes), piezo],
        capture_output=True, text=True, check=True, env=environment, cwd=tree,  # python -c puts the cwd first
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def true_errors(result: dict, reference: dict | None) -> dict:
    """Relative errors of a result's f and w against the converged values (empty without references)."""
    if not reference or reference.get("f_converged_hz") is None:
        return {}
    errors = {"f_error_true": result["f"] / reference["f_converged_hz"] - 1}
    if reference.get("w_converged_um") is not None:
        errors["w_error_true"] = result["w"] / (reference["w_converged_um"] * UM) - 1
    return errors


def stage_figures(against: Path | None) -> dict:
    """Stage timing (cold and warm) of both piezo models on the plates of :data:`PLATES`."""
    here = Path(__file__).resolve().parent.parent
    references = json.loads(REFERENCES.read_text()) if REFERENCES.is_file() else {}
    figures = {"cpu_load_1min": os.getloadavg()[0]}
    for name, changes in PLATES.items():
        plate = ORIGINAL_PLATE.with_(**changes)
        for piezo in ("eigenstrain", "coupled"):
            reference = references.get(name, {}).get(piezo)
            entry = {"cold": profiled_evaluation(plate, piezo), "warm": profiled_evaluation(plate, piezo)}
            warm = entry["warm"]
            entry["warm"].update(true_errors({"f": warm["f_khz"] * KHZ, "w": warm["w_um"] * UM}, reference))
            if against is not None:  # both in fresh processes, one after the other
                cold = cold_evaluation(here, changes, piezo)
                previous = cold_evaluation(against, changes, piezo)
                entry["fresh_process"] = {"s": cold["s"], "cpu_s": cold["cpu_s"], **true_errors(cold, reference)}
                entry["previous_fresh_process"] = {"s": previous["s"], "cpu_s": previous["cpu_s"],
                                                   "f_error_estimate": previous["f_error"],
                                                   **true_errors(previous, reference)}
                entry["previous_over_this"] = previous["s"] / cold["s"]
                entry["previous_over_this_cpu"] = previous["cpu_s"] / cold["cpu_s"]
            if piezo == "eigenstrain":
                entry["floor"] = final_level_floor(plate, warm["level"])
            figures[f"{name}_{piezo}"] = entry
    figures["cpu_load_1min_after"] = os.getloadavg()[0]
    return figures


if __name__ == "__main__":
    main()
