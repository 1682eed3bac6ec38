"""``tactile measure``: run a bench procedure on serial ports or on the in-process simulator.

Logs go under ``measurements/`` in the working directory by default (ignored by git, so a
measurement never lands among the repository's tracked files); running the same command
again resumes its log.  Whatever ends the run (its end, an error, SIGINT, SIGTERM, SIGHUP)
the generator is left with its output off at its lowest amplitude (docs/safety.md).
"""

import argparse
import glob
import math
import sys
from contextlib import contextmanager
from pathlib import Path

from instruments.drivers.amplifier import DEFAULT_CERAMIC_VOLTAGE_LIMIT, DEFAULT_GAIN
from instruments.procedures.hold import DEFAULT_START_VOLTAGE
from instruments.procedures.render import RenderPlan
from instruments.procedures.ringdown import RINGDOWN_INTERVAL_ASKED, RingdownPlan
from instruments.procedures.sweeps import CampaignPlan, ResonancePlan, VoltageSweepPlan
from instruments.procedures.readout import DEFAULT_TIME_CONSTANT
from instruments.procedures.scan import DEFAULT_GRID, DEFAULT_MARGIN, DEFAULT_VOLTAGE
from workflow.cli.options import (
    Stopped,
    StopSignals,
    add_bench_arguments,
    add_damping_option,
    add_force_option,
    add_built_plate_arguments,
    add_json_flag,
    add_rendering_arguments,
    add_texture_arguments,
    bench_settings,
    bounded,
    limit_text,
    built_plate_from_args,
    built_plate_model,
    describe_texture,
    load_damping,
    rendering_model,
    texture_and_motion,
)
from workflow.errors import TactileError
from workflow.models.limits import LIMITS, point_problem
from workflow.models.materials import PLATE_Q
from workflow.pipeline.outputs import output_folder, save_figure
from workflow.units import MM

DEFAULT_DATA_DIR = Path("measurements")
"""Folder of the logs when --out is not given, relative to the working directory."""
PROCEDURES = ("resonance", "campaign", "voltage-sweep", "scan", "ringdown", "render", "hold")
INSTRUMENT_BAUD_RATE = 115200
"""Default serial rate of the vibrometer controller and the lock-in (their factory setting) [baud]."""


VOLTAGE = bounded(float, *LIMITS["campaign.voltages_v"], "V")
"""argparse type of a drive voltage [V peak across the ceramics]."""


