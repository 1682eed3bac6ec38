"""Command-line options shared by several commands, their conversion to SI, and stop signals as an exception.

The one module that command modules share: no command module imports another.
"""

import argparse
import math
import signal
from contextlib import contextmanager

from workflow.damping.laws import law_parameters
from workflow.damping.posterior import load_posterior
from workflow.errors import GeometryError, TactileError
from workflow.models import materials
from workflow.models.analytical import resonance_frequency
from workflow.models.fem.accuracy import ACCURACY_RANGE, DEFAULT_ACCURACY, SIMULATION_ACCURACY_TARGET, FemAccuracy
from workflow.pipeline.design_models import DESIGN_MODELS
from workflow.models.limits import LIMITS, point_problem, problem, unit
from workflow.models.plate import ORIGINAL_PLATE, Plate, check_design_space
from workflow.optimise.problem import DesignProblem
from workflow.units import KHZ, MM, UM

MODELS = tuple(DESIGN_MODELS)


def finite_float(text: str) -> float:
    """argparse type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def bounded(kind, low, high, unit: str = ""):
    """argparse type: a finite ``kind`` (float or int) in [low, high], the range named in the error."""
    unit = f" {unit}" if unit else ""

    def convert(text: str):
        try:
            value = kind(text)
        except ValueError:
            expected = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(
                f"{text} is outside the accepted range {_number(low)} to {_number(high)}{unit}"
            )
        return value

    return convert


def limit_text(key: str, unit: str = "") -> str:
    """The accepted range of a :data:`~workflow.pipeline.config.LIMITS` key for --help, e.g. ``"0.001 to 1000 V"``."""
    return range_text(LIMITS[key], unit)


def range_text(limits: tuple, unit: str = "") -> str:
    """``(low, high)`` for --help, e.g. ``"0.001 to 1000 V"``."""
    low, high = limits
    return f"{_number(low)} to {_number(high)}" + (f" {unit}" if unit else "")


def _number(value) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


def seed_option(parser, default: int, help: str) -> None:
    """A ``--seed`` option in the accepted range of numpy's seeds."""
    parser.add_argument("--seed", type=bounded(int, *LIMITS["campaign.seed"]), default=default,
                        help=f"{help}, {limit_text('campaign.seed')} (default {default})")


def add_force_option(parser, what: str = "files in --out") -> None:
    """``--force``: overwrite ``what`` even where tactile did not write it (docs/cli.md, "Output folders")."""
    parser.add_argument(
        "--force",
        action="store_true",
        help=f"overwrite {what} that tactile did not write (or that changed since); without it the "
        "command refuses them before any work",
    )


def add_mixed_plates_option(parser: argparse.ArgumentParser, overrides: bool = False) -> None:
    """``--mixed-plates refuse|warn``: logs that are not of one plate (their metadata or their resonances)."""
    key_option(parser, "damping.mixed_plates", overrides=overrides)


def add_model_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", choices=MODELS, default="analytical", help="plate model (default: analytical)")


def add_ceramic_option(parser: argparse.ArgumentParser, required: bool) -> None:
    sizes = ", ".join(f"{t / MM:g}" for t in materials.CERAMIC_THICKNESSES)
    parser.add_argument(
        "--hp-mm",
        type=positive_float,
        required=required,
        help=f"ceramic thickness h_p [mm], one of {sizes}" + ("" if required else " (default: all)"),
    )


def add_width_option(parser: argparse.ArgumentParser) -> None:
    """``--b-mm``: the configuration's ``[design] width_mm``."""
    key_option(parser, "design.width_mm", "--b-mm", metavar="B")


