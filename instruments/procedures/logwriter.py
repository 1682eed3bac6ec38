"""Writer of interferometer logs (docs/log-format.md, format version 1) that survives crashes and hand edits.

Every row is written, flushed and fsync'd as soon as it is measured.  Resuming a log never
deletes nor rewrites a row it holds (docs/log-format.md, "Resuming a log"): the procedures
match its rows to their planned points by value, at the precision the log writes them
(:func:`point_key`: ``-36.55`` is the point ``-36.5500``), and append only the points no row
covers.  Rows that repeat a point are kept (a warning names them); a row that is no point of
the plan, or a line that is not a row of this log, makes the resume refuse in one line and
leaves the file byte for byte as it was.  An unterminated last line (a write cut short) is
kept: as a row, its newline added, when it is a complete row, else as a comment line (without the
NUL bytes a power loss may pad the file's last block with).  A log is
only resumed by the same procedure with the same plan (the ``plan_*`` metadata, compared by
value); anything else is an error, not a guess.

A log has one writer: :func:`exclusive` holds an ``fcntl.flock`` on ``<log>.lock`` (which
holds the writer's pid, for the message a second writer gets) for as long as the log is
written.  The kernel releases the lock when its process dies, so a lock file left by a
killed process is taken over.  A file this module did not write (no title line) is never
appended to nor overwritten, and only regular files are logs.
"""

import contextlib
import fcntl
import math
import os
import stat
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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
    logformat.HOLD_TIME: "{:.9g}",
}
KEY_COLUMNS = (logformat.SWEEP, logformat.FREQUENCY, logformat.DRIVE_VOLTAGE, logformat.X_POSITION, logformat.Y_POSITION,
               logformat.DECAY_TIME, logformat.RENDER_TIME, logformat.HOLD_TIME)
"""The columns that identify a planned point (those a log has; a hold's frequency and drive are measured, its key is
:data:`HOLD_KEY_COLUMNS`)."""
HOLD_KEY_COLUMNS = (logformat.SWEEP, logformat.HOLD_TIME)
"""The key of a hold log's rows: its samples are planned in time, frequency and drive are what the loop set."""
REQUIRED = (logformat.SWEEP, logformat.FREQUENCY, logformat.DRIVE_VOLTAGE, logformat.VELOCITY) + KEY_COLUMNS[3:]
"""Columns every row of ours fills (the others may be empty)."""
INCOMPLETE_ROW = "# incomplete row (a write cut short), kept as a comment by the resume: "
"""Prefix the resume puts before an unterminated last line that is not a complete row."""


def format_value(column: str, value) -> str:
    """The text of ``value`` in ``column``, as written to the log (-0 written as 0)."""
    return _FORMATS[column].format(value + 0 if column != logformat.SWEEP else int(value))


def point_key(values: dict, keys: tuple = KEY_COLUMNS) -> tuple:
    """Identity of a planned point: its ``keys`` values (column -> number, those it has) as the log writes them, so
    that rows and points match by value at the log's precision."""
    return tuple(format_value(column, values[column]) for column in keys if column in values)


def row_key(row: dict, keys: tuple = KEY_COLUMNS) -> tuple:
    """The :func:`point_key` of a logged row (column -> text, already normalised by :func:`read_log`)."""
    return tuple(row[column] for column in keys if column in row)


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


@dataclass(frozen=True)
class LoggedRows:
    """What a log of ours holds, as :func:`read_log` read it.

    Attributes
    ----------
    metadata : dict
        key -> text of the ``# key: value`` lines before the header.
    rows : list of dict
        column -> text of each row, the :data:`KEY_COLUMNS` normalised to the writer's format.
    lines : list of int
        Line number of each row [-].
    length : int
        Bytes of the file up to the end of its last complete line (0 without a header row: a log cut
        inside its header, which holds no row).
    tail : bytes
        The unterminated last line, if any ("" otherwise).
    tail_is_row : bool
        Whether ``tail`` is a complete row (then the last of ``rows``).
    """

    metadata: dict
    rows: list
    lines: list
    length: int
    tail: bytes = b""
    tail_is_row: bool = False


def _row(path: Path, number: int, fields: list, columns: tuple, complete: bool) -> dict | None:
    """A row of ours (column -> text), its key columns normalised; :class:`InputFileError` naming the line, or None
    for an unterminated last line that is no row."""
    row = dict(zip(columns, fields))
    for column, text in row.items():
        if not text.strip() and column not in REQUIRED:
            continue
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or (column == logformat.SWEEP and value != round(value)):
            if not complete:
                return None
            kind = "an integer" if column == logformat.SWEEP else "a finite number"
            raise InputFileError(f"{path}, line {number}: {column} {text!r} is not {kind}")
        if column in KEY_COLUMNS:
            row[column] = format_value(column, value)
    return row


