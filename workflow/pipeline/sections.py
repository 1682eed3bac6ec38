"""The sections of ``tactile run``'s configuration as types: one frozen dataclass per section, declared once.

Every key is a field carrying its type, default, unit, help text and, where it has them, its accepted range and
choices (:func:`setting`).  From these declarations come the embedded defaults (:func:`section_defaults`), the
checks of a user's TOML file (:mod:`workflow.pipeline.config`), the command-line options of the same quantities
(``--q``, ``--voltage``, ``--ceramic``, ``--resonator``, ``--glue-um``, ``--piezo``, ``--mixed-plates``:
:func:`workflow.cli.options.key_option`, and ``tactile run``'s overrides of those keys) and the table of keys in
docs/cli.md (:func:`markdown_table`; ``tests/pipeline/test_sections.py`` fails when the two disagree, and
``python -m workflow.pipeline.sections --write docs/cli.md`` writes it again).  Adding a key is one field here.

Defaults that are facts of the domain (Table 1, the procedures' plans, the simulator, the robust design) are read
from where they are defined, through a factory, so that they stay one fact.  Ranges shared with the command-line
options of the same quantity stay in :data:`~workflow.models.limits.LIMITS` under ``section.key`` (or a declared
quantity's name); a field declares only what is its own.
"""

import sys
import typing
from dataclasses import MISSING, dataclass, field, fields, make_dataclass
from functools import partial

from workflow.damping.laws import SAMPLED_LAWS
from workflow.damping.logs import MIXED_PLATES, SAME_PLATE_TOLERANCE
from workflow.models import materials
from workflow.models.builtplate import DEMONSTRATION_DEVIATIONS, SIMULATED_DEVIATIONS
from workflow.models.limits import LIMITS, mm_range
from workflow.models.plate import ORIGINAL_PLATE
from workflow.units import KHZ, MM, UM

TABLE_START = "<!-- configuration keys: generated from workflow/pipeline/sections.py -->"
TABLE_END = "<!-- end of configuration keys -->"
"""The lines around the generated table in docs/cli.md."""


@dataclass(frozen=True)
class Declared:
    """What a configuration key declares beside its type and default.

    Attributes
    ----------
    unit : str
        Its unit as the file writes it ("mm", "kHz", "-" for a number without one, "" for text and switches).
    help : str
        What it sets, one sentence.
    limits : str, tuple, callable or None
        Accepted (low, high), a function that returns them (limits defined where they are enforced), or the
        :data:`~workflow.models.limits.LIMITS` quantity it shares; None: the LIMITS entry ``section.key`` if there
        is one, else any finite number.
    choices : tuple or None
        Accepted values (of each item, for a list).
    not_empty : bool
        A list that needs at least one item.
    """

    unit: str
    help: str
    limits: typing.Any = None
    choices: typing.Any = None
    not_empty: bool = False


def setting(default=MISSING, *, factory=None, unit: str = "", help: str, limits=None, choices=None,
            not_empty: bool = False):
    """A dataclass field of a configuration section: ``default`` (or ``factory()``) and its :class:`Declared`."""
    declared = {"declared": Declared(unit, help, limits, choices, not_empty)}
    if factory is not None:
        return field(default_factory=factory, metadata=declared)
    return field(default=default, metadata=declared)


def _mm(length: float) -> float:
    """A length in metres as the file writes it [mm] (rounded as Table 1 states it)."""
    return round(length / MM, 9)


CERAMIC_CHOICES = mm_range(materials.CERAMIC_THICKNESSES)
"""The ceramic thicknesses a design or map may ask for [mm] (the stock of Table 1)."""


