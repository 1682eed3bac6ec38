"""Reading and validating interferometer logs (docs/log-format.md, format version 1).

The reader only opens files for reading: an input file is never modified.  Anything a
user must fix raises :class:`~workflow.errors.InputFileError` naming the file, the line
and the problem.  Two things are tolerated with a warning (collected on the result, the
CLI prints each as one line): rows whose velocity is missing or ``nan`` (vibrometer
dropouts) are dropped and counted, and an incomplete last line without a newline (a
writer interrupted mid-row) is ignored.
"""

import math
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence, Tuple

import numpy as np

from workflow import logformat
from workflow.damping.mode_shape import BeamMode, measurement_factor
from workflow.errors import InputFileError
from workflow.models import materials
from workflow.models.builtplate import BuiltPlate
from workflow.models.limits import LIMITS, problem
from workflow.units import MM

_QUANTITY_STEMS = {
    logformat.FREQUENCY: ("frequency", "freq"),
    logformat.DRIVE_VOLTAGE: ("drive_voltage", "voltage", "drive"),
    logformat.VELOCITY: ("velocity", "vel"),
}
"""Column-name stems that reveal a required quantity given in another unit."""

_MISSING = {"", "nan", "NaN", "NAN"}

MAX_ROWS = 1_000_000
"""Most data rows accepted in one log (a campaign is a few hundred; 200 000 are read in 2.4 to 5 s)."""
MIN_PEAK_VELOCITY = 1e-6
"""Smallest accepted peak velocity of a sweep [m/s]: a sweep whose every velocity is below this
(all zeros, or "tiny" values such as a velocity in km/s) holds no resonance to fit."""


@dataclass(frozen=True)
class CampaignLog:
    """Sweeps read from one or more logs, as arrays of equal length (one entry per row).

    Attributes
    ----------
    frequency : numpy.ndarray
        Drive frequency [Hz].
    drive_voltage : numpy.ndarray
        Peak voltage across the ceramics [V].
    velocity : numpy.ndarray
        Peak velocity amplitude at the measurement point [m/s].
    sweep : numpy.ndarray of int
        Sweep index 0 .. n_sweeps - 1, numbered in reading order across files.
    sources : tuple of str
        The files read.
    warnings : tuple of str
        One line per tolerated problem (dropped dropouts, ignored partial line).
    timestamp : numpy.ndarray or None
        Seconds since the start of the campaign per row (None when a log has none) [s].
    mode_factor : numpy.ndarray or None
        |phi| of the mode at each row's measurement point: measured velocity over the
        antinode's (:mod:`~workflow.damping.mode_shape`); None means 1 (at an antinode) [-].
    ringdown : RingdownLog or None
        Ring-downs read with the sweeps (``tactile fit-damping SWEEPS RINGDOWNS``).
    """

    frequency: np.ndarray
    drive_voltage: np.ndarray
    velocity: np.ndarray
    sweep: np.ndarray
    sources: Tuple[str, ...]
    warnings: Tuple[str, ...] = ()
    timestamp: Optional[np.ndarray] = None
    mode_factor: Optional[np.ndarray] = None
    ringdown: Optional["RingdownLog"] = None

    @property
    def n_sweeps(self) -> int:
        """Number of sweeps [-] (0 for ring-downs alone)."""
        return int(self.sweep.max()) + 1 if self.sweep.size else 0

    def measurement_factor(self) -> np.ndarray:
        """|phi| at each row's measurement point (1 where none was logged) [-]."""
        return np.ones_like(self.velocity) if self.mode_factor is None else self.mode_factor

    def sweep_voltages(self) -> np.ndarray:
        """Median drive voltage of each sweep [V]."""
        return np.array([np.median(self.drive_voltage[self.sweep == k]) for k in range(self.n_sweeps)])

    def subset(self, keep: np.ndarray, sweep: np.ndarray, warnings: Tuple[str, ...]) -> "CampaignLog":
        """The rows ``keep`` (boolean mask) renumbered into ``sweep``, with ``warnings``."""
        optional = {name: None if getattr(self, name) is None else getattr(self, name)[keep] for name in ("timestamp", "mode_factor")}
        return CampaignLog(self.frequency[keep], self.drive_voltage[keep], self.velocity[keep], sweep, self.sources, warnings,
                           ringdown=self.ringdown, **optional)