def _voltages(text: str) -> tuple:
    """Comma-separated drive voltages, each in the range of :data:`VOLTAGE`."""
    try:
        return tuple(VOLTAGE(item) for item in text.split(","))
    except argparse.ArgumentTypeError as error:
        raise argparse.ArgumentTypeError(f"expected comma-separated volts, e.g. 2.5,5,7.5: {error}") from None


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "measure",
        help="run a bench procedure (resonance, campaign, voltage-sweep, scan, ringdown, render, hold) and log it",
        description="Run a measurement procedure against serial ports (--generator/--vibrometer/--lockin) or the in-process "
        "simulator (--simulate). Each point is appended to a CSV log (docs/log-format.md) at once, by default "
        f"{DEFAULT_DATA_DIR}/<procedure>.csv in the working directory (a folder git ignores); rerunning the "
        "same command resumes an interrupted log. One process writes a log at a time (a second one is refused, "
        "naming the first's pid); a refused instrument setting stops the run before its point is logged.",
    )
    procedures = parser.add_subparsers(dest="procedure", metavar="PROCEDURE", parser_class=type(parser))
    procedures.required = True
    common = argparse.ArgumentParser(add_help=False)
    ports = common.add_argument_group("instruments")
    ports.add_argument("--generator", metavar="PORT", help="serial port (or pyserial URL) of the signal generator")
    ports.add_argument("--vibrometer", metavar="PORT", help="serial port (or pyserial URL) of the vibrometer controller")
    ports.add_argument("--lockin", metavar="PORT", help="serial port (or pyserial URL) of the lock-in amplifier (SR860)")
    ports.add_argument("--simulate", action="store_true", help="use the in-process bench simulator instead of ports")
    ports.add_argument("--baudrate", type=bounded(int, 50, 4_000_000), default=9600,
                       help="the generator's serial baud rate, 50 to 4000000 (default 9600)")
    for name in ("vibrometer", "lockin"):
        ports.add_argument(f"--{name}-baudrate", type=bounded(int, 50, 4_000_000), default=INSTRUMENT_BAUD_RATE,
                           help=f"the {name}'s serial baud rate (default {INSTRUMENT_BAUD_RATE})")
    ports.add_argument("--time-constant", type=bounded(float, 1e-6, 30e3, "s"), default=DEFAULT_TIME_CONSTANT,
                       metavar="SECONDS", help="lock-in time constant of the readings (the nearest SR860 value; each "
                       f"reading waits for it to settle), 1e-6 to 30000 s (default {DEFAULT_TIME_CONSTANT:g})")
    ports.add_argument("--temperature-aux", type=int, choices=(1, 2, 3, 4), metavar="N",
                       help="the lock-in's Aux In carrying the plate's temperature sensor (5 mV/degC), 1 to 4 (default: "
                       "none on real ports; the simulator's is on 1)")
    ports.add_argument("--timeout", type=bounded(float, 0.001, 3600.0, "s"), default=1.0,
                       help="reply timeout [s], 0.001 to 3600 (default 1)")
    ports.add_argument("--retries", type=bounded(int, 0, 100), default=3,
                       help="retries of a point after a timeout or garbled reply, 0 to 100 (default 3)")
    ports.add_argument("--amplifier-gain", type=bounded(float, *LIMITS["amplifier_gain"]), default=DEFAULT_GAIN,
                       help=f"power amplifier voltage gain, {limit_text('amplifier_gain')} (default {DEFAULT_GAIN:g})")
    ports.add_argument("--max-voltage", type=bounded(float, *LIMITS["simulator.ceramic_voltage_limit_v"], "V"),
                       default=DEFAULT_CERAMIC_VOLTAGE_LIMIT, metavar="VOLTS",
                       help=f"safety limit, peak volts across the ceramics, {limit_text('simulator.ceramic_voltage_limit_v', 'V')} "
                       f"(default {DEFAULT_CERAMIC_VOLTAGE_LIMIT:g})")
    ports.add_argument("--out", type=Path, help=f"log file (default: {DEFAULT_DATA_DIR}/<procedure>.csv in the working "
                       "directory, a folder git ignores; the path is printed at the end)")
    add_force_option(ports, "a scan's figure (--figure)")
    ports.add_argument("--restart", action="store_true", help="overwrite an existing log tactile wrote instead of resuming it (any other file is never overwritten nor appended to: the command refuses it)")
    add_bench_arguments(common)
    add_built_plate_arguments(common)
    add_json_flag(common)

    resonance = procedures.add_parser("resonance", parents=[common], help="coarse then fine sweep to find f_r",
                                      description="Find the resonance: a coarse sweep then a fine one around its peak.")
    _add_search_flags(resonance, ResonancePlan.start, ResonancePlan.coarse_points)
    resonance.add_argument("--voltage", type=VOLTAGE, default=ResonancePlan.voltage,
                           help=f"drive, peak volts across the ceramics (default {ResonancePlan.voltage:g})")

    campaign = procedures.add_parser("campaign", parents=[common], help="Q(v) campaign: sweeps at several voltages",
                                     description="Frequency sweeps around the resonance at several drive voltages "
                                     "(sweep id = voltage index). Without --center-hz the centre comes from the log "
                                     "being resumed or from a resonance search logged to <out>-resonance.csv.")
    campaign.add_argument("--voltages", type=_voltages, default=CampaignPlan.voltages,
                          help=f"peak volts across the ceramics, comma-separated (default {_listed(CampaignPlan.voltages)})")
    campaign.add_argument("--points", type=int, default=CampaignPlan.points_per_sweep,
                          help="frequency points per sweep, 3 to 10000; at most 100000 points in all "
                          f"(default {CampaignPlan.points_per_sweep})")
    campaign.add_argument("--span-hz", type=bounded(float, *LIMITS["campaign.span_hz"], "Hz"), default=CampaignPlan.span,
                          help=f"sweep width [Hz], {limit_text('campaign.span_hz', 'Hz')} (default {CampaignPlan.span:g})")
    campaign.add_argument("--center-hz", type=float, help="sweep centre [Hz] (default: see above)")
    campaign.add_argument("--alternate", action="store_true",
                          help="odd sweeps downward in frequency (default: every sweep upward): separates a drift of the "
                          "resonance from Q and narrows the fit's bands, which the laws' shape error then exceeds "
                          "(docs/damping.md); a log made with it resumes only with it")

    sweep = procedures.add_parser("voltage-sweep", parents=[common], help="deflection versus voltage at resonance",
                                  description="Velocity and deflection at one frequency for several voltages. Without "
                                  "--frequency-hz the frequency comes from the log being resumed or from a resonance "
                                  "search logged to <out>-resonance.csv.")
    sweep.add_argument("--voltages", type=_voltages, default=VoltageSweepPlan.voltages,
                       help="peak volts across the ceramics, comma-separated, at most 100000 (default 1,2,...,15)")
    sweep.add_argument("--frequency-hz", type=float, help="drive frequency [Hz] (default: see above)")
    ring = procedures.add_parser("ringdown", parents=[common], help="free decays after bursts at resonance",
                                 description="One burst per level at the resonance (33500 burst mode, bus trigger), "
                                 "then the lock-in's capture of the free decay; one row per sample, with "
                                 "the plate temperature where the bench reports it (docs/log-format.md). Without "
                                 "--frequency-hz the frequency comes from the log being resumed or from a resonance "
                                 "search logged to <out>-resonance.csv.")
    ring.add_argument("--voltages", type=_voltages, default=RingdownPlan.voltages,
                      help=f"burst levels, peak volts across the ceramics, comma-separated (default {_listed(RingdownPlan.voltages)})")
    ring.add_argument("--frequency-hz", type=float, help="burst frequency [Hz] (default: see above)")
    ring.add_argument("--cycles", type=bounded(int, 1, 100_000_000), default=RingdownPlan.cycles,
                      help=f"cycles per burst, 1 to 100000000 (default {RingdownPlan.cycles})")
    ring.add_argument("--samples", type=bounded(int, 2, 256), default=RingdownPlan.samples,
                      help=f"envelope samples after each burst, 2 to 256 (default {RingdownPlan.samples})")
    ring.add_argument("--interval-us", type=bounded(float, 0.8, 1_000_000.0, "us"), default=RINGDOWN_INTERVAL_ASKED * 1e6,
                      help="time between samples [us], taken to the lock-in's nearest capture interval 2^k x 0.8 us "
                      f"(default {RINGDOWN_INTERVAL_ASKED * 1e6:g}: {RingdownPlan.interval * 1e6:g})")
    scan = procedures.add_parser(
        "scan", parents=[common], help="deflection map: the laser spot moved over a grid of points at resonance",
        description="Drive the plate at one frequency and voltage and measure the velocity at each point of a grid "
        "covering the plate (the vibrometer's scanner; docs/instruments.md). Needs the built plate (--lambda-mm, "
        "--hi-mm, --hp-mm [--b-mm]) for its extent. Without --frequency-hz the frequency comes from the log being "
        "resumed or from a resonance search (the --start-hz ... flags) logged to <out>-resonance.csv. Writes a "
        "figure of the measured map beside the FEM's map of the nominal plate, with their MAC.")
    scan.add_argument("--grid", type=int, nargs=2, default=DEFAULT_GRID, metavar=("NX", "NY"),
                      help=f"points along x and y (default {DEFAULT_GRID[0]} {DEFAULT_GRID[1]})")
    scan.add_argument("--points", type=_points, help="explicit points instead of --grid: 'x:y,x:y,...' [mm from the centre]")
    scan.add_argument("--margin-mm", type=float, default=DEFAULT_MARGIN / MM,
                      help=f"distance of the outer grid points from the edges [mm] (default {DEFAULT_MARGIN / MM:g})")
    scan.add_argument("--voltage", type=VOLTAGE, default=DEFAULT_VOLTAGE,
                      help=f"drive, peak volts across the ceramics (default {DEFAULT_VOLTAGE:g})")
    scan.add_argument("--frequency-hz", type=float, help="drive frequency [Hz] (default: see above)")
    _add_search_flags(scan, 15e3, 101)
    scan.add_argument("--figure", type=Path, help="the map figure (default: <out> with .png)")
    render = procedures.add_parser(
        "render", parents=[common], help="play a texture's drive, plain and pre-compensated, and record the envelope",
        description="Render a texture on the bench (docs/rendering.md): its drive computed as by 'tactile render' "
        "(the envelope model's resonance set to the measured one) is played as the generator's amplitude modulation "
        "by an arbitrary waveform, first plain switching then pre-compensated, and the velocity envelope is captured "
        "after each; the log holds the captures with the drive, wanted and predicted envelopes, and the texture, "
        "model and drives in its metadata. Without --frequency-hz the resonance comes from the log being resumed or "
        "from a resonance search (the --start-hz ... flags) logged to <out>-resonance.csv. Writes a figure of the "
        "two playbacks side by side, and prints the envelope errors, rise and fall times and the contrast per period.")
    add_texture_arguments(render)
    add_rendering_arguments(render)
    render.add_argument("--frequency-hz", type=float, help="the plate's small-amplitude resonance [Hz] (default: see above)")
    _add_search_flags(render, 15e3, 101)
    render.add_argument("--loops", type=bounded(float, 0.1, 100.0), default=2.0,
                        help="loops of the drive each capture spans (256 samples), 0.1 to 100 (default 2)")
    render.add_argument("--settle-s", type=bounded(float, 0.0, 60.0, "s"), default=RenderPlan.settle,
                        help=f"time the drive loops before each capture [s], 0 to 60 (default {RenderPlan.settle:g})")
    render.add_argument("--figure", type=Path, help="the comparison figure (default: <out> with .png)")
    hold = procedures.add_parser(
        "hold", parents=[common], help="hold the plate at resonance and at a target amplitude (closed loop)",
        description="Hold the plate at its resonance and at a target velocity (or deflection) for a given time: a "
        "phase-locked loop on the lock-in's phase tracks the resonance while the plate warms, a PI loop sets the drive "
        "(never above --max-voltage), both with gains from the Q(v) law (--damping, else a constant --q). Logs time, "
        "frequency, drive, velocity, phase and temperature every --interval-s; on a lost lock, an overload or a lost "
        "connection the output goes off and the log says why. Without --frequency-hz the start frequency comes from "
        "the log being resumed or from a resonance search logged to <out>-resonance.csv. Writes a figure of the hold.")
    target = hold.add_mutually_exclusive_group()
    target.add_argument("--velocity-m-s", type=bounded(float, 1e-6, 10.0, "m/s"),
                        help="target velocity amplitude at the laser spot [m/s]")
    target.add_argument("--deflection-um", type=bounded(float, 1e-3, 1000.0, "um"),
                        help="target deflection amplitude [um] (velocity 2 pi f w at the start frequency; default: the "
                        "plate's working deflection, the beam model at 15 V with Q 54)")
    hold.add_argument("--duration-s", type=bounded(float, 1.0, 7 * 86400.0, "s"), default=600.0,
                      help="hold time [s] (default 600)")
    hold.add_argument("--interval-s", type=bounded(float, 0.01, 3600.0, "s"), default=1.0,
                      help="time between logged samples [s], at least the loop period (default 1)")
    hold.add_argument("--open-loop", action="store_true", help="freeze frequency and drive once locked (the comparison)")
    hold.add_argument("--start-voltage", type=VOLTAGE, default=DEFAULT_START_VOLTAGE,
                      help=f"drive the loop starts from, peak volts across the ceramics (default {DEFAULT_START_VOLTAGE:g})")
    add_damping_option(hold)
    hold.add_argument("--q", type=bounded(float, *LIMITS["design.q"]), default=PLATE_Q,
                      help=f"constant quality factor of the gains without --damping (default {PLATE_Q:g})")
    hold.add_argument("--frequency-hz", type=float, help="start frequency [Hz] (default: see above)")
    _add_search_flags(hold, 15e3, 101)
    hold.add_argument("--figure", type=Path, help="the hold's figure (default: <out> with .png)")
    for sub in (resonance, campaign, sweep, scan, ring, render, hold):
        sub.set_defaults(handler=run)