def key_option(parser: argparse.ArgumentParser, path: str, flag: str | None = None, overrides: bool = False,
               metavar: str | None = None) -> None:
    """An option declared by the configuration key ``path`` ("section.name", :mod:`workflow.pipeline.sections`): its
    type, range, choices, default and help; ``flag`` defaults to the key's name (``--glue-um`` for ``glue_um``).

    With ``overrides`` it defaults to None: the value of the run's configuration is kept (:func:`override_config`).
    """
    from workflow.pipeline.sections import key as declared_key

    key = declared_key(path)
    unit = "" if key.declared.unit in ("", "-") else key.declared.unit
    if key.limits is not None:
        kind, accepted = bounded(key.kind, *key.limits, unit), ", " + range_text(key.limits, unit)
    else:
        kind, accepted = (finite_float if key.kind is float else key.kind), f" [{unit}]" if unit else ""
    shown = _number(key.default) if isinstance(key.default, (int, float)) else key.default
    default = f"the configuration's [{key.section}] {key.name}, {shown}" if overrides else shown
    parser.add_argument(
        flag or "--" + key.name.replace("_", "-"),
        type=kind,
        choices=key.declared.choices,
        default=None if overrides else key.default,
        metavar=metavar,
        help=f"{key.declared.help}{accepted} (default: {default})".replace("%", "%%"),
    )


def add_drive_options(parser: argparse.ArgumentParser) -> None:
    """--q (the plate's quality factor) and --voltage."""
    key_option(parser, "design.q")
    key_option(parser, "design.voltage_v", "--voltage")


def add_hi_min_option(parser: argparse.ArgumentParser) -> None:
    """``--hi-min-mm``: the configuration's ``[design] hi_min_mm``."""
    key_option(parser, "design.hi_min_mm", metavar="H")


def plate_from_args(args) -> Plate:
    """The plate named by --lambda-mm, --hi-mm, --hp-mm, --b-mm, checked against Table 1."""
    plate = build_plate(args).with_(
        wavelength=args.lambda_mm * MM,
        resonator_thickness=args.hi_mm * MM,
        ceramic_thickness=args.hp_mm * MM,
        width=args.b_mm * MM,
    )
    return check_design_space(plate)


def ceramic_thicknesses(args) -> tuple:
    """The h_p values [m] asked for: the one given by --hp-mm, else all commercial sizes."""
    return materials.CERAMIC_THICKNESSES if args.hp_mm is None else (args.hp_mm * MM,)


def design_problem(args, ceramic_thickness: float) -> DesignProblem:
    """The optimisation problem for one h_p from --b-mm, --hi-min-mm and --voltage."""
    hi_min = args.hi_min_mm * MM
    high = materials.RESONATOR_THICKNESS_RANGE[1]
    if hi_min >= high:  # the parser checked the declared range; the box must keep some thickness above the minimum
        raise GeometryError(f"--hi-min-mm {args.hi_min_mm:g} leaves no resonator thickness to optimise: give less than "
                            f"{high / MM:g} mm")
    return DesignProblem(
        ceramic_thickness=ceramic_thickness,
        width=args.b_mm * MM,
        voltage=getattr(args, "voltage", materials.DESIGN_VOLTAGE),
        min_resonator_thickness=hi_min,
        build=build_plate(args) if hasattr(args, "ceramic") else ORIGINAL_PLATE,
    )


def add_build_options(parser: argparse.ArgumentParser, overrides: bool = False) -> None:
    """--ceramic, --resonator, --glue-um: what the plate is made of (material records, bond).

    With ``overrides`` they default to None: the value of the run's configuration is kept.
    """
    for name in BUILD_KEYS:
        key_option(parser, name, overrides=overrides, metavar="T" if name == "design.glue_um" else None)


BUILD_KEYS = ("design.ceramic", "design.resonator", "design.glue_um")
"""The configuration keys of the build options."""
RUN_OVERRIDES = {"fem.accuracy": "accuracy", "fem.piezo": "piezo", "design.ceramic": "ceramic",
                 "design.resonator": "resonator", "design.glue_um": "glue_um", "damping.mixed_plates": "mixed_plates"}
"""The configuration keys ``tactile run``'s options override -> the options' names in the parsed arguments."""


def build_plate(args) -> Plate:
    """The paper's plate made of the materials and bond of --ceramic, --resonator, --glue-um."""
    return ORIGINAL_PLATE.with_(
        ceramic=materials.ceramic(args.ceramic),
        resonator=materials.resonator(args.resonator),
        glue_thickness=args.glue_um * UM,
    )


