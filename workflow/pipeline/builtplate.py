"""Built plates on the bench: their logs' metadata, deflection scans, and the FEM they are compared with.

* :func:`read_built_plate`: the built plate's nominal geometry a log's metadata names (:class:`~workflow.models.builtplate.BuiltPlate`);
* :func:`read_scan`: a deflection scan (``x_mm``, ``y_mm`` columns; docs/log-format.md);
* :func:`built_plate_model`: the FEM of a nominal plate built with deviations, as the bench
  simulator plays it, cached on disk by content (:mod:`workflow.execution.cache`); with no
  deviations it is the nominal plate's prediction;
* :func:`scan_mac`: the modal assurance criterion between a scan and the FEM's map.

Files are only read, never modified; a problem is an :class:`~workflow.errors.InputFileError`
naming the file and line.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from instruments import simulator
from instruments.simulator import builtplate as simulated
from workflow import logformat
from workflow.damping.logs import MIN_PEAK_VELOCITY, read_table
from workflow.errors import InputFileError
from workflow.execution.cache import EvaluationCache, content_key, package_directory, source_version
from workflow.models import fem
from workflow.models.builtplate import BuiltPlate, PlateDeviations
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.fem.settings import FemSettings
from workflow.models.fem.surface import modal_assurance_criterion
from workflow.models.limits import point_problem
from workflow.models.materials import PLATE_Q
from workflow.models.plate import Plate
from workflow.units import MM

def is_scan_log(path) -> bool:
    """Whether the log's column header names the scan's ``x_mm`` and ``y_mm`` columns (docs/log-format.md)."""
    return {logformat.X_POSITION, logformat.Y_POSITION} <= set(logformat.column_names(path))


def read_built_plate(path) -> BuiltPlate:
    """The nominal geometry a built-plate log names (``# lambda_mm``, ``# h_i_mm``, ``# h_p_mm``, ``# b_mm``, ...)."""
    return BuiltPlate.from_metadata(logformat.read_metadata(path), str(path))


@dataclass(frozen=True)
class ScanLog:
    """A deflection scan read from a log.

    Attributes
    ----------
    x, y : array
        Measurement points from the plate's centre [m].
    frequency : array
        Drive frequency [Hz].
    drive_voltage : array
        Peak voltage across the ceramics [V].
    velocity : array
        Peak velocity amplitude [m/s].
    phase_deg : array
        Phase of the velocity relative to the drive [deg].
    plate : BuiltPlate
        The nominal geometry the log names.
    source : str
    """

    x: np.ndarray
    y: np.ndarray
    frequency: np.ndarray
    drive_voltage: np.ndarray
    velocity: np.ndarray
    phase_deg: np.ndarray
    plate: BuiltPlate
    source: str

    @property
    def phasors(self) -> np.ndarray:
        """Complex velocity v e^{i phase} [m/s]."""
        return self.velocity * np.exp(1j * np.radians(self.phase_deg))


SCAN_NEEDS = (logformat.X_POSITION, logformat.Y_POSITION, logformat.FREQUENCY, logformat.DRIVE_VOLTAGE,
              logformat.VELOCITY, logformat.PHASE)
"""The columns a scan log must have."""


def read_scan(path) -> ScanLog:
    """Read a deflection scan of a built plate (docs/log-format.md).

    Raises
    ------
    InputFileError
        No built-plate metadata, a needed column missing, a row of the wrong length, a
        non-finite or implausible number (:func:`~workflow.damping.logs.read_table`), a missing
        velocity, a point off the named plate, no velocity above the reader's floor.
    """
    path = Path(path)
    plate = read_built_plate(path)
    table = read_table(path, required=SCAN_NEEDS, phase=True)
    if table.warnings:
        raise InputFileError(f"{table.warnings[0]}; a scan needs every point")
    columns = table.arrays
    x, y = columns[logformat.X_POSITION] * MM, columns[logformat.Y_POSITION] * MM
    nominal = plate.plate()
    for index, (x_i, y_i) in enumerate(zip(x, y)):
        reason = point_problem(nominal, x_i, y_i)
        if reason:
            raise InputFileError(f"{path}, line {table.line_numbers[index]}: {reason}")
    velocity = columns[logformat.VELOCITY]
    if velocity.max() < MIN_PEAK_VELOCITY:
        raise InputFileError(f"{path}: every velocity of the scan is below {MIN_PEAK_VELOCITY:g} m/s "
                             "(all zero, or not in m/s?): no mode shape to compare")
    return ScanLog(x, y, columns[logformat.FREQUENCY], columns[logformat.DRIVE_VOLTAGE], velocity,
                   columns[logformat.PHASE], plate, str(path))


def built_plate_model(nominal: Plate, deviations: PlateDeviations = PlateDeviations(),
                      settings: FemAccuracy | FemSettings = simulated.SIMULATION_ACCURACY,
                      cache: EvaluationCache | None = None) -> simulated.BuiltPlateModel:
    """:func:`instruments.simulator.builtplate.built_plate_model`, read from ``cache`` when it holds it."""
    if cache is None:
        return simulated.built_plate_model(nominal, deviations, settings)
    key = content_key({
        "model": "built-plate-surface",
        "plate": nominal,
        "deviations": deviations,
        "settings": settings.as_dict(),
        "code": [source_version(package_directory(package)) for package in (simulator, fem)],
    })
    found, value = cache.load(key)
    if not found:
        value = simulated.built_plate_model(nominal, deviations, settings)
        cache.store(key, value)
    return value


def predicted_map(scan: ScanLog, nominal: simulated.BuiltPlateModel, q: float = PLATE_Q) -> np.ndarray:
    """The nominal plate's complex deflection at the scan's points when driven at its working frequency [m].

    Parameters
    ----------
    scan : ScanLog
    nominal : BuiltPlateModel
        The FEM of the nominal plate (no deviations).
    q : float
        Quality factor [-].
    """
    return nominal.surface.deflection(scan.x, scan.y, nominal.resonance_frequency, q)


def scan_mac(scan: ScanLog, nominal: simulated.BuiltPlateModel, q: float = PLATE_Q) -> float:
    """MAC between the measured complex velocities of a scan and the nominal FEM's map at the same points [-]."""
    return modal_assurance_criterion(scan.phasors, predicted_map(scan, nominal, q))
