"""A content-addressed disk cache of expensive evaluations.

An evaluation is named by a plain description (model name, plate fields, Q, voltage,
settings, code version...); the key is the SHA-256 of its canonical JSON, so the same
inputs always find the same file and any change of input gives a new key.  Values are
stored as data (:mod:`workflow.execution.datafile`: npz arrays and a JSON tree, checksummed;
nothing is pickled, so a planted or damaged file cannot run code: it is ignored with a
warning and recomputed).  Writes go to a temporary file in the cache directory and are
renamed into place, so a reader never sees a half-written entry and concurrent writers
cannot corrupt one.

The directory is ``$TACTILE_CACHE`` if set, else the platform's user cache folder
(``platformdirs.user_cache_dir("tactile")``: ``~/.cache/tactile`` on Linux, ``~/Library/Caches/tactile``
on macOS, ``%LOCALAPPDATA%\\tactile\\Cache`` on Windows), whatever the working directory.
"""

import dataclasses
import hashlib
import json
import os
import sys
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import Callable, Iterable, List, Optional

import numpy as np
import platformdirs

from workflow.execution import datafile
from workflow.execution.parallel import map_evaluations

CACHE_VARIABLE = "TACTILE_CACHE"
"""Environment variable naming the cache directory."""


def default_directory() -> Path:
    """``$TACTILE_CACHE``, else the user cache folder of the platform (``~/.cache/tactile`` on Linux)."""
    return Path(os.environ.get(CACHE_VARIABLE) or platformdirs.user_cache_dir("tactile", appauthor=False))


def package_directory(package) -> str:
    """The folder of an imported package (``package.__path__``), for :func:`source_version`."""
    return str(Path(package.__path__[0]))


VERSIONED_SUFFIXES = (".py", ".toml", ".csv")
"""What :func:`source_version` reads: the sources and the package data they read (material records, defaults, the
published plates' logs)."""


@lru_cache(maxsize=None)
def source_version(package_directory: str) -> str:
    """SHA-256 of the Python sources and package data under a directory: changes whenever the code or its data does."""
    digest = hashlib.sha256()
    paths = (path for path in Path(package_directory).rglob("*") if path.suffix in VERSIONED_SUFFIXES)
    for path in sorted(paths):
        digest.update(path.relative_to(package_directory).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _plain(value):
    """JSON form of numpy scalars/arrays and dataclasses (for canonical keys)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot describe {type(value).__name__} in a cache key")


def content_key(description: dict) -> str:
    """SHA-256 hex digest of the canonical JSON of ``description``."""
    text = json.dumps(description, sort_keys=True, default=_plain, allow_nan=False, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


class EvaluationCache:
    """Values on disk as data files, one per content key.

    Attributes
    ----------
    directory : Path
    hits, misses : int
        Lookups answered from disk and lookups that were not, since creation.
    """

    def __init__(self, directory: Optional[os.PathLike] = None):
        self.directory = Path(directory) if directory is not None else default_directory()
        self.hits = self.misses = 0

    def _path(self, key: str) -> Path:
        return self.directory / key[:2] / f"{key}.npz"

    def load(self, key: str):
        """(True, value) when the key is stored, else (False, None).

        A damaged or foreign entry counts as missing: one warning line on stderr, and the
        value is recomputed (and the entry replaced) by the caller.
        """
        path = self._path(key)
        try:
            value = datafile.loads(path.read_bytes())
        except FileNotFoundError:
            self.misses += 1
            return False, None
        except (OSError, datafile.DataFileError) as error:
            print(f"tactile: warning: ignoring cache entry {path}: {error}; recomputing it", file=sys.stderr)
            self.misses += 1
            return False, None
        self.hits += 1
        return True, value

    def store(self, key: str, value) -> None:
        """Write atomically: temporary file in the same directory, then rename."""
        path = self._path(key)
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=".", suffix=".tmp")
        try:
            with os.fdopen(handle, "wb") as stream:
                stream.write(datafile.dumps(value))
            os.replace(temporary, path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise


def cached_map(
    function: Callable,
    items: Iterable,
    describe: Callable[[object], dict],
    cache: Optional[EvaluationCache],
    scheduler=None,
    progress: bool = True,
    description: str = "evaluations",
) -> List:
    """:func:`~workflow.execution.parallel.map_evaluations` that computes only what the cache lacks.

    Parameters
    ----------
    function : callable
        Picklable function of one item.
    items : iterable
    describe : callable
        item -> dict of plain data naming the evaluation (the key's content).
    cache : EvaluationCache or None
        None evaluates everything.
    scheduler, progress, description
        As for :func:`~workflow.execution.parallel.map_evaluations`.

    Returns
    -------
    list
        Results in the order of ``items``; identical items are computed once.
    """
    items = list(items)
    if cache is None:
        return map_evaluations(function, items, scheduler, progress, description=description)
    keys = [content_key(describe(item)) for item in items]
    results, pending = {}, {}
    for key, item in zip(keys, items):
        if key in results or key in pending:
            continue
        found, value = cache.load(key)
        if found:
            results[key] = value
        else:
            pending[key] = item
    computed = map_evaluations(function, list(pending.values()), scheduler, progress, description=description)
    for key, value in zip(pending, computed):
        cache.store(key, value)
        results[key] = value
    return [results[key] for key in keys]
