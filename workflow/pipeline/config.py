"""The run configuration: embedded defaults, overridden by a user TOML file.

The embedded ``defaults.toml`` is the schema: a user file may only use its sections and
keys, with values of the same type (an int is accepted where a float is expected).
"""

import copy
import math
import sys
from dataclasses import MISSING, fields
from importlib import resources

from workflow.damping.laws import SAMPLED_LAWS
from workflow.damping.logs import MIXED_PLATES
from workflow.errors import InputFileError
from workflow.inputfiles import load_toml
from workflow.models import materials
from workflow.models.limits import LIMITS, mm_range
from workflow.models.plate import ORIGINAL_PLATE
from workflow.units import KHZ, MM, UM

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CHOICES = {
    "damping.laws": SAMPLED_LAWS,
    "damping.mixed_plates": MIXED_PLATES,
    "design.ceramic_thicknesses_mm": mm_range(materials.CERAMIC_THICKNESSES),
    "maps.fem_ceramic_thicknesses_mm": mm_range(materials.CERAMIC_THICKNESSES),
    "loop.hp_mm": mm_range(materials.CERAMIC_THICKNESSES),
}
"""Accepted values of the items of list keys."""

LIST_ITEMS = {"campaign.logs": "", "recommendation.built_plates": ""}
"""An item of each list key whose default is empty, for its type (the logs' paths are strings)."""

NOT_EMPTY = ("damping.laws", "design.ceramic_thicknesses_mm", "campaign.voltages_v", "loop.stock_hi_mm",
             "recommendation.stock_hi_mm")
"""List keys that need at least one item."""

ORDERED = (
    ("design.wavelength_min_mm", "design.wavelength_max_mm"),
    ("design.hi_min_mm", "design.hi_max_mm"),
    ("fem.width_min_mm", "fem.width_max_mm"),
    ("fem.fine_width_min_mm", "fem.fine_width_max_mm"),
    ("simulator.working_q", "simulator.low_velocity_q"),
)
"""Pairs of keys (low, high) where low must be below high (the law's Q falls from its low-velocity value)."""


def default_config() -> dict:
    """The embedded defaults, as nested dicts: Table 1 for [design], ``defaults.toml`` for the rest."""
    embedded = tomllib.loads(resources.files(__package__).joinpath("defaults.toml").read_text(encoding="utf-8"))
    embedded["fem"] = {**fem_defaults(), **embedded["fem"]}
    return {"design": design_defaults(), **embedded, "campaign": campaign_defaults(), "simulator": simulator_defaults(),
            "loop": loop_defaults(), "recommendation": recommendation_defaults()}


def fem_defaults() -> dict:
    """The accuracy and mesh keys of [fem] (:mod:`workflow.models.fem.accuracy`, :class:`workflow.models.fem.FemSettings`)."""
    from workflow.models.fem import FemSettings
    from workflow.models.fem.accuracy import DEFAULT_ACCURACY, SURVEY_ACCURACY

    return {"accuracy": DEFAULT_ACCURACY, "survey_accuracy": SURVEY_ACCURACY, **FemSettings().as_dict()}


def campaign_defaults() -> dict:
    """The [campaign] section from the Q(v) campaign procedure's defaults."""
    from instruments.procedures.sweeps import CampaignPlan

    from instruments.procedures.ringdown import RingdownPlan

    return {
        "logs": [],
        "voltages_v": list(CampaignPlan.voltages),
        "points_per_sweep": CampaignPlan.points_per_sweep,
        "span_hz": CampaignPlan.span,
        "seed": 0,
        "ringdown_voltages_v": list(RingdownPlan.voltages),
        "ringdown_samples": RingdownPlan.samples,
        "ringdown_interval_us": round(RingdownPlan.interval * 1e6),
    }


def simulator_defaults() -> dict:
    """The [simulator] section from the bench simulator's defaults."""
    from instruments.simulator.bench import DEFAULT_DRIFT_RATE, BenchSettings
    from instruments.simulator.physics import DEFAULT_LOW_VELOCITY_Q
    from workflow.models.builtplate import DEMONSTRATION_DEVIATIONS as built
    from workflow.models.builtplate import SIMULATED_DEVIATIONS

    bench = {f.name: f.default for f in fields(BenchSettings) if f.default is not MISSING}
    return {
        "low_velocity_q": DEFAULT_LOW_VELOCITY_Q,
        "working_q": materials.PLATE_Q,
        "drift_hz_per_s": DEFAULT_DRIFT_RATE,
        "softening_s2_m2": RUN_SOFTENING,
        "amplifier_gain": float(bench["amplifier_gain"]),
        "ceramic_voltage_limit_v": float(bench["ceramic_voltage_limit"]),
        "relative_noise": bench["relative_noise"],
        "floor_fraction": bench["floor_fraction"],
        "phase_noise_deg": bench["phase_noise"],
        **{setting.config_key: setting.value(built) for setting in SIMULATED_DEVIATIONS},
    }


RUN_SOFTENING = 0.08
"""Amplitude softening of the run's simulated plate, kappa in f_r0 (1 - kappa v^2) [s^2/m^2]: 0.4 % at the
working point's 0.23 m/s, small, yet resolved by the fit (the bench simulator's own default is none)."""


LOOP_STOCK_MM = (0.75, 0.8, 1.0)
"""Stock h_i of the run's demonstration re-design [mm]: the thicker half of ``tactile optimize``'s default list
(the thinner stocks put a transverse mode within 1-2 % of the working frequency at h_p = 1 mm and are rejected;
leaving them out halves the loop's FEM evaluations)."""