def _listed(values) -> str:
    """Volts as a help text lists them: 2.5,5,7.5."""
    return ",".join(f"{v:g}" for v in values)


def _add_search_flags(parser, start: float, coarse: int) -> None:
    """The flags of a resonance search's plan."""
    parser.add_argument("--start-hz", type=float, default=start, help=f"coarse sweep start [Hz] (default {start:g})")
    parser.add_argument("--stop-hz", type=float, default=ResonancePlan.stop,
                        help=f"coarse sweep stop [Hz] (default {ResonancePlan.stop:g})")
    parser.add_argument("--coarse-points", type=int, default=coarse,
                        help=f"points of the coarse sweep, 3 to 10000 (default {coarse})")
    parser.add_argument("--fine-points", type=int, default=ResonancePlan.fine_points,
                        help=f"points of the fine sweep, 3 to 10000 (default {ResonancePlan.fine_points})")


def _points(text: str) -> tuple:
    try:
        points = tuple(tuple(float(v) * MM for v in item.split(":")) for item in text.split(","))
    except ValueError:
        points = ((),)
    if not points or any(len(point) != 2 or not all(map(math.isfinite, point)) for point in points):
        raise argparse.ArgumentTypeError(f"expected points as x:y,x:y,... in mm, got {text!r}")
    return points