def add_fem_options(
    parser: argparse.ArgumentParser, overrides: bool = False, accuracy: float = DEFAULT_ACCURACY, build: bool = True
) -> None:
    """--accuracy and --piezo (the FEM's target relative frequency error and piezo model), and the build options
    unless ``build`` is False (a command whose inputs name the materials).

    With ``overrides`` they default to None: the value of the run's configuration is kept;
    otherwise --accuracy defaults to ``accuracy``.
    """
    kept = " (default: the configuration's [fem] value, {})" if overrides else " (default: {})"
    key_option(parser, "fem.piezo", overrides=overrides)
    if build:
        add_build_options(parser, overrides)
    low, high = ACCURACY_RANGE
    parser.add_argument(
        "--accuracy",
        type=bounded(float, low, high),
        default=None if overrides else accuracy,
        metavar="REL",
        help=f"FEM only: target relative frequency error, {low:g} to {high:g}; the mesh follows the geometry and is "
        "refined until the estimated error meets it" + kept.format(f"{accuracy:g}, i.e. {accuracy * 100:g} %%"),
    )


def override_config(config: dict, args) -> dict:
    """The run's configuration with the FEM, build and --mixed-plates options given on the command line."""
    for path, option in RUN_OVERRIDES.items():
        section, name = path.split(".")
        if getattr(args, option) is not None:
            config[section][name] = getattr(args, option)
    return config


def fem_accuracy(args) -> FemAccuracy:
    """The FEM accuracy and piezo model asked for by --accuracy and --piezo."""
    return FemAccuracy(target=args.accuracy, piezo=args.piezo)


def accuracy_line(error) -> str:
    """An FEM :class:`~workflow.models.fem.accuracy.ErrorEstimate` for people."""
    verdict = "met" if error.met else "NOT met (finest mesh reached)"
    return (
        f"  FEM accuracy: f_r {error.frequency * 100:+.2f} %, w_dyn {error.deflection * 100:+.2f} % "
        f"(estimated error of the values above, mesh level {error.level}; target {error.target * 100:g} % {verdict})"
    )


def add_json_flag(parser: argparse.ArgumentParser) -> None:
    """The common ``--json`` flag."""
    parser.add_argument("--json", action="store_true", help="print one JSON object on the last line of stdout")


def add_damping_option(parser: argparse.ArgumentParser) -> None:
    """The ``--damping POSTERIOR`` option: design with the fitted Q(v) instead of a constant Q."""
    parser.add_argument(
        "--damping",
        metavar="POSTERIOR",
        help="posterior.npz (or its folder) from 'tactile fit-damping': use the posterior-median Q(v) law, "
        "solved self-consistently, instead of a constant Q",
    )


def load_damping(args):
    """The :class:`~workflow.damping.posterior.DampingPosterior` named by ``--damping``, or None."""
    path = getattr(args, "damping", None)
    return None if path is None else load_posterior(path)


def describe_law(name: str, parameters: dict) -> str:
    """A Q(v) law for people, e.g. ``"quadratic law, Q0 150, alpha 0.254 s^2/m^2"``."""
    from workflow.damping.fit import parameter_unit

    items = [f"{name} law"]
    for key, value in parameters.items():
        unit = parameter_unit(name, key)
        items.append(f"{'Q0' if key == 'q0' else key} {value:.4g}" + ("" if unit == "-" else f" {unit}"))
    return ", ".join(items)


def damping_line(values) -> str:
    """A :class:`~workflow.optimise.damped.QOfV` for people: the Q(v) law used, the Q the plate settles at, and the
    voltage for the target deflection with its 90 % interval (over draws of the whole posterior)."""
    law, posterior = values.law, values.posterior
    v05, v50, v95 = values.required_voltage
    median = ("posterior median of" if posterior.law_name == law.name
              else "posterior median of the mixture's most frequent law in")
    return (
        f"  Q(v) used: {describe_law(law.name, law_parameters(law))} ({median} {posterior.source}); "
        f"Q settles at {values.quality_factor:.1f}; {v50:.2f} V for {values.target / UM:g} µm "
        f"(90 %: {v05:.2f} to {v95:.2f} V)"
    )


