"""The run configuration: the embedded defaults, overridden by a user TOML file.

The sections and keys, their types, defaults, units, ranges and choices are declared once, as the frozen dataclasses
of :mod:`workflow.pipeline.sections`; a user file may only use those sections and keys, with values of the declared
type (an int is accepted where a float is expected) inside the declared range.
"""

import copy
import math

from workflow.errors import InputFileError
from workflow.inputfiles import load_toml
from workflow.models.limits import LIMITS
from workflow.models.plate import ORIGINAL_PLATE
from workflow.pipeline.sections import SECTIONS, Key, keys, section_defaults

ORDERED = (
    ("design.wavelength_min_mm", "design.wavelength_max_mm"),
    ("design.hi_min_mm", "design.hi_max_mm"),
    ("fem.width_min_mm", "fem.width_max_mm"),
    ("fem.fine_width_min_mm", "fem.fine_width_max_mm"),
    ("simulator.working_q", "simulator.low_velocity_q"),
)
"""Pairs of keys (low, high) where low must be below high (the law's Q falls from its low-velocity value)."""


def default_config() -> dict:
    """The embedded defaults, as nested dicts (:func:`~workflow.pipeline.sections.section_defaults`)."""
    return section_defaults()


def load_config(path=None) -> dict:
    """The effective configuration: the defaults updated by the TOML file at ``path``.

    Raises
    ------
    InputFileError
        Unreadable, oversized or malformed file (:func:`~workflow.inputfiles.load_toml`), unknown section
        or key, or a value of the wrong type or outside its range, naming the file and the key.
    """
    config = default_config()
    if path is None:
        return config
    user = load_toml(path, str(path))
    return merge(config, user, source=str(path))


def merge(defaults: dict, user: dict, source: str = "configuration") -> dict:
    """``defaults`` updated by ``user``, checking sections, keys, types and the campaign's size."""
    merged = copy.deepcopy(defaults)
    for section, values in user.items():
        if section not in SECTIONS:
            raise InputFileError(f"{source}: unknown section [{section}]; known: {', '.join(SECTIONS)}")
        if not isinstance(values, dict):
            raise InputFileError(f"{source}: '{section}' must be a [section] table")
        declared = {key.name: key for key in keys(section)}
        for name, value in values.items():
            if name not in declared:
                raise InputFileError(
                    f"{source}: unknown key '{section}.{name}'; known keys of [{section}]: {', '.join(declared)}"
                )
            key = declared[name]
            merged[section][name] = _checked(value, key.kind, key.item, key.path, source)
            _check_range(merged[section][name], key, source)
    _check_consistency(merged, source)
    _check_campaign_size(merged["campaign"], source)
    return merged


def _check_campaign_size(campaign: dict, source: str) -> None:
    """Refuse a [campaign] too small or too large to run (the procedures' limits), naming the key."""
    from instruments.procedures.sweeps import PlanError, check_sizes

    points = campaign["points_per_sweep"]
    try:
        check_sizes({"campaign.points_per_sweep": points}, points * len(campaign["voltages_v"]),
                    "campaign.points_per_sweep x campaign.voltages_v")
    except PlanError as error:
        raise InputFileError(f"{source}: {error}") from None


def _check_range(value, key: Key, source: str) -> None:
    """Refuse a non-finite number, or one outside the key's range or choices, naming the key and what is accepted."""
    bounds, choices, name = key.limits, key.declared.choices, key.path
    for item in value if isinstance(value, list) else [value]:
        if isinstance(item, float) and not math.isfinite(item):
            raise InputFileError(f"{source}: '{name}' must be a finite number, got {item!r}")
        if bounds and not bounds[0] <= item <= bounds[1]:
            raise InputFileError(f"{source}: '{name}' = {item!r} is outside the accepted range "
                                 f"{bounds[0]} to {bounds[1]}")
        if choices is not None and item not in choices:
            raise InputFileError(f"{source}: '{name}' holds {item!r}; accepted: {', '.join(map(repr, choices))}")
    if key.declared.not_empty and not value:
        raise InputFileError(f"{source}: '{name}' is empty; it needs at least one value")


def _check_consistency(config: dict, source: str) -> None:
    """Refuse a low bound not below its high bound (:data:`ORDERED`) and FEM mesh keys the FEM refuses (or whose mesh
    of the original plate exceeds the memory budget)."""
    from workflow.errors import TactileError
    from workflow.models.fem import FemSettings
    from workflow.models.fem.mesh import check_memory

    for low, high in ORDERED:
        (section, low_key), (_, high_key) = low.split("."), high.split(".")
        if not config[section][low_key] < config[section][high_key]:
            raise InputFileError(f"{source}: '{low}' = {config[section][low_key]!r} must be below "
                                 f"'{high}' = {config[section][high_key]!r}")
    fem = config["fem"]
    fine = int((fem["fine_width_max_mm"] - fem["fine_width_min_mm"]) / fem["fine_width_step_mm"] + 1e-9) + 1
    if fine > LIMITS["fem.width_points"][1]:
        raise InputFileError(f"{source}: 'fem.fine_width_step_mm' = {fem['fine_width_step_mm']!r} gives {fine} widths from "
                             f"{fem['fine_width_min_mm']:g} to {fem['fine_width_max_mm']:g} mm, more than the "
                             f"{LIMITS['fem.width_points'][1]} of a width sweep")
    if len(config["loop"]["scan_grid"]) != 2:
        raise InputFileError(f"{source}: 'loop.scan_grid' must be [points along x, points across], "
                             f"got {config['loop']['scan_grid']!r}")
    mesh = {name: config["fem"][name] for name in FemSettings().as_dict()}
    try:
        check_memory(ORIGINAL_PLATE, FemSettings(**mesh))
    except TactileError as error:
        raise InputFileError(f"{source}: [fem] {error}") from None


def _checked(value, kind: type, item: type | None, name: str, source: str):
    """``value`` as the declared ``kind`` (a list of ``item``), an int taken for a float; else refused."""
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind is list:
        if not isinstance(value, list):
            raise InputFileError(f"{source}: '{name}' must be a list, got {type(value).__name__} {value!r}")
        return [_checked(entry, item, None, f"{name}[{i}]", source) for i, entry in enumerate(value)]
    if type(value) is not kind:
        raise InputFileError(f"{source}: '{name}' must be {_type_name(kind)}, got {type(value).__name__} {value!r}")
    return value


def _type_name(kind) -> str:
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false"}.get(kind, kind.__name__)


def to_toml(config: dict, comments: bool = False) -> str:
    """The configuration as TOML text (for --print-config); with ``comments`` each key followed by its unit and what
    it sets, as declared (:mod:`workflow.pipeline.sections`)."""
    lines = []
    for section, values in config.items():
        lines.append(f"[{section}]")
        declared = {key.name: key.declared for key in keys(section)} if comments and section in SECTIONS else {}
        for key, value in values.items():
            line = f"{key} = {_toml_value(value)}"
            if key in declared:
                unit = declared[key].unit
                line = f"{line:<40} # {f'[{unit}] ' if unit and unit != '-' else ''}{declared[key].help}"
            lines.append(line)
        lines.append("")
    return "\n".join(lines)


_TOML_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}
"""Characters a TOML basic string escapes by name; the other control characters are written \\uXXXX."""


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + "".join(_TOML_ESCAPES.get(c) or (f"\\u{ord(c):04X}" if ord(c) < 0x20 or ord(c) == 0x7F else c)
                             for c in value) + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)
