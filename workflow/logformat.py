"""Interferometer log format, version 1 (docs/log-format.md): the names, once, its one reader and its text.

UTF-8 CSV.  Optional leading metadata lines ``# key: value`` (the first may be a title
line), then one header row and the data rows.  :class:`LogReader` is the one reader of the format
(:func:`read_metadata`, the fit's :func:`~workflow.damping.logs.read_table` and the resume's
:func:`~instruments.procedures.logwriter.read_log` are views of it); :func:`head_text` and :func:`rows_text`
are its text, written to a file by the one writer, :class:`~instruments.procedures.logwriter.LogWriter`.
"""

import codecs
import csv
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


RESUME_HINTS = {"plan_alternate": "a campaign log resumes with the --alternate setting it was made with "
                                  "('plan_alternate: True' in its header: with it; none: without)"}
"""What to do when a resumed log's ``plan_*`` key differs from the run's, where there is something to do."""
MAX_HEADER_LINES = 10_000
"""Most lines read before the header row [-]."""
MAX_LINE_LENGTH = 10_000
"""Longest accepted line [characters]; a data row is under 200."""


def metadata_text(value) -> str:
    """A metadata value as written: a list as comma-separated items (floats as ``%g``), white space folded."""
    if isinstance(value, (list, tuple)):
        value = ",".join(f"{item:g}" if isinstance(item, float) else str(item) for item in value)
    return " ".join(str(value).split())


def metadata_line(key: str, value) -> str:
    """The ``# key: value`` line of a metadata entry (:func:`metadata_text`; no line end)."""
    return f"{METADATA_PREFIX}{key}: {metadata_text(value)}"


def metadata_entry(line: str) -> tuple[str, str] | None:
    """(key, value) of a ``# key: value`` line (leading blanks allowed, both stripped); None for any other line."""
    text = line.lstrip()
    if not text.startswith("#"):
        return None
    key, separator, value = text[1:].partition(":")
    return (key.strip(), value.strip()) if separator and key.strip() else None


def head_text(title: str, metadata: dict, columns) -> str:
    """The lines a log starts with: ``# title``, a ``# key: value`` line per metadata item, the header row."""
    lines = [METADATA_PREFIX + title, *(metadata_line(key, value) for key, value in metadata.items()), ",".join(columns)]
    return "\n".join(lines) + "\n"


def rows_text(rows) -> str:
    """Rows of field texts (names and numbers: never quoted) as comma-separated lines, each ending with ``\\n``."""
    return "".join(",".join(row) + "\n" for row in rows)


