"""The hostile corpus (tests/data/hostile/, its cases in ``cases.toml``): loading its cases, the inputs it
generates, and running ``tactile`` on them in process (or as a process) with a time limit."""

import contextlib
import io
import os
import shutil
import signal
import subprocess
import sys
import threading
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workflow.cli import main
from workflow.inputfiles import MAX_CALIBRATION_BYTES, MAX_CONFIG_BYTES, MAX_LOG_BYTES, MAX_POSTERIOR_BYTES

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

CORPUS = Path(__file__).resolve().parent / "data" / "hostile"
MANIFEST = tomllib.loads((CORPUS / "cases.toml").read_text(encoding="utf-8"))
ROOT = Path(__file__).resolve().parents[1]
TIME_LIMIT = 60
"""Seconds a case may take before it counts as a hang (generous: the machine is shared)."""


@dataclass(frozen=True)
class Case:
    """One hostile command: its argv with placeholders (see cases.toml) and what its error line must say."""

    id: str
    kind: str
    argv: tuple
    message: tuple
    absent: tuple = ()
    setup: tuple = ()
    process: bool = False


def cases() -> list[Case]:
    """Every [[case]] of the manifest, templates expanded."""
    found = []
    for entry in MANIFEST["case"]:
        argv = tuple(MANIFEST["templates"].get(entry.get("template"), [])) + tuple(entry["args"])
        found.append(Case(entry["id"], entry["kind"], argv, tuple(entry["message"]), tuple(entry.get("absent", ())),
                          tuple(map(tuple, entry.get("setup", ()))), entry.get("process", False)))
    return found


def resume_cases() -> list[tuple[str, str]]:
    """(procedure, edit) of every hand-edited log under resume/."""
    return [(folder.name, path.stem) for folder in sorted((CORPUS / "resume").iterdir()) for path in sorted(folder.glob("*.csv"))]


def _sparse(path: Path, size: int) -> Path:
    """A file of ``size`` bytes that takes no disk space."""
    with open(path, "wb") as stream:
        stream.truncate(size)
    return path


def _nested(path: Path, prefix: str) -> Path:
    """``prefix`` then 100 000 nested arrays: deeper than Python's parsers can recurse."""
    path.write_text(prefix + "[" * 100_000 + "]" * 100_000, encoding="utf-8")
    return path


def _special(path: Path, make) -> Path:
    make(path)
    return path


def _npy_as_npz(path: Path) -> Path:
    """A single array saved as .npy, named .npz."""
    buffer = io.BytesIO()
    np.save(buffer, np.zeros(3))
    path.write_bytes(buffer.getvalue())
    return path


def _zip_bomb(path: Path) -> Path:
    """An npz whose member unpacks to more than :data:`MAX_POSTERIOR_BYTES` (written in 1 MiB blocks of zeros)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        with archive.open("padding.npy", "w", force_zip64=True) as member:
            block = bytes(2**20)
            for _ in range(MAX_POSTERIOR_BYTES // len(block) + 1):
                member.write(block)
    return path


GENERATED = {
    "fifo": lambda folder: _special(folder / "fifo", os.mkfifo),
    "folder": lambda folder: _special(folder / "folder", os.mkdir),
    "deep.json": lambda folder: _nested(folder / "deep.json", ""),
    "deep.toml": lambda folder: _nested(folder / "deep.toml", "a = "),
    "oversize_calibration.json": lambda folder: _sparse(folder / "oversize_calibration.json", MAX_CALIBRATION_BYTES + 1),
    "oversize_config.toml": lambda folder: _sparse(folder / "oversize_config.toml", MAX_CONFIG_BYTES + 1),
    "oversize_log.csv": lambda folder: _sparse(folder / "oversize_log.csv", MAX_LOG_BYTES + 1),
    "array.npz": lambda folder: _npy_as_npz(folder / "array.npz"),
    "bomb.npz": lambda folder: _zip_bomb(folder / "bomb.npz"),
}
"""Inputs a case names as {@name}, made in its scratch folder: special files, and files too large or too deep to keep."""


@dataclass
class Prepared:
    """A case's argv with its placeholders filled, and the input files it must leave unchanged."""

    argv: list
    inputs: dict = field(default_factory=dict)

    def changed(self) -> list:
        """The inputs whose bytes changed (or that went away)."""
        return [path for path, data in self.inputs.items() if not path.is_file() or path.read_bytes() != data]


def prepare(case: Case, folder: Path) -> Prepared:
    """Copy the case's corpus files into ``folder``, generate its special inputs, fill its placeholders."""
    prepared = Prepared([])
    for source, target in case.setup:
        shutil.copyfile(CORPUS / source, folder / target)
    for name in os.listdir(folder):
        prepared.inputs[folder / name] = (folder / name).read_bytes()

    def fill(text: str) -> str:
        if text.startswith("{@") and text.endswith("}"):
            return str(GENERATED[text[2:-1]](folder))
        if text.startswith("{") and text.endswith("}") and "/" in text and not text.startswith("{tmp}"):
            copy = folder / Path(text[1:-1]).name
            shutil.copyfile(CORPUS / text[1:-1], copy)
            prepared.inputs[copy] = copy.read_bytes()
            return str(copy)
        return text.replace("{tmp}", str(folder))

    prepared.argv = [fill(item) for item in case.argv]
    return prepared


class Hung(BaseException):
    """A command ran past its time limit (a BaseException: ``tactile``'s handler of bugs does not swallow it)."""


def run_in_process(argv: list, limit: int = TIME_LIMIT) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``tactile ARGV`` run by its main function; :class:`Hung` past ``limit`` s.

    A watchdog thread interrupts the main thread with SIGUSR1 (not SIGALRM, which pytest-timeout uses).
    """
    out, err = io.StringIO(), io.StringIO()

    def expire(signum, frame):
        raise Hung(f"tactile {' '.join(argv)} ran past {limit} s")

    previous = signal.signal(signal.SIGUSR1, expire)
    watchdog = threading.Timer(limit, signal.pthread_kill, (threading.main_thread().ident, signal.SIGUSR1))
    watchdog.start()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                status = main(argv)
            except SystemExit as exit_:
                status = exit_.code
    finally:
        watchdog.cancel()
        signal.signal(signal.SIGUSR1, previous)
    return status, out.getvalue(), err.getvalue()


def run_process(argv: list, limit: int = TIME_LIMIT) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``python -m workflow ARGV`` as a process; :class:`Hung` past ``limit`` s."""
    try:
        done = subprocess.run([sys.executable, "-m", "workflow", *argv], capture_output=True, text=True, timeout=limit,
                              cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    except subprocess.TimeoutExpired:
        raise Hung(f"tactile {' '.join(argv)} ran past {limit} s") from None
    return done.returncode, done.stdout, done.stderr


def error_lines(stderr: str) -> list:
    """The ``tactile ...: error:`` (and ``internal error``) lines of a command's stderr."""
    return [line for line in stderr.splitlines() if line.startswith("tactile ") and "error:" in line]
