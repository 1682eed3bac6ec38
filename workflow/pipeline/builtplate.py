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

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from instruments import simulator
from instruments.simulator import builtplate as simulated
from workflow import logformat
from workflow.errors import InputFileError
from workflow.execution.cache import EvaluationCache, content_key, package_directory, source_version
from workflow.logformat import read_metadata
from workflow.models import fem
from workflow.models.builtplate import BuiltPlate, PlateDeviations
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.fem.settings import FemSettings
from workflow.models.fem.surface import modal_assurance_criterion
from workflow.models.materials import PLATE_Q
from workflow.models.plate import Plate
from workflow.units import MM

def is_scan_log(path) -> bool:
    """Whether the log's column header names the scan's ``x_mm`` and ``y_mm`` columns (docs/log-format.md)."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as stream:
            for line in stream:
                if line.strip() and not line.lstrip().startswith("#"):
                    fields = {field.strip() for field in next(csv.reader([line]))}
                    return {logformat.X_POSITION, logformat.Y_POSITION} <= fields
    except (OSError, UnicodeDecodeError) as error:
        raise InputFileError(f"{path}: cannot read ({getattr(error, 'strerror', None) or error})") from None
    return False


def read_built_plate(path) -> BuiltPlate:
    """The nominal geometry a built-plate log names (``# lambda_mm``, ``# h_i_mm``, ``# h_p_mm``, ``# b_mm``, ...)."""
    return BuiltPlate.from_metadata(read_metadata(Path(path)), str(path))


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
        non-finite number, a point off the named plate.
    """
    path = Path(path)
    plate = read_built_plate(path)
    columns = {name: [] for name in SCAN_NEEDS}
    header = None
    with open(path, encoding="utf-8-sig", newline="") as stream:
        for number, line in enumerate(stream, start=1):
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            fields = [field.strip() for field in next(csv.reader([line]))]
            if header is None:
                missing = [name for name in SCAN_NEEDS if name not in fields]
                if missing:
                    raise InputFileError(f"{path}, line {number}: not a scan: no {', '.join(missing)} column(s)")
                header = {name: fields.index(name) for name in SCAN_NEEDS}
                width = len(fields)
                continue
            if len(fields) != width:
                raise InputFileError(f"{path}, line {number}: expected {width} fields, got {len(fields)}")
            for name, index in header.items():
                try:
                    value = float(fields[index])
                except ValueError:
                    value = np.nan
                if not np.isfinite(value):
                    raise InputFileError(f"{path}, line {number}: {name} must be a finite number, got {fields[index]!r}")
                columns[name].append(value)
    if not columns[logformat.VELOCITY]:
        raise InputFileError(f"{path}: no scan rows")
    x, y = np.array(columns[logformat.X_POSITION]) * MM, np.array(columns[logformat.Y_POSITION]) * MM
    nominal = plate.plate()
    off = (np.abs(x) > float(nominal.length) / 2 + 1e-9) | (np.abs(y) > plate.width / 2 + 1e-9)
    if off.any():
        i = int(np.argmax(off))
        raise InputFileError(f"{path}: point ({x[i] / MM:g}, {y[i] / MM:g}) mm is off the named plate "
                             f"({float(nominal.length) / MM:g} x {plate.width / MM:g} mm)")
    return ScanLog(x, y, np.array(columns[logformat.FREQUENCY]), np.array(columns[logformat.DRIVE_VOLTAGE]),
                   np.array(columns[logformat.VELOCITY]), np.array(columns[logformat.PHASE]), plate, str(path))


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