def add_bench_arguments(parser) -> None:
    """Flags that configure a simulated bench (shared with ``tactile measure --simulate``)."""
    group = parser.add_argument_group("simulated bench")
    seed_option(group, 0, "seed of the measurement noise")
    group.add_argument("--drop-rate", type=float, default=0.0, help="probability of a dropped reply (default 0)")
    group.add_argument("--garble-rate", type=float, default=0.0, help="probability of a garbled reply (default 0)")
    group.add_argument("--disconnect-at", type=int, default=None, metavar="N",
                       help="cut the line at the N-th command (once; default never)")
    group.add_argument("--faulty", choices=("generator", "vibrometer", "lockin"), default=None,
                       help="drop and garble the replies of this instrument only (default: of all)")
    group.add_argument("--bench-limit", type=bounded(float, *LIMITS["simulator.ceramic_voltage_limit_v"], "V"),
                       default=None, metavar="VOLTS",
                       help="the simulated generator's own limit, peak volts across the ceramics, "
                       f"{limit_text('simulator.ceramic_voltage_limit_v', 'V')} (default 30)")
    group.add_argument("--softening", type=bounded(float, *LIMITS["softening_s2_m2"], "s^2/m^2"), default=0.0,
                       metavar="KAPPA", help="amplitude softening of the simulated resonance, f_r (1 - KAPPA v^2) with v "
                       f"the antinode velocity, {limit_text('softening_s2_m2', 's^2/m^2')} (default 0: none)")
    group.add_argument("--no-heating", action="store_true",
                       help="the simulated plate does not warm with the power it dissipates (default: it does)")
    group.add_argument("--thermal-factor", type=bounded(float, 0.0, 100.0), default=1.0, metavar="K",
                       help="multiply the simulated plate's frequency coefficient (-1.75e-4 /K, CuBe) by K: a stress "
                       "case of the hold, 0 to 100 (default 1)")
    group.add_argument("--point-mm", type=_point, default=(0.0, 0.0), metavar="X,Y",
                       help="where the simulated vibrometer points on the paper's plate, from its centre [mm] (default "
                       "0,0: an antinode; a built plate's spot is moved by its scanner instead)")