def _open_station(args):
    """(station, extra log metadata) for real ports or the simulator."""
    import serial

    from instruments.drivers.amplifier import PowerAmplifier
    from instruments.procedures.simulated import simulated_station, simulation_metadata
    from instruments.procedures.sweeps import open_station
    from instruments.simulator import register_url_handler

    options = {"retries": args.retries, "time_constant": args.time_constant}
    if args.temperature_aux is not None:
        options["temperature_aux"] = args.temperature_aux
    if args.simulate:
        if args.generator or args.vibrometer or args.lockin:
            raise TactileError("give either --simulate or --generator/--vibrometer/--lockin, not both")
        settings = bench_settings(args)
        station, _ = simulated_station(settings, args.max_voltage, settle_time=0.0, **options)
        return station, simulation_metadata(settings)
    built = built_plate_from_args(args)
    if not (args.generator and args.vibrometer and args.lockin):
        raise TactileError("need --generator PORT, --vibrometer PORT and --lockin PORT (or --simulate)")
    register_url_handler()
    ports = []
    for flag, name, baudrate in (("--generator", args.generator, args.baudrate),
                                 ("--vibrometer", args.vibrometer, args.vibrometer_baudrate),
                                 ("--lockin", args.lockin, args.lockin_baudrate)):
        try:
            ports.append(serial.serial_for_url(name, baudrate=baudrate, timeout=args.timeout))
        except (serial.SerialException, ValueError, OSError) as error:
            raise TactileError(f"cannot open {flag} {name}: {error}") from None
    metadata = {"simulated": "no", **({} if built is None else built.metadata())}
    return open_station(*ports, PowerAmplifier(args.amplifier_gain), args.max_voltage, **options), metadata


