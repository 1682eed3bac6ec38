"""Writer of interferometer logs (docs/log-format.md, format version 1) that survives crashes.

Every row is written, flushed and fsync'd as soon as it is measured.  Resuming a log
reads the rows already there; the procedures skip the planned points they cover (keyed
by sweep id and the exact text of frequency and voltage).  A crash can leave only an
unterminated final line (a row being written): resuming truncates that line alone, so
every complete row is kept and the file stays a valid log.  A log is only resumed by
the same procedure with the same plan (the ``plan_*`` metadata); anything else is an
error, not a guess.

A log has one writer: :func:`exclusive` holds an ``fcntl.flock`` on ``<log>.lock`` (which
holds the writer's pid, for the message a second writer gets) for as long as the log is
written.  The kernel releases the lock when its process dies, so a lock file left by a
killed process is taken over.  A file this module did not write (no title line) is never
appended to nor overwritten, and only regular files are logs.
"""

import contextlib
import csv
import fcntl
import io
import os
import stat
import threading
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
    logformat.DECAY_TIME: "{:.9g}",
    logformat.TEMPERATURE: "{:.3f}",
    logformat.X_POSITION: "{:.4f}",
    logformat.Y_POSITION: "{:.4f}",
    logformat.RENDER_TIME: "{:.9g}",
    logformat.WANTED_VELOCITY: "{:.7g}",
    logformat.PREDICTED_VELOCITY: "{:.7g}",
}
KEY_COLUMNS = (logformat.SWEEP, logformat.FREQUENCY, logformat.DRIVE_VOLTAGE, logformat.X_POSITION, logformat.Y_POSITION)
"""The columns that identify a planned point (those a log has)."""


def format_value(column: str, value) -> str:
    """The text of ``value`` in ``column``, as written to the log."""
    return _FORMATS[column].format(value)


def point_key(sweep: int, frequency: float, voltage: float, position: tuple | None = None) -> tuple:
    """Identity of a planned point: (sweep, frequency, voltage) as the log writes them, and (x_mm, y_mm) of a scan."""
    values = {logformat.SWEEP: sweep, logformat.FREQUENCY: frequency, logformat.DRIVE_VOLTAGE: voltage}
    if position is not None:
        values.update(zip((logformat.X_POSITION, logformat.Y_POSITION), position))
    return tuple(format_value(column, value) for column, value in values.items())


def row_key(row: dict) -> tuple:
    """The :func:`point_key` of a logged row (column -> text)."""
    return tuple(row[column] for column in KEY_COLUMNS if column in row)


def _metadata_text(value) -> str:
    if isinstance(value, (list, tuple)):
        value = ",".join(f"{item:g}" if isinstance(item, float) else str(item) for item in value)
    return " ".join(str(value).split())


def check_output(path: Path) -> None:
    """Raise :class:`InputFileError` unless ``path`` is absent or a writable log this module wrote.

    A log this module wrote starts with its title line (an empty file, or one cut inside the
    title, holds nothing to lose).  Reads only that line, so that a device or a huge foreign
    file is refused at once.
    """
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as error:
        raise InputFileError(f"{path}: cannot use it as a log: {error.strerror}") from None
    if not stat.S_ISREG(mode):
        raise InputFileError(f"{path}: not a regular file; a log must be a file (choose another --out)")
    title = f"# {TITLE}\n".encode()
    try:
        with open(path, "rb") as file:
            first = file.read(len(title))
    except OSError as error:
        raise InputFileError(f"{path}: cannot read it: {error.strerror}") from None
    if not title.startswith(first):  # empty, or cut inside our title line: nothing to lose
        raise InputFileError(f"{path}: not a log tactile wrote (no '# {TITLE}' title line); "
                             "it is left untouched: choose another --out")
    if not os.access(path, os.W_OK):
        raise InputFileError(f"{path}: not writable; cannot resume or restart it")


_HELD: dict[tuple[Path, int], list] = {}
_HELD_GUARD = threading.Lock()


@contextlib.contextmanager
def exclusive(path):
    """Hold the one-writer lock of the log ``path`` (:func:`check_output` first); re-entrant in a thread.

    Raises
    ------
    InputFileError
        If another process (or thread) writes the log, naming the pid in its lock file.
    """
    path = Path(path)
    key = (path.resolve(), threading.get_ident())
    with _HELD_GUARD:
        held = _HELD.get(key)
        if held:
            held[1] += 1
    if not held:
        check_output(path)
        descriptor = _lock(path)
        held = _HELD[key] = [descriptor, 1]
    try:
        yield
    finally:
        with _HELD_GUARD:
            held[1] -= 1
            if not held[1]:
                del _HELD[key]
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(lock_path(path))
                os.close(held[0])


