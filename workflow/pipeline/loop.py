"""The loop of ``tactile run`` (docs/calibration.md, "The loop in tactile run"): design, build, measure,
calibrate, re-design robustly, build and measure again; and the case study on the published plates.

The bench simulator plays each plate as built with the hidden deviations of the [simulator] section
(:func:`workflow.pipeline.steps.built_plate_deviations`); the resonance search and the deflection scan
run through the real procedures and write built-plate logs into ``loop/`` of the run's folder.  The
calibration reads only those logs, never the deviations.
"""

from dataclasses import dataclass
from pathlib import Path

from workflow.errors import TactileError
from workflow.models.plate import Plate
from workflow.pipeline.runner import RunContext
from workflow.units import KHZ, MM

LOOP_FOLDER = "loop"
"""Sub-folder of the run's output with the loop's logs and calibration."""
LOOP_OUTPUTS = ("*.csv", "calibration.json", "*.png")
"""Glob patterns of the files the loop writes into its sub-folder."""
PAIRS_CAPTION = "Posterior of the calibration on plate #1"
"""Caption of the loop's calibration pairs figure."""
SCAN_VOLTAGE = 5.0
"""Drive of the deflection scan [V peak across the ceramics]."""


@dataclass(frozen=True)
class BuiltMeasurement:
    """One plate built on the simulator and measured.

    Attributes
    ----------
    plate : Plate
        Nominal design [m].
    nominal_frequency : float
        The nominal plate's working frequency by the simulator's FEM [Hz].
    built_frequency : float
        The simulator's truth: the FEM f_r of the plate as built [Hz].
    measured_frequency : float
        What the resonance search found [Hz].
    resonance_log, scan_log : Path or None
        The logs (no scan: None).
    mac : float or None
        MAC of the scan against the nominal FEM's map [-].
    """

    plate: Plate
    nominal_frequency: float
    built_frequency: float
    measured_frequency: float
    resonance_log: Path
    scan_log: Path | None
    mac: float | None


def loop_folder(context: RunContext) -> Path:
    folder = context.out / LOOP_FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def build_and_measure(context: RunContext, plate: Plate, name: str, scan: bool) -> BuiltMeasurement:
    """Play ``plate`` as built on the simulated bench; resonance search (and a scan) into ``loop/NAME-*.csv``."""
    from instruments.procedures.scan import ScanPlan, deflection_scan, grid_points
    from instruments.procedures.simulated import simulated_station, simulation_metadata
    from instruments.procedures.sweeps import ResonancePlan, resonance_search
    from instruments.simulator.bench import built_bench_settings
    from workflow.models.builtplate import PlateDeviations
    from workflow.pipeline.builtplate import built_plate_model, read_scan, scan_mac
    from workflow.pipeline.domain import bench_settings, built_plate_deviations

    loop = context.config["loop"]
    model = built_plate_model(plate, built_plate_deviations(context.config), cache=context.cache)
    nominal = built_plate_model(plate, PlateDeviations(), cache=context.cache)
    simulator = bench_settings(context.config)
    settings = built_bench_settings(
        model, drift_rate=context.config["simulator"]["drift_hz_per_s"], amplifier_gain=simulator.amplifier_gain,
        ceramic_voltage_limit=simulator.ceramic_voltage_limit, relative_noise=simulator.relative_noise,
        floor_fraction=simulator.floor_fraction, phase_noise=simulator.phase_noise, seed=simulator.seed,
    )
    station, _ = simulated_station(settings, settle_time=0.0)
    metadata = simulation_metadata(settings)
    folder = loop_folder(context)
    search = resonance_search(station, folder / f"{name}-resonance.csv",
                              ResonancePlan(start=loop["search_start_khz"] * KHZ), metadata, restart=True, fsync=False)
    frequency = search.summary["resonance_frequency_hz"]
    scan_log, mac = None, None
    if scan:
        points = grid_points(float(plate.length) / 2, float(plate.width) / 2, *loop["scan_grid"])
        scan_log = deflection_scan(station, folder / f"{name}-scan.csv", ScanPlan(frequency, SCAN_VOLTAGE, points),
                                   metadata, restart=True, fsync=False).path
        mac = scan_mac(read_scan(scan_log), nominal)
    return BuiltMeasurement(plate, nominal.resonance_frequency, model.resonance_frequency, frequency,
                            search.path, scan_log, mac)


def calibration_model(context: RunContext):
    """(FEM model, its conditions) of the run's calibrations and robust designs: the run's Q and voltage, the designs'
    accuracy ([fem] accuracy; :data:`~workflow.models.fem.accuracy.DEFAULT_ACCURACY` when it is 0: a fixed mesh), whose
    surrogates are two-level designs (:meth:`~workflow.optimise.fem_model.FemModel.design_fem`)."""
    from workflow.models.fem.accuracy import DEFAULT_ACCURACY
    from workflow.pipeline.calibration_files import calibration_accuracy
    from workflow.pipeline.domain import fem_model

    design = context.config["design"]
    accuracy = context.config["fem"]["accuracy"] or DEFAULT_ACCURACY
    fem = {"q": design["q"], "voltage_v": design["voltage_v"], "accuracy": accuracy,
           "piezo": context.config["fem"]["piezo"]}
    return fem_model(context, settings=calibration_accuracy(fem)), fem