def read_log(path: Path, columns: tuple = logformat.COLUMNS) -> LoggedRows:
    """The metadata and rows of a log we wrote with ``columns`` (:class:`~workflow.logformat.LogReader`, lines of
    any length).

    Blank lines and ``#`` comment lines after the header are skipped.  An unterminated last line is a row when it
    is a complete one, else ignored (:attr:`LoggedRows.tail` holds it).

    Raises
    ------
    InputFileError
        Those of the reader; a header row that is not ours; a complete line that is no row of ours (wrong number
        of fields, a value that is not a number, a sweep id that is not an integer), naming the file and line.
    """
    rows, lines = [], []
    with logformat.LogReader(path, max_line_length=None) as log:
        number, header, complete = next(log, (0, None, False))
        metadata = {key: value for key, (value, _) in log.metadata.items()}
        if not complete:  # no header row, or one cut short: a log that holds no row
            return LoggedRows(metadata, [], [], 0, log.tail)
        if tuple(header) != columns:
            raise InputFileError(f"{path}, line {number}: header {header} is not {list(columns)}; not a log this "
                                 "writer can resume")
        try:
            for number, fields, complete in log:
                row = None if fields is None else _row(path, number, fields, columns, complete)
                if row:
                    rows.append(row)
                    lines.append(number)
        except InputFileError as error:
            raise InputFileError(f"{error}; not resuming a damaged log (fix or remove the line, or choose another "
                                 "--out)") from None
    return LoggedRows(metadata, rows, lines, log.length, log.tail, tail_is_row=not complete and lines[-1:] == [number])


LINE_BREAKS = "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
"""The characters that end a line for :meth:`str.splitlines`."""


def _kept_tail(tail: bytes) -> bytes:
    """The comment line that keeps an unterminated last line which is no row (:data:`INCOMPLETE_ROW`): its text as it
    was (spaces kept) but without the NUL bytes a power loss may pad a file's last block with, a character cut in two
    replaced by U+FFFD and any character that would end a line (CR, NEL, ...) by a space; nothing when only padding
    is left."""
    text = tail.replace(b"\x00", b"").decode("utf-8", "replace")
    kept = "".join(" " if c in LINE_BREAKS else c for c in text)  # as it was, but on one line
    return (INCOMPLETE_ROW + kept + "\n").encode() if text.strip() else b""


def _same_value(old: str | None, new: str | None) -> bool:
    """Whether two metadata texts say the same: equal, or the same numbers (comma-separated) to 1e-9."""
    if old == new:
        return True
    try:
        a, b = (np.array([float(item) for item in text.split(",")]) for text in (old, new))
    except (AttributeError, ValueError):
        return False
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-9, atol=0))