@dataclass(frozen=True)
class RingdownLog:
    """Ring-downs (free decays after a burst) read from one or more logs, one entry per sample.

    Attributes
    ----------
    frequency : numpy.ndarray
        Drive frequency of the burst [Hz] (at resonance).
    drive_voltage : numpy.ndarray
        Burst level, peak voltage across the ceramics [V].
    velocity : numpy.ndarray
        Envelope of the velocity at the measurement point [m/s].
    burst : numpy.ndarray of int
        Burst index 0 .. n_bursts - 1.
    decay_time : numpy.ndarray
        Time since the end of the burst [s].
    mode_factor : numpy.ndarray
        |phi| at the measurement point [-].
    temperature : numpy.ndarray
        Plate temperature [deg C]; NaN where not reported.
    sources : tuple of str
    warnings : tuple of str
        One line per tolerated problem.
    """

    frequency: np.ndarray
    drive_voltage: np.ndarray
    velocity: np.ndarray
    burst: np.ndarray
    decay_time: np.ndarray
    mode_factor: np.ndarray
    temperature: np.ndarray
    sources: Tuple[str, ...]
    warnings: Tuple[str, ...] = ()

    @property
    def n_bursts(self) -> int:
        """Number of bursts [-]."""
        return int(self.burst.max()) + 1


MIN_POINTS_PER_SWEEP = 5
"""Fewer rows than this cannot locate a sweep's resonance; such sweeps are dropped."""


def drop_short_sweeps(log: CampaignLog, min_points: int = MIN_POINTS_PER_SWEEP) -> CampaignLog:
    """The log without sweeps of fewer than ``min_points`` rows (e.g. the partial sweep of an
    interrupted campaign), renumbered, with one warning naming what was dropped.

    Raises
    ------
    InputFileError
        If no sweep is long enough.
    """
    counts = np.bincount(log.sweep, minlength=log.n_sweeps)
    short = np.nonzero(counts < min_points)[0]
    if short.size == 0:
        return log
    if short.size == log.n_sweeps:
        raise InputFileError(
            f"{', '.join(log.sources)}: no sweep has {min_points} or more rows; cannot locate a resonance"
        )
    keep = counts[log.sweep] >= min_points
    renumbered = np.cumsum(counts >= min_points)[log.sweep[keep]] - 1
    warning = (
        f"{', '.join(log.sources)}: ignored {short.size} sweep(s) with fewer than {min_points} rows "
        f"({int(counts[short].sum())} rows)"
    )
    return log.subset(keep, renumbered, log.warnings + (warning,))


MIXED_PLATES = ("refuse", "warn")
"""What to do with logs of different plates given together: refuse them, or fit them with a warning."""
SAME_PLATE_TOLERANCE = 0.02
"""Largest relative spread of the logs' resonances still taken for one plate [-]: drift, temperature and
softening move a plate's resonance by well under 1 %; the paper's two built plates are 3.4 % apart."""


def read_logs(paths: Sequence, mixed_plates: str = "refuse") -> CampaignLog:
    """Read and concatenate several logs; sweeps (and bursts) are renumbered so they never collide.

    Ring-down logs (a ``decay_time_s`` column) are gathered in :attr:`CampaignLog.ringdown`;
    with ring-down logs alone the sweeps are empty.  Logs that are not of one plate
    (:func:`plate_mismatch`) are refused, or with ``mixed_plates="warn"`` read with a warning.

    Raises
    ------
    InputFileError
        On the first malformed file, naming it; logs of different plates unless ``mixed_plates="warn"``.
    """
    if not paths:
        raise InputFileError("no log file given")
    read = [read_log(path) for path in paths]
    mismatch = plate_mismatch(paths, read)
    if mismatch and mixed_plates == "refuse":
        raise InputFileError(f"{mismatch}; logs of different plates are not fitted together (--mixed-plates warn "
                             "fits them anyway)")
    logs = [log for log in read if isinstance(log, CampaignLog)]
    decays = [log for log in read if isinstance(log, RingdownLog)]
    offsets = np.cumsum([0] + [log.n_sweeps for log in logs[:-1]])
    timestamps = [log.timestamp for log in logs]
    factors = [log.mode_factor for log in logs]
    return CampaignLog(
        frequency=np.concatenate([log.frequency for log in logs] + [np.zeros(0)]),
        drive_voltage=np.concatenate([log.drive_voltage for log in logs] + [np.zeros(0)]),
        velocity=np.concatenate([log.velocity for log in logs] + [np.zeros(0)]),
        sweep=np.concatenate([log.sweep + offset for log, offset in zip(logs, offsets)] + [np.zeros(0, dtype=int)]),
        sources=tuple(source for log in logs for source in log.sources),
        warnings=tuple(warning for log in read for warning in log.warnings) + ((mismatch,) if mismatch else ()),
        timestamp=np.concatenate(timestamps) if logs and all(t is not None for t in timestamps) else None,
        mode_factor=None if all(m is None for m in factors) else np.concatenate([log.measurement_factor() for log in logs]),
        ringdown=_concatenate_ringdowns(decays) if decays else None,
    )