@dataclass(frozen=True)
class DesignSection:
    """[design]: the design problem; defaults to Table 1 (:mod:`workflow.models.materials`)."""

    ceramic_thicknesses_mm: tuple[float, ...] = setting(
        CERAMIC_CHOICES, unit="mm", help="ceramic thicknesses h_p the design is optimised for", choices=CERAMIC_CHOICES,
        not_empty=True)
    wavelength_min_mm: float = setting(factory=lambda: _mm(materials.WAVELENGTH_RANGE[0]), unit="mm",
                                       help="shortest wavelength lambda of the design box")
    wavelength_max_mm: float = setting(factory=lambda: _mm(materials.WAVELENGTH_RANGE[1]), unit="mm",
                                       help="longest wavelength lambda of the design box")
    hi_min_mm: float = setting(factory=lambda: _mm(materials.PRACTICAL_MIN_RESONATOR_THICKNESS), unit="mm",
                               help="thinnest resonator h_i of the design box")
    hi_max_mm: float = setting(factory=lambda: _mm(materials.RESONATOR_THICKNESS_RANGE[1]), unit="mm",
                               help="thickest resonator h_i of the design box")
    width_mm: float = setting(factory=lambda: _mm(ORIGINAL_PLATE.width), unit="mm", help="plate width b")
    voltage_v: float = setting(factory=lambda: materials.DESIGN_VOLTAGE, unit="V",
                               help="drive amplitude across the ceramics (peak)")
    min_frequency_khz: float = setting(factory=lambda: round(materials.MIN_FREQUENCY / KHZ, 9), unit="kHz",
                                       help="lowest resonance frequency a design may have")
    target_deflection_um: float = setting(factory=lambda: round(materials.TARGET_DEFLECTION / UM, 9), unit="µm",
                                          help="deflection the damped design's voltage is solved for")
    q: float = setting(factory=lambda: materials.PLATE_Q, unit="-", help="plate quality factor (constant Q)")
    ceramic: str = setting(factory=lambda: materials.PAPER, choices=materials.ceramic_names(),
                           help="piezo-ceramic material record (docs/model.md; paper: Table 1 of the paper)")
    resonator: str = setting(factory=lambda: materials.PAPER, choices=materials.resonator_names(),
                             help="resonator material record (paper: the paper's CuBe)")
    glue_um: float = setting(0.0, unit="µm", help=(
        f"epoxy bond under each ceramic (0: none, as in the paper); the FEM models it as a layer "
        f"(E {materials.EPOXY.youngs_modulus / 1e9:g} GPa, nu {materials.EPOXY.poisson_ratio:g}, "
        f"{materials.EPOXY.density:g} kg/m^3), the beam model ignores it"))


@dataclass(frozen=True)
class MapsSection:
    """[maps]: the contour maps of w_dyn and f_r over (lambda, h_i)."""

    grid: int = setting(41, unit="-", help="analytical (lambda, h_i) grid, points per axis")
    fem_grid: int = setting(4, unit="-", help="FEM grid, points per axis (the full resolution is an option: e.g. 12)")
    fem_ceramic_thicknesses_mm: tuple[float, ...] = setting(
        (1.0,), unit="mm", help="h_p values for which FEM maps are drawn", choices=CERAMIC_CHOICES)


def _fem_accuracy():
    from workflow.models.fem.accuracy import DEFAULT_ACCURACY

    return DEFAULT_ACCURACY


def _survey_accuracy():
    from workflow.models.fem.accuracy import SURVEY_ACCURACY

    return SURVEY_ACCURACY


FEM_ACCURACY_KEYS = [
    ("accuracy", float, setting(factory=_fem_accuracy, unit="-", help=(
        "target relative frequency error of the original plate, the optima, the designs and the calibrations' and "
        "robust designs' surrogates (0: the fixed mesh below, without an error estimate)"))),
    ("survey_accuracy", float, setting(factory=_survey_accuracy, unit="-",
                                       help="target of the FEM maps and the width sweep (many geometries)")),
]
FEM_RUN_KEYS = [
    ("space_mapping", bool, setting(True,
                                    help="FEM optimum per h_p by space mapping (false: the beam model's design)")),
    ("direct_nlopt", bool, setting(False, help="also the direct NLopt FEM run (slow: tens of FEM evaluations)")),
    ("width_min_mm", float, setting(30.0, unit="mm", help="width sweep of the original plate: coarse range, from")),
    ("width_max_mm", float, setting(100.0, unit="mm", help="width sweep: coarse range, to")),
    ("width_points", int, setting(15, unit="-", help="width sweep: widths in the coarse range")),
    ("fine_width_min_mm", float, setting(45.0, unit="mm", help="width sweep: fine range around 49 mm, from")),
    ("fine_width_max_mm", float, setting(56.0, unit="mm", help="width sweep: fine range, to")),
    ("fine_width_step_mm", float, setting(1.0, unit="mm", help="width sweep: step of the fine range")),
    ("responses", bool, setting(True, help="frequency and transient responses of the original plate")),
]