def _centre(args, station, metadata, out: Path, key: str) -> float:
    """The frequency a campaign or voltage sweep is centred on (see ``working_frequency``)."""
    from instruments.procedures.sweeps import working_frequency

    from instruments.procedures.sweeps import ResonancePlan

    searched = ("scan", "render", "hold")
    plan = ResonancePlan(args.start_hz, args.stop_hz, args.coarse_points, args.fine_points) if args.procedure in searched else ResonancePlan()
    frequency, search = working_frequency(station, out, key, metadata, args.restart, plan)
    for warning in () if search is None else search.warnings:
        print(f"tactile measure: warning: {warning}", file=sys.stderr)
    if search is not None and not args.json:
        print(f"resonance search: {frequency:.1f} Hz; log: {search.path}")
    return frequency


def _check_plan_flags(args) -> None:
    from instruments.procedures.sweeps import check_sizes

    positive = {flag: getattr(args, flag.lstrip("-").replace("-", "_"), None)
                for flag in ("--start-hz", "--stop-hz", "--voltage", "--span-hz", "--center-hz", "--frequency-hz")}
    for flag, value in positive.items():
        if value is not None and not value > 0:
            raise TactileError(f"{flag} must be positive, got {value:g}")
    if args.procedure in ("resonance", "scan", "render", "hold"):
        sweeps = {"--coarse-points": args.coarse_points, "--fine-points": args.fine_points}
        check_sizes(sweeps, sum(sweeps.values()), "--coarse-points + --fine-points")
    if args.procedure == "scan":
        built = built_plate_from_args(args)
        if built is None:
            raise TactileError("a scan needs the plate: give --lambda-mm, --hi-mm and --hp-mm (and --b-mm)")
        for x, y in args.points or ():
            off = point_problem(built.plate(), x, y)
            if off:
                raise TactileError(f"--points: {off}")
        if args.points is None and min(args.grid) < 1:
            raise TactileError(f"--grid needs at least 1 point along each axis, got {args.grid[0]} {args.grid[1]}")
        check_sizes({}, len(args.points) if args.points else args.grid[0] * args.grid[1], "scan points")
    elif args.procedure == "campaign":
        check_sizes({"--points": args.points}, args.points * len(args.voltages), "--points x --voltages")
    elif args.procedure == "ringdown":
        check_sizes({}, args.samples * len(args.voltages), "--samples x --voltages")
    elif args.procedure == "voltage-sweep":
        check_sizes({}, len(args.voltages), "--voltages")
    if args.procedure in ("resonance", "scan", "render", "hold") and not args.start_hz < args.stop_hz:
        raise TactileError(f"--start-hz {args.start_hz:g} must be below --stop-hz {args.stop_hz:g}")