def log_resonance(log) -> float:
    """The resonance a log measured [Hz]: the median of its sweeps' peak frequencies, or of its bursts' frequency."""
    if isinstance(log, RingdownLog):
        return float(np.median(log.frequency))
    return float(np.median([log.frequency[log.sweep == k][np.argmax(log.velocity[log.sweep == k])]
                            for k in range(log.n_sweeps)]))


def plate_mismatch(paths: Sequence, logs: Sequence) -> str | None:
    """Why the logs (read from ``paths``) are not of one plate, or None: two name different built plates in
    their metadata (:class:`~workflow.models.builtplate.BuiltPlate`), or their resonances (:func:`log_resonance`)
    spread by more than :data:`SAME_PLATE_TOLERANCE`."""
    named = [(path, logformat.read_metadata(path)) for path in paths]
    plates = [(path, BuiltPlate.from_metadata(metadata, str(path))) for path, metadata in named
              if all(key in metadata for key in logformat.BUILT_PLATE_KEYS)]
    for path, plate in plates[1:]:
        if plate != plates[0][1]:
            return (f"{plates[0][0]} and {path} name different plates in their metadata ({_described(plates[0][1])}; "
                    f"{_described(plate)})")
    resonances = [log_resonance(log) for log in logs]
    low, high = int(np.argmin(resonances)), int(np.argmax(resonances))
    if resonances[high] > (1 + SAME_PLATE_TOLERANCE) * resonances[low]:
        return (f"{paths[low]} (resonance {resonances[low]:.0f} Hz) and {paths[high]} ({resonances[high]:.0f} Hz) are "
                f"{(resonances[high] / resonances[low] - 1) * 100:.1f} % apart, more than the "
                f"{SAME_PLATE_TOLERANCE * 100:g} % of one plate")
    return None


def _described(plate: BuiltPlate) -> str:
    return ", ".join(f"{key} {value}" for key, value in plate.metadata().items())


def _concatenate_ringdowns(logs: Sequence[RingdownLog]) -> RingdownLog:
    offsets = np.cumsum([0] + [log.n_bursts for log in logs[:-1]])
    columns = ("frequency", "drive_voltage", "velocity", "decay_time", "mode_factor", "temperature")
    return RingdownLog(
        **{name: np.concatenate([getattr(log, name) for log in logs]) for name in columns},
        burst=np.concatenate([log.burst + offset for log, offset in zip(logs, offsets)]),
        sources=tuple(source for log in logs for source in log.sources),
        warnings=tuple(warning for log in logs for warning in log.warnings),
    )


@dataclass(frozen=True)
class LogTable:
    """The numeric columns of one log, as read by :func:`read_table`.

    Attributes
    ----------
    arrays : dict
        Column name -> values (one per kept row) [the column's unit].
    line_numbers : numpy.ndarray
        Line of each kept row in the file [-].
    metadata : dict
        key -> (value text, line number) of the ``# key: value`` lines before the header.
    warnings : list of str
        Tolerated problems (dropped dropouts, an ignored partial last line).
    """

    arrays: dict
    line_numbers: np.ndarray
    metadata: dict
    warnings: list