def first_plate(context: RunContext) -> BuiltMeasurement | None:
    """Plate #1: the run's recommended design for the [loop] h_p, built and measured (resonance and scan)."""
    if not context.config["loop"]["enabled"]:
        return None
    hp = context.config["loop"]["hp_mm"] * MM
    designs = context.results.recommended_design.designs
    match = [design for key, design in designs.items() if abs(key - hp) < 1e-9]
    if not match:
        raise TactileError(f"[loop] hp_mm {hp / MM:g} is not among [design] ceramic_thicknesses_mm")
    return build_and_measure(context, match[0].plate, "plate1", scan=True)


def first_plate_figures(context: RunContext, measured: BuiltMeasurement | None) -> None:
    from workflow.pipeline.builtplate import built_plate_model, read_scan
    from workflow.pipeline.figures.scan import scan_figure

    if measured is None or measured.scan_log is None:
        return
    nominal = built_plate_model(measured.plate, cache=context.cache)
    context.save_figure(scan_figure(read_scan(measured.scan_log), nominal, measured.mac), "loop_scan.png",
                        scan_caption(context, measured))


def scan_caption(context: RunContext, measured: BuiltMeasurement) -> str:
    """The caption of plate #1's scan figure: the scan grid and the MAC against the nominal FEM."""
    grid = " × ".join(map(str, context.config["loop"]["scan_grid"]))
    return f"Plate #1 as built, scanned on a {grid} grid, beside the nominal FEM's map: MAC {measured.mac:.4f}"


def loop_calibration(context: RunContext):
    """The calibration on plate #1's resonance log and scan (default priors and sampler: resonance, deflection per
    volt and mode shape), and its prediction of plate #1."""
    from workflow.calibration.calibration import calibrate, predict
    from workflow.calibration.parameters import load_settings
    from workflow.pipeline.calibration_files import measured_plates

    measured = context.results.loop_first_plate
    if measured is None:
        return None
    model, fem = calibration_model(context)
    settings = load_settings()
    logs = [path for path in (measured.resonance_log, measured.scan_log) if path is not None]
    (plate,) = measured_plates(logs, settings)
    calibration = calibrate([plate], settings, model.design_fem(), fem)
    prediction = predict(calibration, plate.plate, None, calibration.surrogates[0])
    return calibration, tuple(float(f) for f in prediction.frequency)


def loop_calibration_files(context: RunContext, result) -> None:
    """``loop/calibration.json`` and the pairs figure."""
    from workflow.pipeline.calibration_files import write_calibration

    if result is None:
        return
    for path in write_calibration(result[0], loop_folder(context))["figures"]:
        context.record_figure(Path(path).relative_to(context.out).as_posix(), PAIRS_CAPTION)


def redesign(context: RunContext):
    """The robust re-design (:class:`~workflow.optimise.robust.RobustDesign`) under the calibration ([loop]
    reliability, stock h_i, the h_p and width of plate #1)."""
    from workflow.optimise.robust import RobustSettings, robust_design

    calibrated = context.results.loop_calibration
    if calibrated is None:
        return None
    calibration, _ = calibrated
    loop, design = context.config["loop"], context.config["design"]
    model, _ = calibration_model(context)
    first = context.results.loop_first_plate.plate
    stock = [t * MM for t in loop["stock_hi_mm"]]
    settings = RobustSettings(reliability=loop["reliability"], min_frequency=design["min_frequency_khz"] * KHZ)
    return robust_design(calibration, first.with_(resonator_thickness=stock[0]), stock, settings,
                         model.design_fem(), design["q"])


def second_plate(context: RunContext) -> BuiltMeasurement | None:
    """The re-designed plate built with the same hidden deviations and measured (resonance search)."""
    robust = context.results.loop_redesign
    return None if robust is None else build_and_measure(context, robust.best.plate, "plate2", scan=False)


def case_study(context: RunContext):
    """Cross-prediction between the published plates P1 and P2 (their data logs), or None when disabled; their
    surrogates from the calibration on the built plates when it has them (no FEM evaluation then)."""
    from workflow.calibration.case_study import cross_predictions
    from workflow.calibration.parameters import load_settings
    from workflow.calibration.published import PUBLISHED_PLATES, published_plates

    if not (context.config["loop"]["enabled"] and context.config["loop"]["case_study"]):
        return None
    settings = load_settings()
    built = context.results.built_calibration
    surrogates = None if built is None else built.surrogates_of(tuple(PUBLISHED_PLATES))
    first, second = published_plates() if surrogates is None else built.plates_of(tuple(PUBLISHED_PLATES))
    model, fem = calibration_model(context)
    return cross_predictions(first, second, settings, None if surrogates else model.design_fem(), fem, surrogates)
