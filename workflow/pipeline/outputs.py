"""Output folders: tactile overwrites the files it wrote there, and no one else's unless forced.

Each folder a command writes into keeps :data:`RECORD` (``.tactile-outputs.json``): the path,
size and SHA-256 of every file tactile wrote there.  Before any work, a command names the
files it may write (glob patterns, relative to the folder); an existing file matching one of
them is refused unless the record lists it with its present content (a file someone else put
there, or one of ours edited since, is not overwritten) or ``force`` is given.  When the
command ends, even on an error or a stop signal, every matching file it created or changed
is recorded, so the same command rerun into the same folder needs no ``force``.
"""

import hashlib
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from workflow.errors import InputFileError
from workflow.inputfiles import MAX_CONFIG_BYTES, load_json

RECORD = ".tactile-outputs.json"
"""File name of the record of what tactile wrote in a folder."""

RECORD_VERSION = 1


def writable_folder(path, option: str = "--out") -> Path:
    """The folder ``path``, created if missing and checked writable.

    Raises
    ------
    InputFileError
        ``path`` is an existing file, lies under a file, or cannot be created or written to, naming ``option``.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputFileError(
            f"{option} {path}: exists and is not a folder (give a folder, or a path that does not exist)"
        )
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as error:
        raise InputFileError(f"{option} {path}: cannot write a folder there ({error.strerror or error})") from None
    return path


@contextmanager
def output_folder(path, patterns, force: bool = False, option: str = "--out"):
    """Context manager: the checked output folder ``path`` for files matching ``patterns``.

    Parameters
    ----------
    path : path-like
        The folder, created if missing.
    patterns : sequence of str
        Glob patterns, relative to the folder, of every file the command may write there.
    force : bool
        Overwrite files tactile did not write (``--force``).
    option : str
        The option named in errors.

    Yields
    ------
    Path

    Raises
    ------
    InputFileError
        Before any work: the folder is not writable (:func:`writable_folder`), its record is
        damaged, or a file matching ``patterns`` is not tactile's (without ``force``).
    """
    folder = writable_folder(path, option)
    try:
        record = _read_record(folder)
    except InputFileError:
        if not force:
            raise
        record = {}
    before = _snapshot(folder, patterns)
    if not force:
        _refuse_foreign(folder, before, record, option)
    try:
        yield folder
    finally:
        _update_record(folder, patterns, before, record)


def _read_record(folder: Path) -> dict:
    path = folder / RECORD
    if not path.exists():
        return {}
    try:
        data = load_json(path, str(path), MAX_CONFIG_BYTES)
        files = data["files"]
        if data.get("version") != RECORD_VERSION or not all(
            isinstance(name, str) and isinstance(entry["size"], int) and isinstance(entry["sha256"], str)
            for name, entry in files.items()
        ):
            raise ValueError("unknown layout")
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise InputFileError(
            f"{path}: not a record of tactile's outputs ({error}); delete it, or pass --force "
            "to overwrite the files tactile writes in this folder"
        ) from None
    return files


def _snapshot(folder: Path, patterns) -> dict:
    """Relative path -> (size, modification time [ns]) of the files matching ``patterns``."""
    found = {}
    for pattern in patterns:
        for path in folder.glob(pattern):
            if path.is_file() and path.name != RECORD:
                status = path.stat()
                found[path.relative_to(folder).as_posix()] = (status.st_size, status.st_mtime_ns)
    return found


def _digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _is_ours(folder: Path, name: str, size: int, record: dict) -> bool:
    entry = record.get(name)
    return entry is not None and entry["size"] == size and entry["sha256"] == _digest(folder / name)


def _refuse_foreign(folder: Path, existing: dict, record: dict, option: str) -> None:
    foreign = sorted(name for name, (size, _) in existing.items() if not _is_ours(folder, name, size, record))
    if foreign:
        more = f" (and {len(foreign) - 1} more)" if len(foreign) > 1 else ""
        raise InputFileError(
            f"{option} {folder}: {folder / foreign[0]}{more} would be overwritten, and tactile did not write it "
            f"(or it changed since; {RECORD} lists what tactile wrote); move it, choose another folder, "
            "or pass --force to overwrite"
        )


def _update_record(folder: Path, patterns, before: dict, record: dict) -> None:
    """Add the files matching ``patterns`` created or changed since ``before``; drop the ones gone."""
    after = _snapshot(folder, patterns)
    files = {name: entry for name, entry in record.items() if (folder / name).is_file()}
    for name, state in after.items():
        if before.get(name) != state:
            files[name] = {"size": state[0], "sha256": _digest(folder / name)}
    text = json.dumps({"version": RECORD_VERSION, "files": dict(sorted(files.items()))}, indent=1) + "\n"
    temporary = folder / f"{RECORD}.tmp"
    temporary.write_text(text, encoding="utf-8")
    os.replace(temporary, folder / RECORD)


def save_figure(figure, path, dpi: int = 120, tight: bool = False) -> str:
    """Write a matplotlib figure as PNG, release it and return its path; an unwritable path is one clear error.

    ``tight``: crop the canvas to the drawn artists (``bbox_inches="tight"``).
    """
    import matplotlib.pyplot as plt

    try:
        figure.savefig(path, dpi=dpi, **({"bbox_inches": "tight"} if tight else {}))
    except OSError as error:
        raise InputFileError(f"cannot write the figure {path}: {error.strerror or error}") from None
    finally:
        plt.close(figure)
    return str(path)