def run(args):
    from instruments.procedures.logwriter import exclusive

    _check_plan_flags(args)
    out = args.out or DEFAULT_DATA_DIR / f"{args.procedure}.csv"
    with exclusive(out), _figure_output(args, out) as figure:
        with StopSignals() as signals:
            station, metadata = _open_station(args)
            try:
                result = _measure(args, station, metadata, out)
            except BaseException as error:
                problem = _shut_down(station, signals)
                if isinstance(error, Stopped):
                    error.outcome = problem or "generator output off (OUTP 0, lowest amplitude)"
                raise
            _shut_down(station, signals)
        if figure is not None:
            figures = {"scan": lambda: _scan_figure(args, result.path, figure),
                       "render": lambda: _render_comparison(result.path, figure),
                       "hold": lambda: _hold_figure(result, figure)}
            compared = figures[result.procedure]()
    summary = {
        "log": str(result.path),
        "procedure": result.procedure,
        "planned": result.planned,
        "measured": result.measured,
        "resumed": result.resumed,
        "truncated_bytes": result.truncated_bytes,
        "warnings": list(result.warnings),
        **result.summary,
    }
    for warning in result.warnings:
        print(f"tactile measure: warning: {warning}", file=sys.stderr)
    if figure is not None:
        summary.update(compared)
    if not args.json:
        print(f"{result.procedure}: {result.measured} points measured, {result.resumed} already logged "
              f"({result.planned} planned); log: {result.path}")
        _print_summary(result.procedure, summary)
    return summary


def _measure(args, station, metadata: dict, out: Path):
    """Run the chosen procedure; its :class:`ProcedureResult`."""
    from instruments.procedures import sweeps as procedures

    if args.procedure == "resonance":
        plan = procedures.ResonancePlan(args.start_hz, args.stop_hz, args.coarse_points, args.fine_points, args.voltage)
        return procedures.resonance_search(station, out, plan, metadata, args.restart)
    if args.procedure == "campaign":
        centre = args.center_hz or _centre(args, station, metadata, out, "center_frequency")
        plan = procedures.CampaignPlan(centre, args.span_hz, args.points, args.voltages, args.alternate)
        return procedures.q_campaign(station, out, plan, metadata, args.restart)
    if args.procedure == "scan":
        return _scan(args, station, metadata, out)
    frequency = args.frequency_hz or _centre(args, station, metadata, out, "frequency")
    if args.procedure == "render":
        return _render(args, station, metadata, out, frequency)
    if args.procedure == "hold":
        return _hold(args, station, metadata, out, frequency)
    if args.procedure == "ringdown":
        from instruments.drivers.lockin import capture_interval
        from instruments.procedures.ringdown import ringdown

        interval = capture_interval(args.interval_us * 1e-6)
        if not args.json and abs(interval / (args.interval_us * 1e-6) - 1) > 1e-9:
            print(f"ring-down samples every {interval * 1e6:g} us (the lock-in's capture interval nearest "
                  f"{args.interval_us:g} us)")
        plan = RingdownPlan(frequency, args.voltages, args.cycles, args.samples, interval)
        return ringdown(station, out, plan, metadata, args.restart)
    plan = procedures.VoltageSweepPlan(frequency, args.voltages)
    return procedures.voltage_sweep(station, out, plan, metadata, args.restart)


def _scan(args, station, metadata: dict, out: Path):
    """The deflection scan over --grid or --points of the built plate."""
    from instruments.procedures.scan import ScanPlan, deflection_scan, grid_points

    plate = built_plate_from_args(args).plate()
    points = args.points
    if points is None:
        try:
            points = grid_points(float(plate.length) / 2, float(plate.width) / 2, *args.grid, args.margin_mm * MM)
        except ValueError as error:
            raise TactileError(f"--margin-mm: {error}") from None
    frequency = args.frequency_hz or _centre(args, station, metadata, out, "frequency")
    return deflection_scan(station, out, ScanPlan(frequency, args.voltage, points), metadata, args.restart)


