"""Two-level surrogate designs against designs evaluated to the accuracy at every point (issue 27, item 3).

For the surrogate boxes the run builds — the calibration's prior box around each published plate (24 points,
quadratic) and the robust design's box (lambda, the posterior's range, the manufacturing scatter: 14 points, linear)
around the h_p = 1 mm nominal optimum at two stocks, under the calibration on both published plates — the same Latin
hypercube is evaluated three ways, each into its own cache under ``--work`` (empty for the times: a rerun in the
same folder reads every result back and gives the errors only), on the local cores:

* ``survey``: every point to 0.5 % (what the run's calibrations and robust designs used before);
* ``accurate``: every point to 0.2 % (the reference: the accuracy asked for, at full price);
* ``two_level``: every point on mesh level 3, the centre and the farthest point also to 0.2 % (the default now).

Each surrogate is compared with fresh evaluations to 0.2 % at 8 other points of its box (rms and largest error of
ln f_r and ln w), and the times are given with their ratio to ``accurate`` in the same run.  Prints one JSON object.
docs/calibration.md, "Two-level designs".

    python bench/bench_two_level.py [--work DIR] [--fresh 8]
"""

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from workflow.calibration.calibration import calibrate
from workflow.calibration.parameters import deviated_plate, load_settings
from workflow.calibration.plate_surrogate import DesignFem, SurrogateDesign, fit_plate_surrogate, surrogate_design
from workflow.calibration.published import published_plates
from workflow.calibration.surrogate import latin_hypercube
from workflow.execution.cache import EvaluationCache
from workflow.models import materials
from workflow.models.fem.accuracy import DEFAULT_ACCURACY, SURVEY_ACCURACY, FemAccuracy
from workflow.models.plate import Plate
from workflow.optimise.fem_model import FemModel
from workflow.optimise.robust import (
    RobustSettings,
    fit_robust_surrogate,
    robust_design_points,
    robust_inputs,
    robust_plate,
)

NOMINAL_HP1 = Plate(21.577e-3, 0.930e-3, 1.0e-3, 49e-3)
"""The run's nominal FEM optimum at h_p = 1 mm (docs/calibration.md, "The recommended design in tactile run") [m]."""
STOCKS = (0.8e-3, 1.0e-3)
"""The two stocks the run tries for it [m]."""


def model(work: Path, label: str, target: float) -> FemModel:
    """An FEM model to ``target`` with its own empty cache under ``work``, on the local cores."""
    return FemModel(materials.PLATE_Q, materials.DESIGN_VOLTAGE, FemAccuracy(target),
                    cache=EvaluationCache(work / label))


def errors(surface_f, surface_w, fresh_points, truth) -> dict:
    """rms and largest error of a surrogate's ln f and ln w at fresh points against accurate values [-]."""
    found = {"f": surface_f(fresh_points) - truth[0], "w": surface_w(fresh_points) - truth[1]}
    return {f"{key}_rms": float(np.sqrt(np.mean(e**2))) for key, e in found.items()} | {
        f"{key}_max": float(np.max(np.abs(e))) for key, e in found.items()}


def compare(work: Path, name: str, design: SurrogateDesign, fresh_plates: list, fresh_points: np.ndarray, fit) -> dict:
    """One box: the three ways' times, evaluations and errors at the fresh points."""
    reference = model(work, f"{name}-fresh", DEFAULT_ACCURACY).evaluate_plates(fresh_plates)
    truth = (np.log([r.frequency for r in reference]), np.log([r.deflection for r in reference]))
    ways = {"survey": model(work, f"{name}-survey", SURVEY_ACCURACY).design_fem(),
            "accurate": DesignFem(model(work, f"{name}-accurate", DEFAULT_ACCURACY).evaluate_plates),
            "two_level": model(work, f"{name}-two", DEFAULT_ACCURACY).design_fem()}
    record = {}
    for way, fem in ways.items():
        started = time.perf_counter()
        (values,) = fem.values([design])
        seconds = time.perf_counter() - started
        surface_f, surface_w, fem_error = fit(design, values)
        record[way] = {"seconds": round(seconds, 1), "evaluations": values.evaluations, "fem_error": fem_error,
                       "f_loo": surface_f.loo_rms, "w_loo": surface_w.loo_rms,
                       **errors(surface_f, surface_w, fresh_points, truth)}
    for way in ("survey", "two_level"):
        record[way]["time_ratio_to_accurate"] = ratio(record[way]["seconds"], record["accurate"]["seconds"])
    return record


def ratio(seconds: float, reference: float):
    """``seconds / reference`` to 3 digits, None when the reference took no time (its results were cached: rerun
    with an empty ``--work`` for times)."""
    return round(seconds / reference, 3) if reference > 0 else None


def plate_fit(settings):
    def fit(design, values):
        surrogate = fit_plate_surrogate(settings.names, design, settings.surrogate_degree, values)
        return surrogate.log_frequency, surrogate.log_deflection, surrogate.fem_error
    return fit


def robust_fit(design, values):
    surrogate = fit_robust_surrogate(design, values)
    return surrogate.log_frequency, surrogate.log_deflection, values.fem_error


def main() -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, help="folder for the caches (default: a temporary one)")
    parser.add_argument("--fresh", type=int, default=8, help="fresh accurate points per box (8)")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_two_level_"))
    settings = load_settings()
    boxes = {}
    measured = published_plates()
    for plate in measured:
        name = Path(plate.name).stem
        design = surrogate_design(plate.plate, settings.names, settings.bounds, settings.surrogate_points,
                                  settings.surrogate_seed)
        fresh = latin_hypercube(args.fresh + 1, settings.bounds, 101)[1:]
        boxes[f"calibration {name}"] = compare(work, name, design, [deviated_plate(plate.plate, settings.names, t)
                                                                     for t in fresh], fresh, plate_fit(settings))
    calibration = calibrate(measured, settings, model(work, "calibration", DEFAULT_ACCURACY).design_fem(), {})
    names = robust_inputs(calibration)
    for stock in STOCKS:
        nominal = NOMINAL_HP1.with_(resonator_thickness=stock)
        design = robust_design_points(calibration, nominal, RobustSettings(), True)
        fresh = latin_hypercube(args.fresh + 1, design.bounds, 101)[1:]
        boxes[f"robust h_p 1 mm, h_i {stock * 1e3:g} mm"] = compare(
            work, f"robust{stock * 1e3:g}", design, [robust_plate(nominal, names, t) for t in fresh], fresh,
            robust_fit)
    total = {way: sum(box[way]["seconds"] for box in boxes.values()) for way in ("survey", "accurate", "two_level")}
    result = {"boxes": boxes, "total_seconds": total,
              "total_ratio_two_level_to_accurate": ratio(total["two_level"], total["accurate"]),
              "total_ratio_two_level_to_survey": ratio(total["two_level"], total["survey"])}
    print(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