def _point(text: str) -> tuple:
    """``X,Y`` in millimetres -> (x, y) [mm]."""
    try:
        x, y = (float(item) for item in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in millimetres, e.g. 3,0; got {text!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"expected finite millimetres, got {text!r}")
    return x, y


def add_built_plate_arguments(parser) -> None:
    """The built plate's nominal design (written to logs) and, for the simulator, its hidden deviations."""
    from workflow.models.builtplate import DEMONSTRATION_DEVIATIONS as demo
    from workflow.models.builtplate import SIMULATED_DEVIATIONS

    group = parser.add_argument_group(
        "built plate",
        "the measured plate's nominal design, written to the log's metadata (# lambda_mm, # h_i_mm, ...; "
        "docs/log-format.md); with --simulate the simulator plays it as built, with hidden deviations (the "
        "FEM of the deviated plate; docs/instruments.md)",
    )
    for flag, key, text in (("--lambda-mm", "lambda_mm", "nominal wavelength lambda [mm] (with --hi-mm, --hp-mm)"),
                            ("--hi-mm", "h_i_mm", "nominal resonator thickness h_i [mm]"),
                            ("--hp-mm", "h_p_mm", "nominal ceramic thickness h_p [mm]"),
                            ("--b-mm", "b_mm", f"width b [mm] (default {ORIGINAL_PLATE.width / MM:g})")):
        group.add_argument(flag, type=bounded(float, *LIMITS[key], "mm"), help=f"{text}, {limit_text(key, 'mm')}")
    group.add_argument("--ceramic", choices=materials.ceramic_names(), help="ceramic record (default: the paper's)")
    group.add_argument("--resonator", choices=materials.resonator_names(), help="resonator record (default: the paper's)")
    group.add_argument("--glue-um", type=bounded(float, *LIMITS["glue_um"], "um"), metavar="T",
                       help="nominal bond thickness [um] (default: not stated; the model then has no bond)")
    group.add_argument("--deviations", choices=("demo", "none"), default="demo",
                       help="simulator: the built plate's hidden deviations, the documented demonstration set or "
                       "none (default demo); the --dev-* flags override single values")
    for setting in SIMULATED_DEVIATIONS:
        key = setting.quantity
        group.add_argument(setting.option, type=bounded(float, *LIMITS[key], unit(key)),
                           help=f"simulator: {setting.text}, {limit_text(key, unit(key))} (demo {setting.value(demo):g})")
    default = SIMULATION_ACCURACY_TARGET
    group.add_argument("--sim-accuracy", type=bounded(float, *ACCURACY_RANGE), default=default, metavar="REL",
                       help="FEM accuracy of the simulated built plate and of the nominal map a scan is compared "
                       f"with (default {default:g})")


def built_plate_from_args(args):
    """The :class:`~workflow.models.builtplate.BuiltPlate` of --lambda-mm, --hi-mm, --hp-mm, ..., or None if not given.

    Raises
    ------
    TactileError
        Only some of the three given; a geometry :class:`~workflow.models.plate.Plate` refuses; a beam-model
        resonance outside the plausible frequencies (:data:`~workflow.models.limits.LIMITS`).
    """
    from workflow.models.builtplate import BuiltPlate

    geometry = {flag: getattr(args, flag.lstrip("-").replace("-", "_"), None) for flag in ("--lambda-mm", "--hi-mm", "--hp-mm")}
    given = [flag for flag, value in geometry.items() if value is not None]
    if not given:
        return None
    if len(given) < len(geometry):
        missing = [flag for flag in geometry if flag not in given]
        raise TactileError(f"a built plate needs --lambda-mm, --hi-mm and --hp-mm; {', '.join(missing)} missing")
    width = args.b_mm if args.b_mm is not None else ORIGINAL_PLATE.width / MM
    glue = None if args.glue_um is None else args.glue_um * UM
    built = BuiltPlate(args.lambda_mm * MM, args.hi_mm * MM, args.hp_mm * MM, width * MM, args.ceramic, args.resonator, glue)
    implausible = problem("frequency_hz", float(resonance_frequency(built.plate())), name="its beam-model resonance")
    if implausible:
        raise TactileError(f"the built plate of --lambda-mm, --hi-mm, --hp-mm, --b-mm is no tactile plate: {implausible}")
    return built


def deviations_from_args(args):
    """The simulated built plate's :class:`~workflow.models.builtplate.PlateDeviations` of --deviations and --dev-*
    (each within its plausible range: the options' types)."""
    from workflow.models.builtplate import (
        DEMONSTRATION_DEVIATIONS,
        SIMULATED_DEVIATIONS,
        PlateDeviations,
        deviations_from_settings,
    )

    base = DEMONSTRATION_DEVIATIONS if args.deviations == "demo" else PlateDeviations()
    return deviations_from_settings({s.name: getattr(args, s.dest) for s in SIMULATED_DEVIATIONS}, base)


def built_plate_model(args, built, deviations=None):
    """The FEM of ``built`` (a BuiltPlate) with ``deviations`` (default none) at --sim-accuracy, from the disk cache."""
    from workflow.execution.cache import EvaluationCache
    from workflow.models.builtplate import PlateDeviations
    from workflow.pipeline.builtplate import built_plate_model as cached_model

    return cached_model(built.plate(), deviations or PlateDeviations(), FemAccuracy(target=args.sim_accuracy),
                        EvaluationCache())


def bench_settings(args):
    """BenchSettings from the flags of :func:`add_bench_arguments` (and ``--amplifier-gain`` if present); a built
    plate from those of :func:`add_built_plate_arguments` when they name one."""
    from instruments.drivers.amplifier import DEFAULT_CERAMIC_VOLTAGE_LIMIT, DEFAULT_GAIN
    from instruments.simulator import FaultSettings, default_bench_settings
    from instruments.simulator.bench import built_bench_settings

    try:
        faults = FaultSettings(args.drop_rate, args.garble_rate, args.disconnect_at, seed=args.seed,
                               instruments=None if args.faulty is None else (args.faulty,))
    except ValueError as error:
        raise TactileError(f"bad fault flag: {error}") from None
    limit = DEFAULT_CERAMIC_VOLTAGE_LIMIT if args.bench_limit is None else args.bench_limit
    gain = getattr(args, "amplifier_gain", DEFAULT_GAIN)
    fields = dict(seed=args.seed, faults=faults, ceramic_voltage_limit=limit, amplifier_gain=gain)
    built = built_plate_from_args(args) if hasattr(args, "deviations") else None
    if built is not None:
        if args.point_mm != (0.0, 0.0):
            raise TactileError("--point-mm points the paper's plate; a built plate's spot is moved by its scanner "
                               "('tactile measure scan --points')")
        return _heated(built_bench_settings(built_plate_model(args, built, deviations_from_args(args)), **fields), args)
    point = tuple(value * MM for value in args.point_mm)
    off = point_problem(ORIGINAL_PLATE, *point)
    if off:
        raise TactileError(f"--point-mm {args.point_mm[0]:g},{args.point_mm[1]:g}: {off}")
    try:
        settings = default_bench_settings(**fields, softening=args.softening, measurement_point=point)
        settings.mode_factor()
    except ValueError as error:
        raise TactileError(f"--point-mm {args.point_mm[0]:g},{args.point_mm[1]:g}: {error}") from None
    return _heated(settings, args)


def _heated(settings, args):
    """``settings`` with the plate's heating of --no-heating and --thermal-factor."""
    from dataclasses import replace

    thermal = settings.response.thermal
    thermal = None if args.no_heating or thermal is None else thermal.scaled(args.thermal_factor)
    return replace(settings, response=replace(settings.response, thermal=thermal))


# Stop signals as an exception, so that a command's cleanup (the bench's output off) runs on each.
#
# By default SIGTERM and SIGHUP end Python at once, skipping every ``finally``; a service
# stop or a CI timeout sends SIGTERM.  Inside :class:`StopSignals` the first SIGINT, SIGTERM
# or SIGHUP raises :class:`Stopped` instead, later ones are ignored so that they cannot cut
# the cleanup short, and :meth:`StopSignals.held` defers them around a cleanup that must
# finish.  SIGKILL cannot be caught: nothing runs then.

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class Stopped(BaseException):
    """A stop signal arrived (a BaseException, like KeyboardInterrupt: no ``except Exception`` swallows it).

    Attributes
    ----------
    signum : int
    outcome : str
        What the command did about it (e.g. the output switched off), for the one-line message.
    """

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        self.outcome = ""

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_status(self) -> int:
        """128 + the signal number, the shell's convention (130 SIGINT, 129 SIGHUP, 143 SIGTERM)."""
        return 128 + self.signum


class StopSignals:
    """Context manager: SIGINT/SIGTERM/SIGHUP raise :class:`Stopped` inside; the previous handlers come back after."""

    def __init__(self):
        self.received = None
        self._holding = False
        self._previous = {}

    def __enter__(self):
        for signum in STOP_SIGNALS:
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc):
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        return False

    def _handle(self, signum, frame):
        if self.received is not None:
            return
        self.received = signum
        if not self._holding:
            raise Stopped(signum)

    @contextmanager
    def held(self):
        """Defer a stop signal until the block ends (then :class:`Stopped` is raised, unless one already was)."""
        pending, self._holding = self.received is None, True
        try:
            yield
        finally:
            self._holding = False
        if pending and self.received is not None:
            raise Stopped(self.received)