class LogReader:
    """The one reader of the format, a context manager: one pass over a log, one line in memory at a time.

    It iterates over ``(line number, fields, complete)`` of the header row (its names stripped), then of each
    data row; ``# key: value`` lines before the header go to :attr:`metadata` (key -> (value, line number), a
    key's first), other ``#`` lines and blank lines are skipped.  Only the last line may lack its newline
    (``complete`` False); cut short into no row (not UTF-8, another number of fields than the header), it comes
    with ``fields`` None.  :attr:`empty`: no line read holds text; :attr:`length`: bytes up to the end of the
    last complete line read [bytes]; :attr:`tail`: the unterminated last line.  ``max_line_length``: longest
    line accepted [characters] (None: any, within the file's :data:`MAX_LOG_BYTES`).

    Raises
    ------
    InputFileError
        Naming the file and line: those of :func:`~workflow.inputfiles.open_input`; UTF-16, binary (NUL bytes)
        or not UTF-8; a line over ``max_line_length``; no header row within :data:`MAX_HEADER_LINES` lines; a
        carriage return inside a line; any other line that is no CSV row of the header's width.
    """

    def __init__(self, path, max_line_length: int | None = MAX_LINE_LENGTH):
        self.path, self.max_line_length = Path(path), max_line_length
        self.metadata, self.empty, self.length, self.tail = {}, True, 0, b""
        self._stream = open_input(self.path, str(self.path), MAX_LOG_BYTES)
        self._lines = self._read()

    def __enter__(self) -> "LogReader":
        return self

    def __exit__(self, *exc) -> None:
        self._stream.close()

    def __iter__(self):
        return self._lines

    def __next__(self) -> tuple:
        return next(self._lines)

    def _read(self):
        path, stream, limit = self.path, self._stream, self.max_line_length
        line_bytes = -1 if limit is None else 4 * limit + 8  # a line of ``limit`` UTF-8 characters and its end
        head = stream.peek(4 * MAX_LINE_LENGTH + 8)  # the first block: a binary file is named so even if not UTF-8
        if head.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
            raise InputFileError(f"{path}: UTF-16 text, not UTF-8 (save the log as UTF-8)")
        lines_end = head.rfind(b"\n") + 1  # NULs in an unterminated last line are judged below, as its other bytes
        if b"\x00" in head[:lines_end]:
            raise InputFileError(f"{path}: binary data (NUL bytes), not a CSV log")
        binary_tail = b"\x00" in head[lines_end:]
        number, width = 0, None  # width: the header's number of fields, once read
        while True:
            try:
                raw = stream.readline(line_bytes)
            except OSError as error:
                raise InputFileError(f"{path}: cannot read ({error.strerror or error})") from None
            if not raw:
                return
            number += 1
            if width is None and number > MAX_HEADER_LINES:
                raise InputFileError(f"{path}, line {number}: no header row within {MAX_HEADER_LINES} lines")
            complete = raw.endswith(b"\n")
            if not complete and len(raw) == line_bytes:
                raise InputFileError(f"{path}, line {number}: longer than the {limit} characters accepted per line")
            self.tail = b"" if complete else raw
            if b"\x00" in raw:  # in the unterminated last line: a write cut short (a file padded after a power loss)
                if complete:
                    raise InputFileError(f"{path}, line {number}: binary data (NUL bytes), not a CSV log")
                yield number, None, False
                return
            try:
                line = raw.decode("utf-8-sig" if number == 1 else "utf-8")
            except UnicodeDecodeError as error:
                if complete and binary_tail:
                    raise InputFileError(f"{path}: binary data (NUL bytes), not a CSV log") from None
                if complete:
                    raise InputFileError(f"{path}, line {number}: not UTF-8 (byte 0x{raw[error.start]:02x} at offset "
                                         f"{self.length + error.start})") from None
                yield number, None, False  # cut inside a character
                return
            self.length += len(raw) if complete else 0
            line = line[:-1] if complete else line
            if limit is not None and len(line) > limit:
                raise InputFileError(f"{path}, line {number}: {len(line)} characters, longer than the {limit} accepted "
                                     "per line")
            self.empty = self.empty and not line.strip()
            line = line.rstrip("\r")
            comment = not line.strip() or line.lstrip().startswith("#")
            if comment and width is not None:
                continue
            try:
                if "\r" in line:
                    raise InputFileError(f"{path}, line {number}: a carriage return inside the line (CR line ends? "
                                         "expected LF or CRLF)")
                if comment:
                    entry = metadata_entry(line)
                    if entry:
                        self.metadata.setdefault(entry[0], (entry[1], number))
                    continue
                try:
                    fields = next(csv.reader([line]))
                except csv.Error as error:
                    raise InputFileError(f"{path}, line {number}: not a CSV row ({error})") from None
                if width is not None and len(fields) != width:
                    raise InputFileError(f"{path}, line {number}: expected {width} fields, got {len(fields)}")
            except InputFileError:
                if complete or width is None:
                    raise
                fields = None
            if width is None:
                width, fields = len(fields), [name.strip() for name in fields]
            yield number, fields, complete


def column_names(path) -> list:
    """The names in a log's header row ([] without one), reading no further (:class:`LogReader`; an empty file is
    refused)."""
    with LogReader(path) as log:
        names = next(log, (0, [], True))[1]
    if log.empty:
        raise InputFileError(f"{log.path}: empty file")
    return names


def read_metadata(path) -> dict:
    """key -> (value, line number) of the ``# key: value`` lines before a log's header row (:class:`LogReader`)."""
    with LogReader(path) as log:
        next(log, None)
    return log.metadata


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
