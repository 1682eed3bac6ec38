"""Writer of interferometer logs (docs/log-format.md, format version 1) that survives crashes.

Every row is written, flushed and fsync'd as soon as it is measured.  Resuming a log
reads the rows already there; the procedures skip the planned points they cover (keyed
by sweep id and the exact text of frequency and voltage).  A crash can leave only an
unterminated final line (a row being written): resuming truncates that line alone, so
every complete row is kept and the file stays a valid log.  A log is only resumed by
the same procedure with the same plan (the ``plan_*`` metadata); anything else is an
error, not a guess.
"""

import csv
import io
import os
from pathlib import Path

from workflow import logformat
from workflow.errors import InputFileError

TITLE = "tactile interferometer log"
_FORMATS = {
    logformat.FREQUENCY: "{:.12g}",
    logformat.DRIVE_VOLTAGE: "{:.9g}",
    logformat.VELOCITY: "{:.7g}",
    logformat.SWEEP: "{:d}",
    logformat.TIMESTAMP: "{:.3f}",
    logformat.PHASE: "{:.3f}",
}


def format_value(column: str, value) -> str:
    """The text of ``value`` in ``column``, as written to the log."""
    return _FORMATS[column].format(value)


def point_key(sweep: int, frequency: float, voltage: float) -> tuple[str, str, str]:
    """Identity of a planned point: (sweep, frequency, voltage) as the log writes them."""
    return (
        format_value(logformat.SWEEP, sweep),
        format_value(logformat.FREQUENCY, frequency),
        format_value(logformat.DRIVE_VOLTAGE, voltage),
    )


def _metadata_text(value) -> str:
    if isinstance(value, (list, tuple)):
        value = ",".join(f"{item:g}" if isinstance(item, float) else str(item) for item in value)
    return " ".join(str(value).split())


def read_log(path: Path) -> tuple[dict, list[dict], int]:
    """Metadata, complete rows (column -> text) and the byte length of the complete lines of a log we wrote.

    The length is 0 when there is no header row yet (a crash while the log was being created).

    Raises
    ------
    InputFileError
        If the header row is not ours or a complete row is malformed (file and line named).
    """
    data = path.read_bytes()
    complete = data[: data.rfind(b"\n") + 1]
    metadata, rows, header = {}, [], None
    for number, line in enumerate(complete.decode("utf-8").splitlines(), start=1):
        if header is None and line.startswith("#"):
            key, separator, value = line[1:].partition(":")
            if separator:
                metadata[key.strip()] = value.strip()
            continue
        fields = next(csv.reader([line]))
        if header is None:
            if tuple(fields) != logformat.COLUMNS:
                raise InputFileError(f"{path}:{number}: header {fields} is not {list(logformat.COLUMNS)}; not a log this writer can resume")
            header = fields
        elif len(fields) != len(header):
            raise InputFileError(f"{path}:{number}: expected {len(header)} fields, got {len(fields)}; not resuming a damaged log")
        else:
            rows.append(dict(zip(header, fields)))
    return metadata, rows, len(complete) if header is not None else 0


class LogWriter:
    """Append rows to a log, creating it with its metadata or resuming it.

    Parameters
    ----------
    path : path-like
    metadata : dict
        ``key -> value`` for the ``# key: value`` lines; ``procedure`` and the ``plan_*`` keys
        must match when resuming.
    restart : bool
        Discard an existing log instead of resuming it.
    fsync : bool
        fsync after every row (durable against power loss, not only against crashes).
    """

    def __init__(self, path, metadata: dict, restart: bool = False, fsync: bool = True):
        self.path = Path(path)
        self.fsync = fsync
        self.metadata = {"format_version": logformat.FORMAT_VERSION, **metadata}
        self.rows: list[dict] = []
        self.truncated_bytes = 0
        if not (self.path.exists() and not restart and self._resume()):
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w", encoding="utf-8", newline="")
            lines = [f"# {TITLE}"] + [f"# {key}: {_metadata_text(value)}" for key, value in self.metadata.items()]
            self._write("\n".join(lines) + "\n" + ",".join(logformat.COLUMNS) + "\n")
        self.keys = {(row[logformat.SWEEP], row[logformat.FREQUENCY], row[logformat.DRIVE_VOLTAGE]) for row in self.rows}

    def _resume(self) -> bool:
        old_metadata, self.rows, complete_length = read_log(self.path)
        if not complete_length:
            return False
        wanted = {key: _metadata_text(value) for key, value in self.metadata.items() if key == "procedure" or key.startswith("plan_")}
        for key, value in wanted.items():
            if old_metadata.get(key) != value:
                raise InputFileError(
                    f"{self.path}: cannot resume: it was written with {key} = {old_metadata.get(key)!r}, "
                    f"this run has {value!r}; use another output file or restart it"
                )
        size = self.path.stat().st_size
        self.truncated_bytes = size - complete_length
        with open(self.path, "r+b") as file:
            file.truncate(complete_length)
        self._file = open(self.path, "a", encoding="utf-8", newline="")
        return True

    def _write(self, text: str) -> None:
        self._file.write(text)
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())

    def append(self, row: dict) -> None:
        """Write one row (column -> value; missing optional columns stay empty), durably."""
        text = {column: format_value(column, row[column]) if column in row else "" for column in logformat.COLUMNS}
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerow(text[column] for column in logformat.COLUMNS)
        self._write(buffer.getvalue())
        self.rows.append(text)
        self.keys.add((text[logformat.SWEEP], text[logformat.FREQUENCY], text[logformat.DRIVE_VOLTAGE]))

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
