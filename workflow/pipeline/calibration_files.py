"""Files and JSON records of a calibration: ``calibration.json`` (what ``--calibration`` reads) and the keys
that ``calibrate``, ``evaluate``, ``optimize``, ``maps`` and ``run`` print."""

import json
from pathlib import Path

import numpy as np

from workflow.calibration.calibration import (
    Calibration,
    MeasuredPlate,
    Prediction,
    interval_contents,
    measured_plate,
    predict,
)
from workflow.calibration.logs import read_built_plate
from workflow.calibration.measurements import scan_shape
from workflow.calibration.parameters import CalibrationSettings
from workflow.damping.logs import SAME_PLATE_TOLERANCE
from workflow.errors import InputFileError
from workflow.inputfiles import MAX_CALIBRATION_BYTES, load_json
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.fem.surface import modal_assurance_criterion
from workflow.optimise.robust import RobustDesign
from workflow.pipeline.builtplate import is_scan_log, read_scan
from workflow.pipeline.outputs import save_figure
from workflow.pipeline.records import geometry_record
from workflow.units import KHZ, NM, UM

CALIBRATION_FILE = "calibration.json"
PAIRS_FIGURE = "calibration_pairs.png"
CALIBRATION_OUTPUTS = (CALIBRATION_FILE, PAIRS_FIGURE)
"""Files ``tactile calibrate`` writes into its folder (:mod:`workflow.pipeline.outputs`)."""


def measured_plates(paths, settings: CalibrationSettings, use_deflection: bool = True, mixed_plates: str = "refuse",
                    warnings: list | None = None) -> list[MeasuredPlate]:
    """What the logs measured, one entry per resonance log; a scan log joins the resonance log naming the same plate.

    A scan driven more than :data:`~workflow.damping.logs.SAME_PLATE_TOLERANCE` away from the resonance its
    resonance log measured is of another plate: refused, or with ``mixed_plates="warn"`` appended to ``warnings``.

    Raises
    ------
    InputFileError
        A scan log whose plate no resonance log names, or two scans of one plate, naming the file; a scan of
        another plate (see above).
    """
    is_scan = [is_scan_log(path) for path in paths]
    scans = [read_scan(path) for path, scan in zip(paths, is_scan) if scan]
    logs = [read_built_plate(path) for path, scan in zip(paths, is_scan) if not scan]
    if not logs:
        raise InputFileError(f"{paths[0]}: only scan logs given; the calibration needs a resonance log of each plate")
    matched = {}
    for scan in scans:
        nominal = scan.plate.plate()
        same = [k for k, log in enumerate(logs) if _same_geometry(log.plate, nominal)]
        if not same:
            raise InputFileError(f"{scan.source}: no resonance log given names this scan's plate "
                                 f"(lambda {nominal.wavelength * 1e3:g} mm, h_i {nominal.resonator_thickness * 1e3:g} mm)")
        if same[0] in matched:
            raise InputFileError(f"{scan.source}: a second scan of the plate of {logs[same[0]].source}; give one")
        driven, resonance = float(np.median(scan.frequency)), logs[same[0]].frequency
        if abs(driven / resonance - 1) > SAME_PLATE_TOLERANCE:
            mismatch = (f"{scan.source} was driven at {driven:.0f} Hz, {abs(driven / resonance - 1) * 100:.1f} % from the "
                        f"resonance {resonance:.0f} Hz of {logs[same[0]].source}: a scan of another plate of this design?")
            if mixed_plates == "refuse":
                raise InputFileError(f"{mismatch} (--mixed-plates warn calibrates with it anyway)")
            warnings.append(mismatch)
        matched[same[0]] = scan_shape(scan.x, scan.y, scan.phasors, settings.shape_sigma, scan.source)
    return [measured_plate(log, matched.get(k), use_deflection) for k, log in enumerate(logs)]


def _same_geometry(a, b) -> bool:
    names = ("wavelength", "resonator_thickness", "ceramic_thickness", "width")
    return all(abs(float(getattr(a, n)) - float(getattr(b, n))) <= 1e-9 for n in names)


def write_calibration(calibration: Calibration, out: Path, figures: bool = True, protect=()) -> dict:
    """Write ``calibration.json`` and the pairs figure into ``out``; return their paths."""
    files = {"calibration": str(out / CALIBRATION_FILE), "figures": []}
    for name in CALIBRATION_OUTPUTS:
        if (out / name).resolve() in protect:
            raise InputFileError(f"--out: writing {out / name} would overwrite an input log; choose another folder")
    (out / CALIBRATION_FILE).write_text(json.dumps(calibration.to_dict()) + "\n", encoding="utf-8")
    if figures:
        from workflow.pipeline.figures.calibration import pairs_figure

        files["figures"].append(save_figure(pairs_figure(calibration), out / PAIRS_FIGURE, dpi=110))
    return files


def calibration_accuracy(fem: dict) -> FemAccuracy:
    """The FEM accuracy a calibration was made at (its ``fem`` record: ``accuracy`` and ``piezo``), which every
    prediction with it uses."""
    return FemAccuracy(target=fem["accuracy"], piezo=fem["piezo"])


def load_calibration(path) -> Calibration:
    """The calibration in ``path`` (``calibration.json`` or its folder).

    Raises
    ------
    InputFileError
        Missing, unreadable, oversized, too deeply nested (:func:`~workflow.inputfiles.load_json`), not JSON,
        or not a calibration file (:meth:`Calibration.from_dict`), naming the path.
    """
    path = Path(path)
    if path.is_dir():
        path = path / CALIBRATION_FILE
    data = load_json(path, f"--calibration {path}", MAX_CALIBRATION_BYTES)
    return Calibration.from_dict(data, f"--calibration {path}")


