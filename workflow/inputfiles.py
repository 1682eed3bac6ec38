"""Reading input files within bounds (docs/safety.md, "What inputs are accepted").

Every file tactile reads — a log, a calibration, a configuration, a posterior — is opened here:

* only a regular file is read: a FIFO, a device (``/dev/zero``), a socket or a folder is refused at
  once, before a byte is read (a FIFO is opened without blocking, so that no writer is waited for);
* a file larger than the maximum of its kind is refused before it is read;
* JSON and TOML are refused when nested deeper than :data:`MAX_NESTING` (Python's parsers recurse:
  a deep enough file would exhaust the stack).

Errors are :class:`~workflow.errors.InputFileError` naming the file (``what``).
"""

import json
import os
import re
import stat
import sys

import numpy as np

from workflow.errors import InputFileError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

MIB = 2**20
MAX_LOG_BYTES = 256 * MIB
"""Largest interferometer log [bytes]: a million rows (the reader's limit) of about 100 characters and a header."""
MAX_CALIBRATION_BYTES = 64 * MIB
"""Largest ``calibration.json`` [bytes]: 100 000 kept samples of five parameters take about 12 MiB."""
MAX_POSTERIOR_BYTES = 256 * MIB
"""Largest ``posterior.npz`` [bytes] (a long chain's draws of a dozen parameters take tens of MiB)."""
MAX_CONFIG_BYTES = 1 * MIB
"""Largest TOML configuration or settings file, and largest record of tactile's outputs [bytes]."""
MAX_NESTING = 32
"""Deepest nesting of arrays and tables accepted in a JSON or TOML file [-] (tactile's own files nest 5 deep)."""


def _describe(mode: int) -> str:
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
             (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))
    return next((name for test, name in kinds if test(mode)), "a special file")


def open_input(path, what: str, limit: int):
    """The regular file ``path`` opened for reading in binary mode (the caller closes it).

    Parameters
    ----------
    path : path-like
    what : str
        How messages name the file (e.g. ``"--calibration cal.json"``).
    limit : int
        Largest accepted size [bytes].

    Raises
    ------
    InputFileError
        Missing or unreadable; not a regular file; larger than ``limit``.
    """
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise InputFileError(f"{what}: no such file") from None
    except OSError as error:
        raise InputFileError(f"{what}: cannot read it ({error.strerror or error})") from None
    status = os.fstat(descriptor)
    if not stat.S_ISREG(status.st_mode):
        os.close(descriptor)
        raise InputFileError(f"{what}: is {_describe(status.st_mode)}, not a regular file; give a file")
    if status.st_size > limit:
        os.close(descriptor)
        raise InputFileError(f"{what}: {status.st_size} bytes, more than the {limit} accepted ({limit // MIB} MiB)")
    os.set_blocking(descriptor, True)
    return os.fdopen(descriptor, "rb")


def read_input(path, what: str, limit: int) -> bytes:
    """The bytes of the regular file ``path`` (:func:`open_input`), at most ``limit`` of them."""
    with open_input(path, what, limit) as stream:
        data = stream.read(limit + 1)
    if len(data) > limit:  # grew while being read
        raise InputFileError(f"{what}: more than the {limit} bytes accepted ({limit // MIB} MiB)")
    return data


def read_text(path, what: str, limit: int) -> str:
    """The UTF-8 text of ``path`` (:func:`read_input`; a leading byte-order mark is dropped)."""
    data = read_input(path, what, limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        raise InputFileError(f"{what}: not a UTF-8 text file (byte {error.start})") from None


_JSON_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_TOML_STRINGS_AND_COMMENTS = re.compile(r'""".*?"""|\'\'\'.*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'|#[^\n]*', re.DOTALL)


def nesting_depth(text: str, toml: bool = False) -> int:
    """Deepest nesting of ``[`` and ``{`` outside strings (and, for TOML, comments) [-].

    Brackets of an unterminated string count: a malformed file errs towards a larger depth.
    """
    code = (_TOML_STRINGS_AND_COMMENTS if toml else _JSON_STRINGS).sub("", text).encode("utf-8", "replace")
    marks = np.frombuffer(code, dtype=np.uint8)
    step = np.isin(marks, (ord("["), ord("{"))).astype(np.int64) - np.isin(marks, (ord("]"), ord("}")))
    return int(np.cumsum(step).max(initial=0))


def _load(path, what: str, limit: int, toml: bool):
    """The JSON or TOML document in ``path``, read within ``limit`` bytes and :data:`MAX_NESTING`."""
    text = read_text(path, what, limit)
    depth = nesting_depth(text, toml)
    if depth > MAX_NESTING:
        raise InputFileError(f"{what}: arrays or tables nested {depth} deep, more than the {MAX_NESTING} accepted")
    try:
        return tomllib.loads(text) if toml else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as error:
        raise InputFileError(f"{what}: not valid {'TOML' if toml else 'JSON'}: {error}") from None


def load_json(path, what: str, limit: int):
    """The JSON document in ``path``, read within ``limit`` bytes and :data:`MAX_NESTING`."""
    return _load(path, what, limit, toml=False)


def load_toml(path, what: str, limit: int = MAX_CONFIG_BYTES) -> dict:
    """The TOML document in ``path``, read within ``limit`` bytes and :data:`MAX_NESTING`."""
    return _load(path, what, limit, toml=True)
