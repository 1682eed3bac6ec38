"""Interferometer log format, version 1 (docs/log-format.md): the names, once, and the metadata reader.

UTF-8 CSV.  Optional leading metadata lines ``# key: value`` (the first may be a title
line), then one header row and the data rows.  Readers live in
:mod:`workflow.damping.logs`; the writer in :mod:`instruments.procedures.logwriter`.
"""

import io
import math
from pathlib import Path

from workflow.errors import InputFileError
from workflow.inputfiles import MAX_LOG_BYTES, open_input

FORMAT_VERSION = 1

FREQUENCY = "frequency_hz"
"""Drive frequency [Hz]."""
DRIVE_VOLTAGE = "drive_voltage_v"
"""Peak voltage across the ceramics [V]."""
VELOCITY = "velocity_m_s"
"""Peak velocity amplitude at the measurement point [m/s]."""
SWEEP = "sweep"
"""Integer sweep id (optional)."""
TIMESTAMP = "timestamp_s"
"""Seconds since the start of the campaign (optional)."""
PHASE = "phase_deg"
"""Phase of the velocity relative to the drive [deg] (optional)."""

REQUIRED_COLUMNS = (FREQUENCY, DRIVE_VOLTAGE, VELOCITY)
OPTIONAL_COLUMNS = (SWEEP, TIMESTAMP, PHASE)
COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
"""The columns our writer emits, in this order."""

METADATA_PREFIX = "# "
"""Metadata lines read ``# key: value``."""

X_POSITION = "x_mm"
"""Measurement point along the plate's length, from its centre [mm] (column of a scan; metadata when constant)."""
Y_POSITION = "y_mm"
"""Measurement point across the plate, from its centre [mm]."""
SCAN_COLUMNS = COLUMNS + (X_POSITION, Y_POSITION)
"""The columns of a deflection scan, in this order."""
DECAY_TIME = "decay_time_s"
"""Ring-down logs: time since the end of the burst [s]; its presence makes a log a ring-down log."""
TEMPERATURE = "temperature_c"
"""Plate temperature where the bench reports it [deg C] (optional)."""
POSITION_COLUMNS = (X_POSITION, Y_POSITION)
RINGDOWN_COLUMNS = (SWEEP, TIMESTAMP, DECAY_TIME, FREQUENCY, DRIVE_VOLTAGE, VELOCITY, TEMPERATURE)
"""The columns of a ring-down log (``sweep`` is the burst id), in the order our writer emits them."""
READ_COLUMNS = COLUMNS + POSITION_COLUMNS + (DECAY_TIME, TEMPERATURE)
"""Every column the reader knows."""
RENDER_TIME = "render_time_s"
"""Render logs: time since the start of the looped drive's period [s]; its presence makes a log a render log."""
WANTED_VELOCITY = "wanted_velocity_m_s"
"""Render logs: the antinode velocity amplitude the texture asks for at that time [m/s]."""
PREDICTED_VELOCITY = "predicted_velocity_m_s"
"""Render logs: the antinode velocity amplitude the envelope model predicts for the drive [m/s]."""
RENDER_COLUMNS = (SWEEP, TIMESTAMP, RENDER_TIME, FREQUENCY, DRIVE_VOLTAGE, VELOCITY, WANTED_VELOCITY, PREDICTED_VELOCITY)
"""The columns of a render log (``sweep`` is the playback id; ``drive_voltage_v`` the drive envelope then)."""

HOLD_TIME = "hold_time_s"
"""Hold logs: the planned time of the sample since the hold's start [s]; its presence makes a log a hold log."""
HOLD_COLUMNS = (SWEEP, TIMESTAMP, HOLD_TIME, FREQUENCY, DRIVE_VOLTAGE, VELOCITY, PHASE, TEMPERATURE)
"""The columns of a hold log (``tactile measure hold``: resonance and amplitude held in closed loop), in this order."""

LAMBDA_MM = "lambda_mm"
"""Metadata: the built plate's nominal wavelength [mm]."""
HI_MM = "h_i_mm"
"""Metadata: nominal resonator thickness [mm]."""
HP_MM = "h_p_mm"
"""Metadata: nominal ceramic thickness [mm]."""
B_MM = "b_mm"
"""Metadata: nominal width [mm]."""
CERAMIC = "ceramic"
"""Metadata: ceramic material record name (optional)."""
RESONATOR = "resonator"
"""Metadata: resonator material record name (optional)."""
GLUE_UM = "glue_um"
"""Metadata: nominal bond thickness [um] (optional)."""
BUILT_PLATE_KEYS = (LAMBDA_MM, HI_MM, HP_MM, B_MM)
"""The metadata keys every built-plate log has."""


MAX_HEADER_LINES = 10_000
"""Most metadata lines read before the header row [-]."""
MAX_LINE_LENGTH = 10_000
"""Longest accepted line [characters]; a data row is under 200."""


def read_metadata(path: Path) -> dict:
    """key -> (value, line number) of the ``# key: value`` lines before a log's header row.

    Raises
    ------
    InputFileError
        If the file cannot be read (or is no regular file, or is too large: :func:`~workflow.inputfiles.open_input`),
        is not UTF-8, has a line over :data:`MAX_LINE_LENGTH` or more than :data:`MAX_HEADER_LINES` lines before its header.
    """
    metadata = {}
    with io.TextIOWrapper(open_input(path, str(path), MAX_LOG_BYTES), encoding="utf-8-sig", newline="") as stream:
        try:
            for number in range(1, MAX_HEADER_LINES + 2):
                line = stream.readline(MAX_LINE_LENGTH + 3)
                if not line:
                    break
                if number > MAX_HEADER_LINES:
                    raise InputFileError(f"{path}, line {number}: no header row within {MAX_HEADER_LINES} lines")
                if len(line.rstrip("\r\n")) > MAX_LINE_LENGTH:
                    raise InputFileError(f"{path}, line {number}: longer than the {MAX_LINE_LENGTH} characters accepted per line")
                if line.strip() and not line.lstrip().startswith("#"):
                    break
                key, separator, value = line.lstrip()[1:].partition(":")
                if separator and key.strip():
                    metadata.setdefault(key.strip(), (value.strip(), number))
        except OSError as error:
            raise InputFileError(f"{path}: cannot read ({error.strerror or error})") from None
        except UnicodeDecodeError as error:
            raise InputFileError(f"{path}: not UTF-8 (byte {error.start} of a line)") from None
    return metadata


def metadata_number(metadata: dict, key: str, source) -> float:
    """The finite number of a metadata line read by :func:`read_metadata`, or an error naming ``source``'s line."""
    text, line = metadata[key]
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise InputFileError(f"{source}, line {line}: metadata {key} = {text!r} is not a finite number")
    return value