def _mesh_keys() -> list:
    """The mesh keys of [fem]: the fields of :class:`~workflow.models.fem.FemSettings`, with its defaults; all but the
    modes and the piezo model (which every evaluation uses) only where an accuracy is 0."""
    from workflow.models.fem import FemSettings
    from workflow.models.fem.settings import PIEZO_MODELS

    always = {
        "n_modes": dict(unit="-", help="eigenmodes computed nearest the beam model's resonance"),
        "piezo": dict(help="FEM only: the piezo drive as an eigenstress of a uniform field (eigenstrain, fast, the "
                           "paper's model) or with the electric potential as an unknown (coupled: adds the "
                           "antiresonance, the effective coupling and the admittance)", choices=PIEZO_MODELS),
    }
    hints = typing.get_type_hints(FemSettings)

    def declared(name: str) -> dict:
        return always.get(name) or dict(unit="" if hints[name] is str else "-",
                                        help=f"fixed mesh: FemSettings.{name}, used only where an accuracy is 0")

    return [(f.name, hints[f.name], setting(f.default, **declared(f.name))) for f in fields(FemSettings)]


FemSection = make_dataclass("FemSection", FEM_ACCURACY_KEYS + _mesh_keys() + FEM_RUN_KEYS, frozen=True)
FemSection.__doc__ = """[fem]: accuracy targets, the fixed mesh (where an accuracy is 0) and the width sweep."""
FemSection.__module__ = __name__


@dataclass(frozen=True)
class DampingSection:
    """[damping]: the Q(v) fit (docs/damping.md)."""

    laws: tuple[str, ...] = setting(factory=lambda: tuple(SAMPLED_LAWS),
                                    help="Q(v) laws screened, sampled and compared",
                                    choices=SAMPLED_LAWS, not_empty=True)
    walkers: int = setting(0, unit="-", help="emcee walkers (0: max(32, 2 D + 2) for each law's D sampled parameters)")
    max_steps: int = setting(20000, unit="-", help="longest chain per law")
    softening: bool = setting(True, help="fit the resonance's amplitude softening")
    drift: bool = setting(True, help="fit the drift within each sweep (logs with timestamp_s; else not fitted)")
    heating: bool = setting(True, help="fit the plate's heating within each sweep (logs with timestamp_s)")
    seed: int = setting(7, unit="-", help="random seed of the chains")
    posterior_draws: int = setting(64, unit="-", help="Q(v) draws propagated through the design")
    mixed_plates: str = setting("refuse", choices=MIXED_PLATES, help=(
        f"logs that name different plates in their metadata, or whose resonances are more than "
        f"{SAME_PLATE_TOLERANCE * 100:g} % apart: refuse them, or go on with a warning"))


@dataclass(frozen=True)
class RunSection:
    """[run]: where the work runs and whether it is cached."""

    scheduler: str = setting("", help="tcp://host:port of a Dask scheduler; empty: the local cores")
    cache: bool = setting(True, help="reuse finished steps and FEM evaluations")


def _campaign_plan():
    from instruments.procedures.sweeps import CampaignPlan

    return CampaignPlan


def _ringdown_plan():
    from instruments.procedures.ringdown import RingdownPlan

    return RingdownPlan


def _sweep_sizes() -> tuple:
    from instruments.procedures.sweeps import MAX_POINTS_PER_SWEEP, MIN_POINTS_PER_SWEEP

    return MIN_POINTS_PER_SWEEP, MAX_POINTS_PER_SWEEP


@dataclass(frozen=True)
class CampaignSection:
    """[campaign]: the simulated Q(v) campaign (the procedures' own defaults, instruments/procedures/)."""

    logs: tuple[str, ...] = setting((), help="interferometer logs to fit instead of a simulated campaign")
    voltages_v: tuple[float, ...] = setting(factory=lambda: tuple(_campaign_plan().voltages), unit="V",
                                            help="drive voltage of each sweep", not_empty=True)
    points_per_sweep: int = setting(factory=lambda: _campaign_plan().points_per_sweep, unit="-",
                                    help="frequencies per sweep (all sweeps together within the procedures' limit)",
                                    limits=_sweep_sizes)
    span_hz: float = setting(factory=lambda: _campaign_plan().span, unit="Hz", help="frequency span of each sweep")
    seed: int = setting(0, unit="-", help="random seed of the simulated bench")
    ringdown_voltages_v: tuple[float, ...] = setting(factory=lambda: tuple(_ringdown_plan().voltages), unit="V",
                                                     help="drive voltage of each ring-down (empty: none)")
    ringdown_samples: int = setting(factory=lambda: _ringdown_plan().samples, unit="-",
                                    help="samples of each ring-down record")
    ringdown_interval_us: int = setting(factory=lambda: round(_ringdown_plan().interval * 1e6), unit="µs",
                                        help="interval between a ring-down's samples")


RUN_SOFTENING = 0.08
"""Amplitude softening of the run's simulated plate, kappa in f_r0 (1 - kappa v^2) [s^2/m^2]: 0.4 % at the
working point's 0.23 m/s, small, yet resolved by the fit (the bench simulator's own default is none)."""


