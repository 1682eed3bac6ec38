"""Values as data: a file format for cached results that cannot run code when it is read.

A value (numbers, strings, lists, tuples, dicts, numpy arrays and scalars, paths, and the
project's own dataclasses nested in any way) is written as one ``.npz`` archive: every
array under its own name, and a JSON tree that describes the rest and points to the
arrays.  Nothing is pickled, and reading never imports or calls anything outside this
project: a dataclass is named by module and class, the module must belong to the project
(``workflow`` or ``instruments``), the class must be a dataclass with exactly the stored
fields, and the instance is rebuilt field by field without calling its constructor, so the
value read is bit-identical to the value written.  A SHA-256 of the tree and the arrays is
stored with them and checked on reading.
"""

import dataclasses
import hashlib
import importlib
import io
import json
import re
import zipfile
from pathlib import Path, PurePath

import numpy as np

FORMAT = "tactile-data-1"
"""Name and version of the format, stored in every file."""
PROJECT_MODULE = re.compile(r"(workflow|instruments)(\.[A-Za-z_][A-Za-z0-9_]*)*")
"""Modules whose dataclasses may be rebuilt."""


class DataFileError(ValueError):
    """A file that is not a valid data file (damaged, foreign, or from another format)."""


def dumps(value) -> bytes:
    """The bytes of a data file holding ``value``.

    Raises
    ------
    TypeError
        For a value the format cannot hold (e.g. a function or an object array).
    """
    arrays = []
    tree = _encode(value, arrays)
    named = {f"a{i}": array for i, array in enumerate(arrays)}
    text = json.dumps({"format": FORMAT, "value": tree}, sort_keys=True, separators=(",", ":"))
    buffer = io.BytesIO()
    np.savez(buffer, tree=np.array(text), checksum=np.array(_checksum(text, named)), **named)
    return buffer.getvalue()


def loads(data: bytes):
    """The value held by the bytes of a data file.

    Raises
    ------
    DataFileError
        When the bytes are not an intact data file of this format, or name a type the
        format does not rebuild.
    """
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            contents = {name: archive[name] for name in archive.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, KeyError) as error:
        raise DataFileError(f"not a readable npz archive ({error})") from None
    try:
        text, checksum = str(contents.pop("tree")[()]), str(contents.pop("checksum")[()])
    except KeyError:
        raise DataFileError("no tree or checksum in the archive") from None
    if _checksum(text, contents) != checksum:
        raise DataFileError("checksum mismatch (damaged or edited)")
    try:
        document = json.loads(text)
    except json.JSONDecodeError as error:
        raise DataFileError(f"tree is not JSON ({error})") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise DataFileError(f"not a {FORMAT} file")
    return _decode(document.get("value"), contents)


def _checksum(text: str, arrays: dict) -> str:
    digest = hashlib.sha256(text.encode())
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}:{array.dtype.str}:{array.shape}".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def _encode(value, arrays: list):
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, float)) and type(value) in (int, float):
        return value
    if isinstance(value, (np.ndarray, np.generic)):
        array = np.asarray(value)
        if array.dtype.hasobject:
            raise TypeError("object arrays cannot be stored as data")
        arrays.append(array)
        return {"$array": len(arrays) - 1, "scalar": isinstance(value, np.generic)}
    if isinstance(value, complex):
        return {"$complex": [value.real, value.imag]}
    if isinstance(value, tuple):
        return {"$tuple": [_encode(item, arrays) for item in value]}
    if isinstance(value, list):
        return [_encode(item, arrays) for item in value]
    if isinstance(value, dict):
        return {"$dict": [[_encode(k, arrays), _encode(v, arrays)] for k, v in value.items()]}
    if isinstance(value, PurePath):
        return {"$path": str(value)}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        cls = type(value)
        if not PROJECT_MODULE.fullmatch(cls.__module__):
            raise TypeError(f"only the project's dataclasses can be stored, not {cls.__module__}.{cls.__qualname__}")
        fields = {f.name: _encode(getattr(value, f.name), arrays) for f in dataclasses.fields(value)}
        return {"$dataclass": f"{cls.__module__}:{cls.__qualname__}", "fields": fields}
    raise TypeError(f"cannot store a {type(value).__name__} as data")


def _decode(tree, arrays: dict):
    if tree is None or isinstance(tree, (bool, int, float, str)):
        return tree
    if isinstance(tree, list):
        return [_decode(item, arrays) for item in tree]
    if not isinstance(tree, dict) or len(tree) == 0:
        raise DataFileError(f"unexpected node {str(tree)[:60]!r}")
    if "$array" in tree:
        name = f"a{tree['$array']}"
        if name not in arrays:
            raise DataFileError(f"missing array {name}")
        return arrays[name][()] if tree.get("scalar") else arrays[name]
    if "$complex" in tree:
        real, imag = tree["$complex"]
        return complex(real, imag)
    if "$tuple" in tree:
        return tuple(_decode(item, arrays) for item in tree["$tuple"])
    if "$dict" in tree:
        return {_hashable(_decode(k, arrays)): _decode(v, arrays) for k, v in tree["$dict"]}
    if "$path" in tree:
        return _path(tree["$path"])
    if "$dataclass" in tree:
        return _dataclass(tree["$dataclass"], tree.get("fields"), arrays)
    raise DataFileError(f"unknown node {sorted(tree)[:3]}")


def _hashable(key):
    try:
        hash(key)
    except TypeError:
        raise DataFileError("a dict key that cannot be a key") from None
    return key


def _path(text):
    if not isinstance(text, str):
        raise DataFileError("a path that is not text")
    return Path(text)


def _dataclass(name, fields, arrays: dict):
    """Rebuild one of the project's dataclasses without calling its constructor."""
    module_name, _, qualname = str(name).partition(":")
    if not PROJECT_MODULE.fullmatch(module_name) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.]*", qualname):
        raise DataFileError(f"type {name!r} is not one of the project's")
    try:
        cls = importlib.import_module(module_name)
        for part in qualname.split("."):
            cls = getattr(cls, part)
    except (ImportError, AttributeError):
        raise DataFileError(f"type {name!r} does not exist (stored by another version?)") from None
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise DataFileError(f"{name!r} is not a dataclass")
    expected = {f.name for f in dataclasses.fields(cls)}
    if not isinstance(fields, dict) or set(fields) != expected:
        raise DataFileError(f"fields of {name!r} do not match the class (stored by another version?)")
    instance = object.__new__(cls)
    for field, value in fields.items():
        object.__setattr__(instance, field, _decode(value, arrays))
    return instance