def add_calibration_option(parser: argparse.ArgumentParser) -> None:
    """``--calibration FILE``: predict with the posterior of 'tactile calibrate' instead of the nominal model."""
    parser.add_argument(
        "--calibration",
        metavar="FILE",
        help="calibration.json (or its folder) from 'tactile calibrate': FEM predictions become posterior medians "
        "with 5-95 %% intervals, through a surrogate built at each geometry (docs/calibration.md)",
    )


def load_calibration_option(args):
    """The :class:`~workflow.calibration.calibration.Calibration` named by ``--calibration``, or None."""
    from workflow.pipeline.calibration_files import load_calibration

    path = getattr(args, "calibration", None)
    return None if path is None else load_calibration(path)


def calibration_fem_model(calibration, q: float, voltage: float):
    """The cached, in-process FEM at the calibration's accuracy and piezo model, driven at ``q`` and ``voltage``."""
    from workflow.pipeline.calibration_files import calibration_accuracy

    return command_fem_model(q, voltage, calibration_accuracy(calibration.fem), scheduler="synchronous")


def design_model(args, scheduler=None):
    """The ``--model`` of a design command at --q and --voltage (the FEM at --accuracy and --piezo, cached, on
    ``scheduler``) (:mod:`workflow.pipeline.design_models`)."""
    return DESIGN_MODELS[args.model].for_command(
        args.q, args.voltage, lambda: command_fem_model(args.q, args.voltage, fem_accuracy(args), scheduler))