def calibration_summary(calibration: Calibration, nominal_frequencies, files: dict, seconds: float) -> dict:
    """The JSON of ``tactile calibrate``: parameters, plates, calibration file, diagnostics, identifiability.

    Parameters
    ----------
    calibration : Calibration
    nominal_frequencies : sequence of float
        FEM f_r of each nominal plate [Hz].
    files : dict
        From :func:`write_calibration`.
    seconds : float
        Wall time of the whole calibration [s].
    """
    plates = []
    for plate, surrogate, nominal in zip(calibration.plates, calibration.surrogates, nominal_frequencies):
        predicted = predict(calibration, plate.plate, None, surrogate).frequency
        plates.append({
            "data_used": plate.data_used,
            **measured_terms(calibration, plate, surrogate),
            "log": plate.name,
            **geometry_record(plate.plate),
            "measured_f_khz": plate.frequency / KHZ,
            "predicted_f_khz": predicted[1] / KHZ,
            "predicted_f_khz_p05": predicted[0] / KHZ,
            "predicted_f_khz_p95": predicted[2] / KHZ,
            "nominal_f_khz": nominal / KHZ,
            "surrogate_error": surrogate.log_frequency.loo_rms,
            "fem_error": surrogate.fem_error,
        })
    return {
        "parameters": calibration.summary(),
        "plates": plates,
        "calibration": files["calibration"],
        "figures": files["figures"],
        "diagnostics": calibration.diagnostics.to_dict(),
        "identifiability": calibration.identifiability(),
        "at_prior_bound": calibration.at_prior_bounds(),
        "check": calibration.check(),
        "intervals": interval_contents(calibration.settings),
        "fem_evaluations": calibration.evaluations + len(calibration.plates),
        "fem_surface_evaluations": sum(s.evaluations for s in calibration.surrogates if s.shape is not None),
        "wall_time_s": seconds,
        "fem": calibration.fem,
    }


def measured_terms(calibration: Calibration, plate: MeasuredPlate, surrogate) -> dict:
    """A plate's deflection per volt (measured, posterior p05/p50/p95 [nm/V], surrogate error) and scan (points, noise,
    MAC of the measured pattern with the posterior-median prediction) keys, for the terms it has."""
    record = {}
    if plate.deflection_per_volt is not None:
        g = np.exp(np.percentile(surrogate.log_point_deflection(calibration.samples), [5, 50, 95])) / NM
        record.update({"measured_deflection_nm_v": plate.deflection_per_volt / NM, "predicted_deflection_nm_v": g[1],
                       "predicted_deflection_nm_v_p05": g[0], "predicted_deflection_nm_v_p95": g[2],
                       "deflection_surrogate_error": surrogate.log_point_deflection.loo_rms})
    if plate.scan is not None:
        measured = np.array(plate.scan.pattern)
        predicted = surrogate.shape(np.median(calibration.samples, axis=0))
        record["scan"] = {"log": plate.scan.source, "points": len(measured), "noise": plate.scan.noise,
                          "mirror_scatter": plate.scan.mirror_scatter,
                          "mac": modal_assurance_criterion(measured, predicted),
                          "surrogate_error_max": float(np.max(surrogate.shape.errors))}
    return record


def calibrated_record(prediction: Prediction, source: str) -> dict:
    """Posterior-predictive keys of one plate (:func:`~workflow.calibration.calibration.predict`, with the calibration
    read from ``source``): ``f_r_khz`` (median), ``f_r_khz_p05``/``_p95``, ``w_dyn_um`` likewise, the calibration's
    file, surrogate error, FEM evaluations and samples, and what the intervals contain."""
    f, w, surrogate = prediction.frequency, prediction.deflection, prediction.surrogate
    return {
        "f_r_khz": f[1] / KHZ, "f_r_khz_p05": f[0] / KHZ, "f_r_khz_p95": f[2] / KHZ,
        "w_dyn_um": w[1] / UM, "w_dyn_um_p05": w[0] / UM, "w_dyn_um_p95": w[2] / UM,
        "calibration": {"file": source, "surrogate_error": surrogate.log_frequency.loo_rms,
                        "fem_evaluations": surrogate.evaluations, "samples": prediction.samples},
        "intervals": prediction.contents,
    }


def robust_record(design: RobustDesign, reliability: float, seconds: float) -> dict:
    """The JSON of a robust optimum: the best candidate's keys, every candidate, the counts."""
    def candidate(c) -> dict:
        return {
            **geometry_record(c.plate),
            "f_r_khz": c.frequency[1] / KHZ, "f_r_khz_p05": c.frequency[0] / KHZ, "f_r_khz_p95": c.frequency[2] / KHZ,
            "w_dyn_um": c.deflection[1] / UM, "w_dyn_um_p05": c.deflection[0] / UM, "w_dyn_um_p95": c.deflection[2] / UM,
            "probability": c.probability, "probability_se": c.probability_error, "probability_draws": c.draws,
            "margin_khz": c.margin / KHZ, "separated": c.separated,
            "nearest_transverse": None if c.nearest_transverse is None else {
                "f_khz": c.nearest_transverse["f"] / KHZ,
                "relative_distance": c.nearest_transverse["relative_distance"],
                "indicator": c.nearest_transverse["indicator"],
            },
            "homogeneity_cv": c.homogeneity, "surrogate_error": c.surrogate_error,
            "lambda_at_box_edge": c.lambda_at_edge, "fem_evaluations": c.evaluations,
        }

    best = candidate(design.best)
    return {
        **best,
        "reliability": reliability,
        "candidates": [candidate(c) for c in design.candidates],
        "fine_evaluations": design.evaluations,
        "wall_time_s": seconds,
    }