@contextmanager
def _figure_output(args, log: Path):
    """Context manager: the figure path of a scan or a render (None for the other procedures), checked before any
    measurement.

    The figure may replace only a file tactile wrote there (the folder's record of its outputs,
    :mod:`workflow.pipeline.outputs`) unless ``--force``; it may be neither the log, nor its resonance log.
    """
    if args.procedure not in ("scan", "render", "hold"):
        yield None
        return
    from matplotlib.backend_bases import FigureCanvasBase

    from instruments.procedures.sweeps import resonance_log_path

    figure, option = args.figure or log.with_suffix(".png"), "--figure"
    if figure.is_dir():
        raise TactileError(f"{option} {figure}: is a folder; give the figure's file name")
    formats = FigureCanvasBase.get_supported_filetypes()
    if figure.suffix.lower().lstrip(".") not in formats:
        raise TactileError(f"{option} {figure}: the figure needs a file name ending in one of "
                           f"{', '.join('.' + name for name in sorted(formats))}")
    if figure.resolve() in {log.resolve(), resonance_log_path(log).resolve()}:
        raise TactileError(f"{option} {figure}: the figure would replace the {args.procedure}'s log; give another {option}")
    with output_folder(figure.parent, [glob.escape(figure.name)], force=args.force, option=option) as folder:
        yield folder / figure.name


def _scan_figure(args, log: Path, path: Path) -> dict:
    """Compare a scan with the FEM's map of the nominal plate: write the figure at ``path``; its path, the MAC and
    the FEM's f_r."""
    from workflow.pipeline.builtplate import read_scan, scan_mac
    from workflow.pipeline.figures.scan import scan_figure

    scan = read_scan(log)
    nominal = built_plate_model(args, scan.plate)
    mac = scan_mac(scan, nominal)
    return {"mac": mac, "figure": save_figure(scan_figure(scan, nominal, mac), path), "nominal_fem_frequency_hz": nominal.resonance_frequency}


def _render(args, station, metadata: dict, out: Path, frequency: float):
    """Play the texture's plain and pre-compensated drives on the plate whose small-amplitude resonance is ``frequency``."""
    from workflow.models.plate import ORIGINAL_PLATE
    from workflow.pipeline.render_logs import measure_rendering

    built = built_plate_from_args(args)
    envelope = rendering_model(args, built.plate() if built else ORIGINAL_PLATE)
    texture, motion = texture_and_motion(args)
    return measure_rendering(station, out, texture, motion, envelope, frequency, args.loops, args.settle_s,
                             {**metadata, **describe_texture(texture, motion)}, args.restart)


def _hold(args, station, metadata: dict, out: Path, frequency: float):
    """Hold the target of --velocity-m-s or --deflection-um (default: the plate's working deflection) from ``frequency``."""
    from instruments.drivers.lockin import settle_time
    from instruments.procedures.hold import HoldPlan, hold
    from instruments.procedures.readout import DEFAULT_FILTER_POLES, SETTLE_TOLERANCE
    from workflow.damping.laws import ConstantQ
    from workflow.models import analytical
    from workflow.models.materials import DESIGN_VOLTAGE
    from workflow.models.plate import ORIGINAL_PLATE

    built = built_plate_from_args(args)
    plate = built.plate() if built else ORIGINAL_PLATE
    if args.velocity_m_s is not None:
        velocity = args.velocity_m_s
    else:
        deflection = (args.deflection_um * 1e-6 if args.deflection_um is not None
                      else PLATE_Q * float(analytical.deflection_per_volt_per_q(plate)) * DESIGN_VOLTAGE)
        velocity = 2 * math.pi * frequency * deflection
    damping = load_damping(args)
    law = ConstantQ(args.q) if damping is None else damping.median_law()
    period = settle_time(station.readout.time_constant, DEFAULT_FILTER_POLES, SETTLE_TOLERANCE)
    if args.interval_s < period:
        raise TactileError(f"--interval-s {args.interval_s:g} is shorter than the loop period {period:.3g} s "
                           "(the lock-in's settling at --time-constant)")
    plan = HoldPlan(frequency, velocity, args.duration_s, args.interval_s, law, not args.open_loop, args.start_voltage)
    return hold(station, out, plan, metadata, args.restart)


def _hold_figure(result, path: Path) -> dict:
    """The hold's figure (velocity, frequency, drive and temperature against time) at ``path``, drawn again only
    when the hold measured something (a rerun with nothing left to hold keeps it)."""
    from workflow.pipeline.hold_logs import hold_figure_file

    if not result.measured and path.exists():
        return {"figure": str(path)}
    return hold_figure_file([result.path], path)