def loop_defaults() -> dict:
    """The [loop] section (docs/calibration.md, "The loop in tactile run"): the robust design's defaults."""
    from workflow.optimise.robust import RobustSettings

    return {
        "enabled": True,
        "hp_mm": 1.0,
        "scan_grid": [7, 3],
        "reliability": RobustSettings().reliability,
        "stock_hi_mm": list(LOOP_STOCK_MM),
        "search_start_khz": 15.0,
        "case_study": True,
    }


def recommendation_defaults() -> dict:
    """The [recommendation] section (docs/calibration.md, "The recommended design in tactile run"): the robust design
    per h_p under the calibration on the measured built plates."""
    from workflow.optimise.robust import RobustSettings
    from workflow.pipeline.robust_recommendation import STOCK_HI_MM, STOCKS_PER_DESIGN

    return {
        "robust": True,
        "published_plates": True,
        "built_plates": [],
        "reliability": RobustSettings().reliability,
        "stock_hi_mm": list(STOCK_HI_MM),
        "stocks_per_design": STOCKS_PER_DESIGN,
    }


def design_defaults() -> dict:
    """The [design] section from Table 1 (:mod:`workflow.models.materials`), in the units of the file."""
    mm = [t / MM for t in materials.CERAMIC_THICKNESSES]
    section = {
        "ceramic_thicknesses_mm": mm,
        "wavelength_min_mm": materials.WAVELENGTH_RANGE[0] / MM,
        "wavelength_max_mm": materials.WAVELENGTH_RANGE[1] / MM,
        "hi_min_mm": materials.PRACTICAL_MIN_RESONATOR_THICKNESS / MM,
        "hi_max_mm": materials.RESONATOR_THICKNESS_RANGE[1] / MM,
        "width_mm": ORIGINAL_PLATE.width / MM,
        "voltage_v": materials.DESIGN_VOLTAGE,
        "min_frequency_khz": materials.MIN_FREQUENCY / KHZ,
        "target_deflection_um": materials.TARGET_DEFLECTION / UM,
        "q": materials.PLATE_Q,
    }
    section = {key: [round(v, 9) for v in value] if isinstance(value, list) else round(value, 9) for key, value in section.items()}
    return {**section, "ceramic": materials.PAPER, "resonator": materials.PAPER, "glue_um": 0.0}


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
        if section not in defaults:
            raise InputFileError(f"{source}: unknown section [{section}]; known: {', '.join(defaults)}")
        if not isinstance(values, dict):
            raise InputFileError(f"{source}: '{section}' must be a [section] table")
        for key, value in values.items():
            if key not in defaults[section]:
                raise InputFileError(
                    f"{source}: unknown key '{section}.{key}'; known keys of [{section}]: {', '.join(defaults[section])}"
                )
            merged[section][key] = _checked(value, defaults[section][key], f"{section}.{key}", source)
            _check_range(merged[section][key], f"{section}.{key}", source)
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


def _limits(name: str):
    """(low, high) of the key ``name`` (section.key): its :data:`LIMITS`, or those of the deviation it sets."""
    from workflow.models.builtplate import SIMULATED_DEVIATIONS

    deviations = {f"simulator.{setting.config_key}": setting.quantity for setting in SIMULATED_DEVIATIONS}
    return LIMITS.get(name) or LIMITS.get(deviations.get(name, ""))


def _check_range(value, name: str, source: str) -> None:
    """Refuse a non-finite number, or one outside its :data:`LIMITS`, naming the key and the range."""
    bounds = _limits(name)
    for item in value if isinstance(value, list) else [value]:
        if isinstance(item, float) and not math.isfinite(item):
            raise InputFileError(f"{source}: '{name}' must be a finite number, got {item!r}")
        if bounds and not bounds[0] <= item <= bounds[1]:
            raise InputFileError(f"{source}: '{name}' = {item!r} is outside the accepted range "
                                 f"{bounds[0]} to {bounds[1]}")
        if name in CHOICES and item not in CHOICES[name]:
            raise InputFileError(f"{source}: '{name}' holds {item!r}; accepted: {', '.join(map(repr, CHOICES[name]))}")
    if name in NOT_EMPTY and not value:
        raise InputFileError(f"{source}: '{name}' is empty; it needs at least one value")


def _check_consistency(config: dict, source: str) -> None:
    """Refuse a low bound not below its high bound (:data:`ORDERED`), FEM mesh keys the FEM refuses (or whose mesh
    of the original plate exceeds the memory budget) and material records that do not exist."""
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
    for kind, lookup in (("ceramic", materials.ceramic), ("resonator", materials.resonator)):
        try:
            lookup(config["design"][kind])
        except TactileError as error:
            raise InputFileError(f"{source}: [design] {kind}: {error}") from None


def _checked(value, default, name: str, source: str):
    expected = type(default)
    if expected is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, list):
        if not isinstance(value, list):
            raise InputFileError(f"{source}: '{name}' must be a list, got {type(value).__name__} {value!r}")
        item = default[0] if default else LIST_ITEMS[name]
        return [_checked(entry, item, f"{name}[{i}]", source) for i, entry in enumerate(value)]
    if type(value) is not expected:
        raise InputFileError(f"{source}: '{name}' must be {_type_name(expected)}, got {type(value).__name__} {value!r}")
    return value


def _type_name(kind) -> str:
    return {float: "a number", int: "an integer", str: "a string", bool: "true or false"}.get(kind, kind.__name__)


def to_toml(config: dict) -> str:
    """The configuration as TOML text (for --print-config)."""
    lines = []
    for section, values in config.items():
        lines.append(f"[{section}]")
        lines.extend(f"{key} = {_toml_value(value)}" for key, value in values.items())
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