def read_table(path, required: tuple = logformat.REQUIRED_COLUMNS, phase: bool = False) -> LogTable:
    """The known columns of a log, read line by line (:class:`~workflow.logformat.LogReader`; memory: the rows'
    numbers, about 50 bytes a row).

    Rows without a velocity reading (empty or ``nan``: vibrometer dropouts) are dropped with a warning.
    Every value is checked against its plausible range (:data:`~workflow.models.limits.LIMITS`).

    Parameters
    ----------
    path : path-like
    required : tuple of str
        Columns the log must have (default: those of every log).
    phase : bool
        Read the ``phase_deg`` column too (a scan's; a sweep's phase is not used).

    Raises
    ------
    InputFileError
        Unreadable, oversized, empty, binary or non-UTF-8 file, or not a regular file; no header or no
        data rows; more than :data:`MAX_ROWS` data rows or a line over :data:`~workflow.logformat.MAX_LINE_LENGTH`;
        a required column missing, duplicated or given in an unknown unit; a row with the wrong number
        of fields; a non-numeric or implausible value.
    """
    path = Path(path)
    warnings = []
    with logformat.LogReader(path) as log:
        header_number, header, _ = next(log, (None, None, True))
        if header is None:
            raise InputFileError(f"{path}: empty file" if log.empty else
                                 f"{path}: no header row (expected columns {', '.join(required)})")
        separator = next((mark for mark in ";\t" if len(header) == 1 and mark in header[0]), None)
        if separator:
            raise InputFileError(
                f"{path}, line {header_number}: fields separated by {separator!r}; a log separates them by ','"
            )
        if logformat.RENDER_TIME in header:
            raise InputFileError(f"{path}: a render log ('tactile measure render': a texture played and its envelope), "
                                 "not sweeps or ring-downs; it holds no damping campaign")
        if logformat.HOLD_TIME in header:
            raise InputFileError(f"{path}: a hold log ('tactile measure hold': the plate held at resonance), not sweeps "
                                 "or ring-downs; it holds no damping campaign")
        columns = _column_indices(path, header_number, header, required, phase)
        table = {name: array("d") for name in columns}
        line_numbers, rows, dropouts = array("q"), 0, 0
        for number, cells, complete in log:
            if rows == MAX_ROWS:
                raise InputFileError(f"{path}, line {number}: more than the {MAX_ROWS} data rows accepted in one log")
            try:
                values = None if cells is None else {name: _number(path, number, name, cells[index])
                                                     for name, index in columns.items()}
            except InputFileError:
                if complete:
                    raise
                values = None
            if values is None:  # an unterminated last line that is no row
                warnings.append(f"{path}, line {number}: ignored an incomplete last line (no newline; interrupted writer?)")
                break
            rows += 1
            if math.isnan(values[logformat.VELOCITY]):
                dropouts += 1
                continue
            line_numbers.append(number)
            for name, value in values.items():
                table[name].append(value)
    if not rows:
        raise InputFileError(f"{path}: header only, no data rows")
    if dropouts:
        warnings.append(f"{path}: dropped {dropouts} row(s) without a velocity reading (vibrometer dropouts)")
    if not table[logformat.VELOCITY]:
        raise InputFileError(f"{path}: no data row has a velocity reading")
    arrays = {name: np.frombuffer(values, dtype=float) for name, values in table.items()}
    line_numbers = np.frombuffer(line_numbers, dtype=np.int64)
    _check_physical(path, arrays, line_numbers)
    return LogTable(arrays, line_numbers, log.metadata, warnings)


def read_log(path):
    """Read one interferometer log (:func:`read_table`) as sweeps or ring-downs.

    Without a ``sweep`` column, a new sweep starts wherever the drive voltage changes
    between consecutive rows.  A log with a ``decay_time_s`` column is a ring-down log and
    reads as a :class:`RingdownLog` (``sweep`` is the burst id; a burst also ends where the decay
    time falls back: a decay recorded again); any other as a :class:`CampaignLog`.  The measurement
    point (``x_mm``, ``y_mm`` columns or metadata) needs the plate's ``lambda_mm`` metadata to be mapped
    onto the beam mode.

    A ring-down sample that repeats the one before it (same burst, decay time and velocity: a row
    pasted twice) is dropped with a warning.

    Raises
    ------
    InputFileError
        Those of :func:`read_table`; a sweep (or burst) whose velocities all lie below
        :data:`MIN_PEAK_VELOCITY`; a measurement point off the plate or near a node; two samples of a
        burst at one decay time with different velocities.
    """
    path = Path(path)
    table = read_table(path)
    arrays, warnings, line_numbers = table.arrays, table.warnings, table.line_numbers
    sweep = _sweep_index(path, arrays)
    if logformat.DECAY_TIME in arrays:
        keep = _unrepeated_samples(path, arrays, sweep, line_numbers, warnings)
        arrays, sweep, line_numbers = {name: values[keep] for name, values in arrays.items()}, sweep[keep], line_numbers[keep]
    factor = _mode_factor(path, arrays, table.metadata, warnings)
    _check_peaks(path, arrays[logformat.VELOCITY], sweep, line_numbers)
    if logformat.DECAY_TIME in arrays:
        return RingdownLog(
            frequency=arrays[logformat.FREQUENCY],
            drive_voltage=arrays[logformat.DRIVE_VOLTAGE],
            velocity=arrays[logformat.VELOCITY],
            burst=sweep,
            decay_time=arrays[logformat.DECAY_TIME],
            mode_factor=np.ones_like(arrays[logformat.VELOCITY]) if factor is None else factor,
            temperature=arrays.get(logformat.TEMPERATURE, np.full_like(arrays[logformat.VELOCITY], np.nan)),
            sources=(str(path),),
            warnings=tuple(warnings),
        )
    return CampaignLog(
        frequency=arrays[logformat.FREQUENCY],
        drive_voltage=arrays[logformat.DRIVE_VOLTAGE],
        velocity=arrays[logformat.VELOCITY],
        sweep=sweep,
        sources=(str(path),),
        warnings=tuple(warnings),
        timestamp=arrays.get(logformat.TIMESTAMP),
        mode_factor=factor,
    )