def _bench(name: str):
    from dataclasses import fields as dataclass_fields

    from instruments.simulator.bench import BenchSettings

    return next(f.default for f in dataclass_fields(BenchSettings) if f.name == name)


def _low_velocity_q():
    from instruments.simulator.physics import DEFAULT_LOW_VELOCITY_Q

    return DEFAULT_LOW_VELOCITY_Q


def _drift_rate():
    from instruments.simulator.bench import DEFAULT_DRIFT_RATE

    return DEFAULT_DRIFT_RATE


@dataclass(frozen=True)
class _SimulatorKeys:
    low_velocity_q: float = setting(factory=_low_velocity_q, unit="-", help="simulated plate's Q at low velocity")
    working_q: float = setting(factory=lambda: materials.PLATE_Q, unit="-",
                               help="simulated plate's Q at the working velocity")
    drift_hz_per_s: float = setting(factory=_drift_rate, unit="Hz/s", help="drift of the simulated resonance")
    softening_s2_m2: float = setting(RUN_SOFTENING, unit="s²/m²",
                                     help="amplitude softening kappa of the simulated plate")
    amplifier_gain: float = setting(factory=lambda: float(_bench("amplifier_gain")), unit="V/V",
                                    help="simulated power amplifier's gain")
    ceramic_voltage_limit_v: float = setting(factory=lambda: float(_bench("ceramic_voltage_limit")), unit="V",
                                             help="amplifier's limit of the voltage across the ceramics")
    relative_noise: float = setting(factory=lambda: _bench("relative_noise"), unit="-",
                                    help="vibrometer's relative noise")
    floor_fraction: float = setting(factory=lambda: _bench("floor_fraction"), unit="-",
                                    help="vibrometer's noise floor over the working amplitude")
    phase_noise_deg: float = setting(factory=lambda: _bench("phase_noise"), unit="°", help="lock-in's phase noise")


SimulatorSection = make_dataclass(
    "SimulatorSection",
    [(s.config_key, float, setting(factory=partial(s.value, DEMONSTRATION_DEVIATIONS),
                                   unit=s.text.rsplit("[", 1)[1][:-1].replace("um", "µm"),
                                   help="hidden deviation of the loop's simulated built plates: "
                                        + s.text.rsplit(" [", 1)[0],
                                   limits=s.quantity))
     for s in SIMULATED_DEVIATIONS],
    bases=(_SimulatorKeys,), frozen=True)
SimulatorSection.__doc__ = """[simulator]: the simulated bench and plate (instruments/simulator/)."""
SimulatorSection.__module__ = __name__


LOOP_STOCK_MM = (0.75, 0.8, 1.0)
"""Stock h_i of the run's demonstration re-design [mm]: the thicker half of ``tactile optimize``'s default list
(the thinner stocks put a transverse mode within 1-2 % of the working frequency at h_p = 1 mm and are rejected;
leaving them out halves the loop's FEM evaluations)."""


def _reliability():
    from workflow.optimise.robust import RobustSettings

    return RobustSettings().reliability


@dataclass(frozen=True)
class LoopSection:
    """[loop]: the demonstration loop (docs/calibration.md, "The loop in tactile run")."""

    enabled: bool = setting(True, help="build, measure, calibrate and re-design a plate on the simulator")
    hp_mm: float = setting(1.0, unit="mm", help="ceramic thickness of the loop's plates", choices=CERAMIC_CHOICES)
    scan_grid: tuple[int, ...] = setting((7, 3), unit="-", help="deflection scan: [points along x, points across]")
    reliability: float = setting(factory=_reliability, unit="-", help="P(f_r >= the minimum) of the re-design")
    stock_hi_mm: tuple[float, ...] = setting(LOOP_STOCK_MM, unit="mm", help="stock h_i of the re-design",
                                             not_empty=True)
    search_start_khz: float = setting(15.0, unit="kHz", help="where the built plate's resonance search starts")
    case_study: bool = setting(True, help="P1 and P2 predict each other")


def _stock_hi():
    from workflow.pipeline.robust_recommendation import STOCK_HI_MM

    return tuple(STOCK_HI_MM)


def _stocks_per_design():
    from workflow.pipeline.robust_recommendation import STOCKS_PER_DESIGN

    return STOCKS_PER_DESIGN