def lock_path(path: Path) -> Path:
    """The lock file of the log ``path``: ``<name>.lock`` beside it."""
    return path.with_name(path.name + ".lock")


def _lock(path: Path) -> int:
    """An open descriptor holding the flock of ``lock_path(path)``, with our pid written in it."""
    lock = lock_path(path)
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        while True:
            descriptor = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                owner = os.read(descriptor, 32).decode("ascii", "replace").strip() or "unknown"
                os.close(descriptor)
                raise InputFileError(f"{path}: in use by another tactile process (pid {owner}); "
                                     f"wait for it to finish or stop it (its lock: {lock})") from None
            try:
                same = os.path.samestat(os.fstat(descriptor), os.stat(lock))
            except FileNotFoundError:
                same = False
            if same:  # else the holder removed it between our open and flock: lock the new file
                break
            os.close(descriptor)
        os.ftruncate(descriptor, 0)
        os.write(descriptor, f"{os.getpid()}\n".encode())
    except OSError as error:
        raise InputFileError(f"{path}: cannot lock it ({lock}): {error.strerror}") from None
    return descriptor


def read_log(path: Path, columns: tuple = logformat.COLUMNS) -> tuple[dict, list[dict], int]:
    """Metadata, complete rows (column -> text) and the byte length of the complete lines of a log we wrote with ``columns``.

    The length is 0 when there is no header row yet (a crash while the log was being created).

    Raises
    ------
    InputFileError
        If the header row is not ours, the file is not UTF-8 or a complete row is malformed (file and line named).
    """
    data = path.read_bytes()
    complete = data[: data.rfind(b"\n") + 1]
    try:
        text = complete.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputFileError(f"{path}: not a UTF-8 text log (byte {error.start}); not resuming it") from None
    metadata, rows, header = {}, [], None
    for number, line in enumerate(text.splitlines(), start=1):
        if header is None and line.startswith("#"):
            key, separator, value = line[1:].partition(":")
            if separator:
                metadata[key.strip()] = value.strip()
            continue
        fields = next(csv.reader([line]))
        if header is None:
            if tuple(fields) != columns:
                raise InputFileError(f"{path}:{number}: header {fields} is not {list(columns)}; not a log this writer can resume")
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
        Discard an existing log (one this module wrote) instead of resuming it.
    fsync : bool
        fsync after every row (durable against power loss, not only against crashes).
    columns : tuple of str
        The header (:data:`workflow.logformat.COLUMNS`, ``SCAN_COLUMNS`` for a scan, ``RINGDOWN_COLUMNS`` for a ring-down).
    """

    def __init__(self, path, metadata: dict, restart: bool = False, fsync: bool = True, columns: tuple = logformat.COLUMNS):
        self.path = Path(path)
        self.columns = columns
        self.fsync = fsync
        self.metadata = {"format_version": logformat.FORMAT_VERSION, **metadata}
        self.rows: list[dict] = []
        self.truncated_bytes = 0
        with contextlib.ExitStack() as stack:
            stack.enter_context(exclusive(self.path))
            self._open(restart)
            self._lock = stack.pop_all()
        self.keys = {row_key(row) for row in self.rows}

    def _open(self, restart: bool) -> None:
        if not (self.path.exists() and not restart and self._resume()):
            self._file = open(self.path, "w", encoding="utf-8", newline="")
            lines = [f"# {TITLE}"] + [f"# {key}: {_metadata_text(value)}" for key, value in self.metadata.items()]
            self._write("\n".join(lines) + "\n" + ",".join(self.columns) + "\n")

    def _resume(self) -> bool:
        old_metadata, self.rows, complete_length = read_log(self.path, self.columns)
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
        self.append_rows([row])

    def append_rows(self, rows: list[dict]) -> None:
        """Write several rows in one write (a ring-down's samples), durably."""
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        texts = []
        for row in rows:
            text = {column: format_value(column, row[column]) if row.get(column) is not None else "" for column in self.columns}
            writer.writerow(text[column] for column in self.columns)
            texts.append(text)
        self._write(buffer.getvalue())
        for text in texts:
            self.rows.append(text)
            self.keys.add(row_key(text))

    def keep_rows(self, count: int) -> None:
        """Drop every row after the first ``count`` (an incomplete group of rows, e.g. a ring-down cut short)."""
        self.rows = self.rows[:count]
        self.keys = {row_key(row) for row in self.rows}
        data = self.path.read_bytes()
        end = data.index(("\n" + ",".join(self.columns) + "\n").encode()) + len(",".join(self.columns)) + 2
        for _ in range(count):
            end = data.index(b"\n", end) + 1
        self._file.flush()
        os.truncate(self.path, end)

    def close(self) -> None:
        """Close the log and release its lock."""
        try:
            self._file.close()
        finally:
            self._lock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