def _unrepeated_samples(path: Path, arrays: dict, burst: np.ndarray, line_numbers: np.ndarray, warnings: list) -> np.ndarray:
    """Mask of the ring-down rows to keep: all but exact repeats of the row before (a warning counts them).

    Raises
    ------
    InputFileError
        A sample at the decay time of the one before it in its burst with another velocity (a decay is
        sampled at increasing times).
    """
    time, velocity = arrays[logformat.DECAY_TIME], arrays[logformat.VELOCITY]
    repeat = np.r_[False, (burst[1:] == burst[:-1]) & (time[1:] == time[:-1])]
    conflict = repeat & np.r_[False, velocity[1:] != velocity[:-1]]
    if conflict.any():
        index = int(np.argmax(conflict))
        raise InputFileError(f"{path}, line {line_numbers[index]}: decay time {time[index]:g} s again, with another "
                             f"velocity than line {line_numbers[index - 1]}; a decay's samples come at increasing times")
    if repeat.any():
        warnings.append(f"{path}: dropped {int(repeat.sum())} ring-down row(s) repeating the row before them "
                        f"(first: line {line_numbers[int(np.argmax(repeat))]})")
    return ~repeat


def _mode_factor(path: Path, arrays: dict, metadata: dict, warnings: list):
    """|phi| at each row's measurement point (columns, else metadata), or None when the log names no point
    (or no wavelength to map it with: a warning is appended to ``warnings``); a point off the plate (its length
    from the wavelength, its width from ``b_mm`` when named) is refused."""
    n = len(arrays[logformat.VELOCITY])
    position = {}
    for name in logformat.POSITION_COLUMNS:
        if name in arrays:
            position[name] = arrays[name]
        elif name in metadata:
            position[name] = np.full(n, logformat.metadata_number(metadata, name, path))
    if not position:
        return None
    if logformat.LAMBDA_MM not in metadata:
        warnings.append(f"{path}: a measurement point ({', '.join(position)}) without the plate's "
                        f"'# {logformat.LAMBDA_MM}: ...' metadata cannot be mapped onto the mode; read as an antinode")
        return None
    wavelength = logformat.metadata_number(metadata, logformat.LAMBDA_MM, path)
    reason = problem(logformat.LAMBDA_MM, wavelength)
    if reason:
        raise InputFileError(f"{path}, line {metadata[logformat.LAMBDA_MM][1]}: {reason}")
    half = {logformat.X_POSITION: (2 * materials.N_CERAMICS + 1) * wavelength / 8}
    if logformat.B_MM in metadata:
        half[logformat.Y_POSITION] = logformat.metadata_number(metadata, logformat.B_MM, path) / 2
    for name, values in position.items():
        if name in half and np.any(np.abs(values) > half[name] * (1 + 1e-9)):
            raise InputFileError(f"{path}: measurement point {name} = {values[np.argmax(np.abs(values))]:g} is off the "
                                 f"plate (within +-{half[name]:g} mm of its centre)")
    mode = BeamMode(wavelength * MM)
    zeros = np.zeros(n)
    try:
        return measurement_factor(mode, position.get(logformat.X_POSITION, zeros) * MM,
                                  position.get(logformat.Y_POSITION, zeros) * MM)
    except ValueError as error:
        raise InputFileError(f"{path}: {error}") from None