@dataclass(frozen=True)
class RecommendationSection:
    """[recommendation]: the robust design per h_p under the calibration on the measured built plates."""

    robust: bool = setting(True, help="recommend the robust design per h_p (false: the nominal optima only)")
    published_plates: bool = setting(True, help="calibrate on the published P1 and P2")
    built_plates: tuple[str, ...] = setting((), help="built-plate logs of your own plates to calibrate on too")
    reliability: float = setting(factory=_reliability, unit="-", help="P(f_r >= the minimum) of the robust design")
    stock_hi_mm: tuple[float, ...] = setting(factory=_stock_hi, unit="mm", help="stock h_i the robust design may use",
                                             not_empty=True)
    stocks_per_design: int = setting(factory=_stocks_per_design, unit="-",
                                     help="stocks tried per h_p (those nearest the nominal optimum's h_i)")


SECTIONS = {
    "design": DesignSection,
    "maps": MapsSection,
    "fem": FemSection,
    "damping": DampingSection,
    "run": RunSection,
    "campaign": CampaignSection,
    "simulator": SimulatorSection,
    "loop": LoopSection,
    "recommendation": RecommendationSection,
}
"""The configuration's sections in the order the file and ``--print-config`` write them."""


@dataclass(frozen=True)
class Key:
    """One key of the configuration as the checks and the docs see it."""

    section: str
    name: str
    kind: type
    item: type | None
    default: typing.Any
    declared: Declared

    @property
    def path(self) -> str:
        return f"{self.section}.{self.name}"

    @property
    def limits(self) -> tuple | None:
        """Accepted (low, high) of the value (of each item, for a list), or None."""
        limits = self.declared.limits
        if isinstance(limits, str):
            return LIMITS[limits]
        if callable(limits):
            return limits()
        return limits if limits is not None else LIMITS.get(self.path)


def _as_file_value(value):
    return list(value) if isinstance(value, tuple) else value


def keys(section: str) -> list[Key]:
    """The keys of ``section`` in their order, with their types and defaults."""
    cls = SECTIONS[section]
    hints = typing.get_type_hints(cls)
    defaults = cls()
    found = []
    for f in fields(cls):
        kind = hints[f.name]
        item = typing.get_args(kind)[0] if typing.get_origin(kind) is tuple else None
        found.append(Key(section, f.name, list if item else kind, item, _as_file_value(getattr(defaults, f.name)),
                         f.metadata["declared"]))
    return found


def key(path: str) -> Key:
    """The :class:`Key` of ``path`` ("section.name")."""
    section, name = path.split(".")
    return next(k for k in keys(section) if k.name == name)


def section_defaults() -> dict:
    """The embedded defaults as nested dicts (lists for the list keys), in the file's order."""
    return {section: {key.name: key.default for key in keys(section)} for section in SECTIONS}


def _cell(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return "[" + ", ".join(_cell(v) for v in value) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)


_TYPE_NAMES = {float: "number", int: "integer", str: "text", bool: "true/false"}


def _accepted(key: Key) -> str:
    parts = []
    if key.limits is not None:
        parts.append(f"{_cell(key.limits[0])} to {_cell(key.limits[1])}")
    if key.declared.choices is not None:
        parts.append("one of " + ", ".join(_cell(c) for c in key.declared.choices))
    if key.declared.not_empty:
        parts.append("not empty")
    return "; ".join(parts)


def markdown_table() -> str:
    """The table of every key (section, key, type, default, unit, accepted values, meaning) for docs/cli.md."""
    rows = ["| key | type | default | unit | accepted | what it sets |", "|---|---|---|---|---|---|"]
    for section in SECTIONS:
        for key in keys(section):
            kind = f"list of {_TYPE_NAMES[key.item]}s" if key.item else _TYPE_NAMES[key.kind]
            rows.append(f"| `[{section}] {key.name}` | {kind} | `{_cell(key.default)}` | {key.declared.unit} | "
                        f"{_accepted(key)} | {key.declared.help} |")
    return "\n".join(rows)


def replace_table(text: str) -> str:
    """``text`` (docs/cli.md) with the block between :data:`TABLE_START` and :data:`TABLE_END` generated again."""
    start, end = text.index(TABLE_START) + len(TABLE_START), text.index(TABLE_END)
    return text[:start] + "\n" + markdown_table() + "\n" + text[end:]


if __name__ == "__main__":  # python -m workflow.pipeline.sections [--write docs/cli.md]
    if sys.argv[1:2] == ["--write"]:
        from pathlib import Path

        path = Path(sys.argv[2])
        path.write_text(replace_table(path.read_text(encoding="utf-8")), encoding="utf-8")
    else:
        print(markdown_table())