def _render_comparison(log: Path, path: Path) -> dict:
    """Compare a render log's captures with the wanted and predicted envelopes; the side-by-side figure at ``path``."""
    from workflow.pipeline.render_logs import comparison_figure_file

    return comparison_figure_file(log, path)


def _shut_down(station, signals: StopSignals) -> str | None:
    """Leave the generator safe, deferring stop signals meanwhile; a warning on stderr if it cannot be confirmed.

    Returns None when ``OUTP?`` confirmed the output off, else the warning.
    """
    with signals.held():
        problem = station.shutdown()
    if problem is None:
        return None
    warning = f"cannot confirm the generator output is off ({problem}): switch it off at the instrument"
    print(f"tactile measure: warning: {warning}", file=sys.stderr)
    return warning


def _print_summary(procedure: str, summary: dict) -> None:
    """A procedure's results for people (the JSON keys hold the same numbers in full)."""
    if procedure == "resonance":
        print(f"  resonance {summary['resonance_frequency_hz']:.1f} Hz, peak velocity "
              f"{summary['peak_velocity_m_s']:.4f} m/s, {_q_estimate(summary['q_estimate'])}")
    elif procedure == "campaign":
        for sweep in summary["sweeps"]:
            print(f"  sweep {sweep['sweep']} at {sweep['voltage_v']:g} V: peak {sweep['peak_frequency_hz']:.1f} Hz, "
                  f"{sweep['peak_velocity_m_s']:.4f} m/s, {_q_estimate(sweep['q_estimate'])}")
    elif procedure == "ringdown":
        for burst in summary["bursts"]:
            temperature = "" if burst["temperature_c"] is None else f", plate {burst['temperature_c']:.2f} °C"
            print(f"  burst {burst['burst']} at {burst['voltage_v']:g} V: {burst['initial_velocity_m_s']:.4f} m/s "
                  f"at the burst's end{temperature}")
    elif procedure == "render":
        for name, c in summary["comparison"].items():
            times = ", ".join(f"{label} {c[key]:.2f} ms" for label, key in (("rise", "rise_time_ms"), ("fall", "fall_time_ms"))
                              if c[key] is not None)
            contrast = f"; contrast per loop {', '.join(f'{x:.3f}' for x in c['contrast'])} (wanted " \
                       f"{c['wanted_contrast'][0]:.3f})" if c.get("contrast") else ""
            print(f"  {name}: envelope error {c['error']:.1%} measured, {c['predicted_error']:.1%} predicted; "
                  f"measured - predicted {c['model_error']:.1%}; {times or 'no step'}{contrast}")
        print(f"  figure: {summary['figure']}")
    elif procedure == "hold":
        loop = "closed" if summary["closed_loop"] else "open"
        print(f"  {loop} loop, target {summary['target_velocity_m_s']:.4g} m/s: {summary['samples']} samples, the last "
              f"{summary['final_velocity_error']:+.2%} off the target")
        if "max_velocity_error" in summary:
            low, high = summary["frequency_range_hz"]
            print(f"  from sample {summary['held_from_sample']}: velocity within {summary['max_velocity_error']:.2%} "
                  f"(rms {summary['rms_velocity_error']:.2%}); frequency {low:.1f} to {high:.1f} Hz; drive "
                  f"{summary['drive_range_v'][0]:.2f} to {summary['drive_range_v'][1]:.2f} V")
        print(f"  figure: {summary['figure']}")
    elif procedure == "scan":
        print(f"  {summary['points']} points at {summary['frequency_hz']:.1f} Hz, {summary['voltage_v']:g} V: largest "
              f"deflection {summary['max_deflection_um']:.3f} µm at ({summary['max_x_mm']:g}, {summary['max_y_mm']:g}) mm")
        print(f"  MAC with the FEM's map of the nominal plate (working mode {summary['nominal_fem_frequency_hz']:.0f} Hz): "
              f"{summary['mac']:.4f}; figure: {summary['figure']}")
    else:
        for voltage, deflection in zip(summary["voltage_v"], summary["deflection_um"]):
            print(f"  {voltage:g} V: deflection {deflection:.4f} µm")


def _q_estimate(value) -> str:
    """The half-power Q estimate, or why there is none."""
    return "Q estimate n/a (no half-power bandwidth in the sweep)" if value is None else f"Q estimate {value:.1f}"
