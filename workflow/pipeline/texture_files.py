"""The user's texture files: profiles, friction curves and finger traces (docs/rendering.md#textures-and-the-finger).

UTF-8 CSV with a header row naming the columns (others are ignored) and optional ``#`` comment
lines; every error names the option, the file and, where one is at fault, the line.
"""

import csv
import math
from pathlib import Path

import numpy as np

from workflow.errors import InputFileError
from workflow.rendering.textures import FrictionCurve, Grating, Profile, TextureError, Trace
from workflow.units import MM, UM

PROFILE_COLUMNS = ("position_mm", "amplitude_um")
"""A profile's columns; with a friction curve ``friction`` replaces ``amplitude_um``."""
FRICTION_COLUMNS = ("amplitude_um", "friction")
"""A friction curve's columns (friction ratio: 1 at rest)."""
TRACE_COLUMNS = ("time_s", "position_mm")
"""A finger trace's columns."""
MAX_TABLE_ROWS = 1_000_000
"""Most data rows read from a texture file [-]."""


def _read_table(path, option: str, columns: tuple) -> dict:
    """Column -> values and ``"line"`` -> line numbers of a CSV with a header naming ``columns`` (others ignored)."""
    path = Path(path)
    where = f"{option} {path}"
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as error:
        raise InputFileError(f"{where}: cannot read ({error.strerror or error})") from None
    except UnicodeDecodeError:
        raise InputFileError(f"{where}: not a UTF-8 text file") from None
    rows = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
            if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise InputFileError(f"{where}: empty (expected a header row {','.join(columns)} and data rows)")
    header_line, header = rows[0][0], [name.strip().lower() for name in next(csv.reader([rows[0][1]]))]
    missing = [name for name in columns if name not in header]
    if missing:
        raise InputFileError(f"{where}, line {header_line}: no column {', '.join(missing)}; expected a header row "
                             f"naming {', '.join(columns)} (got {', '.join(header)})")
    if len(rows) == 1:
        raise InputFileError(f"{where}: header only, no data rows")
    if len(rows) - 1 > MAX_TABLE_ROWS:
        raise InputFileError(f"{where}: more than {MAX_TABLE_ROWS} data rows")
    table = {name: [] for name in columns}
    lines = []
    for number, line in rows[1:]:
        cells = next(csv.reader([line]))
        if len(cells) != len(header):
            raise InputFileError(f"{where}, line {number}: expected {len(header)} fields, got {len(cells)}")
        for name in columns:
            try:
                value = float(cells[header.index(name)])
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise InputFileError(f"{where}, line {number}: {name} = {cells[header.index(name)]!r} is not a finite number")
            table[name].append(value)
        lines.append(number)
    return {**{name: np.array(values) for name, values in table.items()}, "line": lines}


def _build(kind, table: dict, where: str, *arrays):
    """``kind(*arrays)``, a TextureError reported with the file (and the line of the sample it names)."""
    try:
        return kind(*arrays)
    except TextureError as error:
        line = f", line {table['line'][error.index]}" if error.index is not None else ""
        raise InputFileError(f"{where}{line}: {error}") from None


def read_friction_curve(path) -> FrictionCurve:
    """The friction curve in ``path`` (columns ``amplitude_um``, ``friction``)."""
    table = _read_table(path, "--friction-curve", FRICTION_COLUMNS)
    return _build(FrictionCurve, table, f"--friction-curve {path}", table["amplitude_um"] * UM, table["friction"])


def read_profile(path, friction: FrictionCurve | None = None) -> Profile:
    """The profile in ``path``: ``position_mm`` and ``amplitude_um``, or ``friction`` converted through ``friction``."""
    columns = ("position_mm", "friction") if friction is not None else PROFILE_COLUMNS
    table = _read_table(path, "--profile", columns)
    where = f"--profile {path}"
    if friction is None:
        amplitude = table["amplitude_um"] * UM
    else:
        amplitude = _build(friction.amplitude_for, table, where, table["friction"])
    return _build(Profile, table, where, table["position_mm"] * MM, amplitude)


def read_trace(path) -> Trace:
    """The finger trace in ``path`` (columns ``time_s``, ``position_mm``)."""
    table = _read_table(path, "--trace", TRACE_COLUMNS)
    return _build(Trace, table, f"--trace {path}", table["time_s"], table["position_mm"] * MM)


def grating_from_friction(period: float, duty: float, friction_levels, curve: FrictionCurve) -> Grating:
    """A grating whose two friction levels [-] become amplitudes through ``curve`` (less friction, more amplitude)."""
    low, high = sorted(float(a) for a in curve.amplitude_for(np.asarray(friction_levels, dtype=float)))
    return Grating(period, duty, low, high)