def _column_indices(path: Path, line: int, header, required: tuple, phase: bool) -> dict:
    """Required and known optional column name -> index in the header (``phase_deg`` only with ``phase``)."""
    indices = {}
    for name in logformat.READ_COLUMNS:
        positions = [i for i, column in enumerate(header) if column == name]
        if len(positions) > 1:
            raise InputFileError(f"{path}, line {line}: column '{name}' appears {len(positions)} times (ambiguous)")
        if positions:
            indices[name] = positions[0]
    for name in required:
        if name in indices:
            continue
        lookalikes = [c for c in header if c.lower().replace(" ", "_").startswith(_QUANTITY_STEMS.get(name, (name,)))]
        if lookalikes:
            raise InputFileError(
                f"{path}, line {line}: column {lookalikes[0]!r} has an unknown unit or name; expected '{name}'"
            )
        shown = ", ".join(header)
        raise InputFileError(
            f"{path}, line {line}: missing required column '{name}' "
            f"(header: {(shown if shown.isprintable() else repr(shown)) or 'empty'})"
        )
    return {name: index for name, index in indices.items() if phase or name != logformat.PHASE}


def _number(path: Path, line: int, column: str, cell: str) -> float:
    """A cell as a float; empty and nan are NaN (allowed only for the velocity)."""
    text = cell.strip()
    if text in _MISSING:
        if column in (logformat.VELOCITY, logformat.TEMPERATURE):
            return math.nan
        raise InputFileError(f"{path}, line {line}: missing value in column '{column}'")
    try:
        value = float(text)
    except ValueError:
        raise InputFileError(f"{path}, line {line}: non-numeric value {text!r} in column '{column}'") from None
    if not math.isfinite(value):
        raise InputFileError(f"{path}, line {line}: non-finite value {text!r} in column '{column}'")
    return value


PLAUSIBLE_COLUMNS = (logformat.FREQUENCY, logformat.DRIVE_VOLTAGE, logformat.VELOCITY, logformat.DECAY_TIME,
                     logformat.TEMPERATURE)
"""Columns checked against :data:`~workflow.models.limits.LIMITS` (a missing temperature is allowed)."""


def _check_physical(path: Path, arrays: dict, line_numbers: np.ndarray) -> None:
    """Refuse the first value of a :data:`PLAUSIBLE_COLUMNS` column outside its plausible range, naming its line."""
    for column in (name for name in PLAUSIBLE_COLUMNS if name in arrays):
        low, high = LIMITS[column]
        values = arrays[column]
        bad = (values < low) | (values > high)
        if bad.any():
            index = int(np.argmax(bad))
            raise InputFileError(f"{path}, line {line_numbers[index]}: {problem(column, values[index])}")


def _check_peaks(path: Path, velocity: np.ndarray, sweep: np.ndarray, line_numbers: np.ndarray) -> None:
    """Refuse a sweep (or burst) whose peak velocity is below :data:`MIN_PEAK_VELOCITY`, naming its first line."""
    peaks = np.zeros(int(sweep.max()) + 1)
    np.maximum.at(peaks, sweep, velocity)
    low = np.nonzero(peaks < MIN_PEAK_VELOCITY)[0]
    if low.size:
        line = line_numbers[np.argmax(sweep == low[0])]
        raise InputFileError(
            f"{path}, line {line}: the sweep (or burst) starting here peaks at {peaks[low[0]]:g} m/s, below the "
            f"{MIN_PEAK_VELOCITY:g} m/s accepted (all-zero velocities, or a velocity not in m/s?)"
        )


def _sweep_index(path: Path, arrays: dict) -> np.ndarray:
    """0-based sweep (or burst) index per row, from the ``sweep`` column or from voltage changes; a burst also
    ends where its decay time falls back (the burst recorded again after a record cut short)."""
    if logformat.SWEEP in arrays:
        ids = arrays[logformat.SWEEP]
        if not np.all(ids == np.round(ids)):
            raise InputFileError(f"{path}: column '{logformat.SWEEP}' must hold integer sweep ids")
        starts = np.r_[True, ids[1:] != ids[:-1]]
        if logformat.DECAY_TIME in arrays:
            starts |= np.r_[False, np.diff(arrays[logformat.DECAY_TIME]) < 0]
    else:
        voltage = arrays[logformat.DRIVE_VOLTAGE]
        starts = np.r_[True, ~np.isclose(voltage[1:], voltage[:-1], rtol=1e-6, atol=1e-9)]
    return np.cumsum(starts) - 1