def command_fem_model(q: float, voltage: float, settings, scheduler=None):
    """The FEM of a command: cached on disk, progress on stderr, at ``q`` [-], ``voltage`` [V peak] and ``settings``
    (an accuracy or a mesh); ``scheduler`` as :func:`~workflow.execution.parallel.map_evaluations` takes it."""
    from workflow.execution.cache import EvaluationCache
    from workflow.optimise.fem_model import FemModel

    return FemModel(q=q, voltage=voltage, settings=settings, cache=EvaluationCache(), scheduler=scheduler, progress=True)


def calibration_line(prediction, source: str) -> str:
    """A calibrated :class:`~workflow.calibration.calibration.Prediction` for people (the calibration read from
    ``source``)."""
    (f05, f50, f95), (w05, w50, w95) = prediction.frequency / KHZ, prediction.deflection / UM
    surrogate = prediction.surrogate
    return (
        f"  calibrated ({source}): f_r {f50:.3f} kHz (90 %: {f05:.3f} to {f95:.3f}), w_dyn {w50:.4f} µm (90 %: "
        f"{w05:.4f} to {w95:.4f}); surrogate error {surrogate.log_frequency.loo_rms * 100:.2f} % from "
        f"{surrogate.evaluations} FEM evaluations"
    )


def _levels(text: str) -> tuple:
    """``LOW,HIGH`` -> two finite numbers (order checked by the caller)."""
    try:
        values = tuple(float(item) for item in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 2 or not all(map(math.isfinite, values)):
        raise argparse.ArgumentTypeError(f"expected two numbers LOW,HIGH, got {text!r}")
    return values


def add_texture_arguments(parser) -> None:
    """The texture (a grating or a profile, in amplitude or in friction) and the finger's motion (docs/rendering.md)."""
    from workflow.models.materials import MIN_USEFUL_DEFLECTION, TARGET_DEFLECTION
    from workflow.pipeline.texture_files import FRICTION_COLUMNS, PROFILE_COLUMNS, TRACE_COLUMNS
    from workflow.rendering.synthesis import ERROR_TARGET

    group = parser.add_argument_group("texture and finger", "a grating (default) or a profile, in deflection amplitude "
                                      "or, with --friction-curve, in friction ratio; the finger at a constant speed or "
                                      "along a recorded trace")
    texture = group.add_mutually_exclusive_group()
    texture.add_argument("--period-mm", type=positive_float, help="a grating of this spatial period [mm] (default 2)")
    texture.add_argument("--profile", metavar="CSV", help=f"a profile along the stroke: columns {','.join(PROFILE_COLUMNS)} "
                         "(or position_mm,friction with --friction-curve), linear between rows")
    group.add_argument("--duty", type=bounded(float, 0.01, 0.99), default=0.5,
                       help="grating: share of each period at the high amplitude, 0.01 to 0.99 (default 0.5)")
    default_levels = f"{MIN_USEFUL_DEFLECTION / UM:g},{TARGET_DEFLECTION / UM:g}"
    group.add_argument("--levels-um", type=_levels, default=(MIN_USEFUL_DEFLECTION / UM, TARGET_DEFLECTION / UM),
                       metavar="LOW,HIGH", help=f"grating: the two antinode deflection amplitudes [um], 0 <= LOW < HIGH "
                       f"(default {default_levels}: the least useful friction reduction and the nominal target)")
    group.add_argument("--friction-curve", metavar="CSV", help=f"your measured friction ratio against amplitude: columns "
                       f"{','.join(FRICTION_COLUMNS)}, friction strictly monotonic (interpolated monotonically, PCHIP)")
    group.add_argument("--levels-friction", type=_levels, metavar="F1,F2",
                       help="grating: the two friction ratios instead of --levels-um (needs --friction-curve)")
    finger = group.add_mutually_exclusive_group()
    finger.add_argument("--speed-mm-s", type=positive_float, help="finger speed [mm/s] (default 100)")
    finger.add_argument("--trace", metavar="CSV", help=f"recorded finger motion: columns {','.join(TRACE_COLUMNS)}, "
                        "time strictly increasing")
    group.add_argument("--error", type=bounded(float, 1e-3, 1.0), default=ERROR_TARGET,
                       help=f"envelope error (RMS over the texture's swing) within which a grating period counts as "
                       f"rendered, for the smallest period reported, 0.001 to 1 (default {ERROR_TARGET:g})")


def add_rendering_arguments(parser) -> None:
    """The plate's envelope model for rendering: ``--damping`` or a constant ``--q``, and the carrier."""
    group = parser.add_argument_group("envelope model", "the plate's envelope dynamics (docs/rendering.md): the "
                                      "posterior-median Q(v) of --damping, with the gain, resonance and softening of "
                                      "its fit.json, or the beam model of the plate with a constant Q")
    group.add_argument("--damping", metavar="POSTERIOR",
                       help="posterior.npz (or its folder) from 'tactile fit-damping': its posterior-median Q(v), and the "
                       "gain, resonance and softening of the fit.json beside it (a fit describes the plate it measured)")
    group.add_argument("--q", type=bounded(float, *LIMITS["design.q"]), default=materials.PLATE_Q,
                       help=f"constant quality factor without --damping, {limit_text('design.q')} "
                       f"(default {materials.PLATE_Q:g})")
    group.add_argument("--carrier-hz", type=positive_float,
                       help="carrier frequency [Hz] (default: the resonance at the texture's highest amplitude)")


def texture_and_motion(args) -> tuple:
    """The texture and finger motion of :func:`add_texture_arguments`' flags."""
    from workflow.pipeline.texture_files import grating_from_friction, read_friction_curve, read_profile, read_trace
    from workflow.rendering.textures import ConstantSpeed, Grating

    curve = read_friction_curve(args.friction_curve) if args.friction_curve else None
    if args.levels_friction is not None and curve is None:
        raise TactileError("--levels-friction needs --friction-curve (your measured friction against amplitude)")
    if args.profile is not None:
        texture = read_profile(args.profile, curve)
    else:
        period = (args.period_mm or 2.0) * MM
        if args.levels_friction is not None:
            texture = grating_from_friction(period, args.duty, args.levels_friction, curve)
        else:
            low, high = args.levels_um
            if not 0 <= low < high:
                raise TactileError(f"--levels-um needs 0 <= LOW < HIGH, got {low:g},{high:g}")
            texture = Grating(period, args.duty, low * UM, high * UM)
    motion = read_trace(args.trace) if args.trace else ConstantSpeed((args.speed_mm_s or 100.0) * MM)
    return texture, motion


def describe_texture(texture, motion) -> dict:
    """The texture and motion as flat ``texture_*`` keys (log metadata, JSON)."""
    from workflow.rendering.textures import Grating, Trace, loop_duration

    keys = {"texture_loop_s": loop_duration(texture, motion),
            "texture_levels_um": [level / UM for level in texture.levels]}
    if isinstance(texture, Grating):
        keys.update(texture_kind="grating", texture_period_mm=texture.period / MM, texture_duty=texture.duty)
    else:
        keys.update(texture_kind="profile", texture_points=len(texture.position))
    if isinstance(motion, Trace):
        keys.update(texture_finger="trace", texture_finger_samples=len(motion.time))
    keys["texture_speed_mm_s"] = motion.typical_speed / MM
    return keys


def rendering_model(args, plate):
    """The :class:`~workflow.pipeline.rendering.PlateEnvelope` of --damping or --q for ``plate``, with --carrier-hz."""
    from workflow.pipeline.rendering import plate_envelope

    envelope = plate_envelope(plate, args.q, args.damping)
    if args.carrier_hz is not None:
        envelope = type(envelope)(envelope.model.with_carrier(args.carrier_hz), envelope.source)
    return envelope