class LogWriter:
    """Append rows to a log, creating it with its metadata or resuming it (never deleting a row).

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
    keys : tuple of str
        The columns that identify a planned point (:data:`KEY_COLUMNS`; :data:`HOLD_KEY_COLUMNS` for a hold).

    Attributes
    ----------
    rows : list of dict
        The log's rows (column -> text), those resumed then those appended.
    keys : dict
        :func:`row_key` -> line of its first row.
    warnings : list of str
        What the resume tolerated: rows repeating a point, an unterminated last line.
    truncated_bytes : int
        Length of an unterminated last line found on resuming [bytes] (kept: see the module's docstring).
    """

    def __init__(self, path, metadata: dict, restart: bool = False, fsync: bool = True, columns: tuple = logformat.COLUMNS,
                 keys: tuple = KEY_COLUMNS):
        self.path = Path(path)
        self.columns = columns
        self.key_columns = keys
        self.fsync = fsync
        self.metadata = {"format_version": logformat.FORMAT_VERSION, **metadata}
        self.rows: list[dict] = []
        self.lines: list[int] = []
        self.warnings: list[str] = []
        self.truncated_bytes = 0
        self._file = None
        self._tail_fix = None
        with contextlib.ExitStack() as stack:
            stack.enter_context(exclusive(self.path))
            self._open(restart)
            self._lock = stack.pop_all()
        self.keys = {}
        repeats = []
        for row, line in zip(self.rows, self.lines):
            first = self.keys.setdefault(row_key(row, keys), line)
            if first != line:
                repeats.append((line, first))
        if repeats:
            more = f" and {len(repeats) - 1} more" if len(repeats) > 1 else ""
            self.warnings.append(f"{self.path}, line {repeats[0][0]}: the same point as line {repeats[0][1]}{more} "
                                 "(rows pasted twice?); every row is kept and no point is measured again")

    def _open(self, restart: bool) -> None:
        if not (self.path.exists() and not restart and self._resume()):
            self._file = open(self.path, "w", encoding="utf-8", newline="")
            self._write(logformat.head_text(TITLE, self.metadata, self.columns))

    def _resume(self) -> bool:
        logged = read_log(self.path, self.columns)
        if not logged.length:
            return False
        wanted = {key: logformat.metadata_text(value) for key, value in self.metadata.items() if key == "procedure" or key.startswith("plan_")}
        wanted.update({key: None for key in logged.metadata if key.startswith("plan_") and key not in wanted})
        for key, value in wanted.items():
            if not _same_value(logged.metadata.get(key), value):
                hint = logformat.RESUME_HINTS.get(key, "use another output file or restart it")
                raise InputFileError(
                    f"{self.path}: cannot resume: it was written with {key} = {logged.metadata.get(key)!r}, "
                    f"this run has {value!r}; {hint}"
                )
        self.rows, self.lines = logged.rows, logged.lines
        self.truncated_bytes = len(logged.tail)
        if logged.tail_is_row:
            self._tail_fix = (logged.length + len(logged.tail), b"\n")
            self.warnings.append(f"{self.path}, line {self.lines[-1]}: the last row has no line end; it is kept")
        elif logged.tail:
            self._tail_fix = (logged.length, _kept_tail(logged.tail))
            self.warnings.append(f"{self.path}: an incomplete last line ({len(logged.tail)} bytes, a write cut short) "
                                 "is kept as a comment line; its point is measured again")
        return True

    def check_planned(self, keys, sweeps) -> None:
        """Refuse (before anything is written) a row of the sweeps ``sweeps`` whose key is not in ``keys``.

        Raises
        ------
        InputFileError
            Naming the first such row's line: a row that is no point of the plan (edited, or from another log).
        """
        names = {str(sweep) for sweep in sweeps}
        for row, line in zip(self.rows, self.lines):
            if row[logformat.SWEEP] in names and row_key(row, self.key_columns) not in keys:
                shown = ", ".join(f"{column} {row[column]}" for column in self.key_columns if column in row)
                raise InputFileError(f"{self.path}, line {line}: this row ({shown}) is no point of the plan being "
                                     "resumed (edited by hand, or pasted from another log?); not resuming: fix or "
                                     "remove the line, or choose another --out")

    def check_sweeps(self, sweeps) -> None:
        """Refuse a row whose sweep id is not one of ``sweeps`` (the procedure's), naming its line."""
        names = {str(sweep) for sweep in sweeps}
        for row, line in zip(self.rows, self.lines):
            if row[logformat.SWEEP] not in names:
                raise InputFileError(f"{self.path}, line {line}: sweep {row[logformat.SWEEP]} is not one of this plan's "
                                     f"({', '.join(sorted(names, key=int))}); not resuming: fix or remove the line, "
                                     "or choose another --out")

    def _write(self, text: str) -> None:
        if self._file is None:
            if self._tail_fix is not None:  # one write, over the unterminated line and past it: nothing is cut
                offset, fix = self._tail_fix
                with open(self.path, "r+b") as file:
                    os.pwrite(file.fileno(), fix, offset)
                    os.ftruncate(file.fileno(), offset + len(fix))  # past the fix: the rest of the tail, rewritten
                self._tail_fix = None
            self._file = open(self.path, "a", encoding="utf-8", newline="")
        self._file.write(text)
        self._file.flush()
        if self.fsync:
            os.fsync(self._file.fileno())

    def append(self, row: dict) -> None:
        """Write one row (column -> value; missing optional columns stay empty), durably."""
        self.append_rows([row])

    def append_rows(self, rows: list[dict]) -> None:
        """Write several rows in one write (a ring-down's samples), durably."""
        texts = [{column: format_value(column, row[column]) if row.get(column) is not None else "" for column in self.columns}
                 for row in rows]
        self._write(logformat.rows_text([text[column] for column in self.columns] for text in texts))
        for text in texts:
            self.rows.append(text)
            self.lines.append(0)
            self.keys.setdefault(row_key(text, self.key_columns), 0)

    def append_comment(self, text: str) -> None:
        """Write a ``# text`` line after the rows (readers skip it): why a procedure stopped."""
        self._write(f"# {' '.join(text.split())}\n")

    def close(self) -> None:
        """Close the log and release its lock."""
        try:
            if self._file is not None:
                self._file.close()
        finally:
            self._lock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
