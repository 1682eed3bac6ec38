"""Measurement procedures: resonance search, Q(v) campaign, deflection versus voltage.

Each procedure plans its points, skips those already in its log (resume), measures the
rest one by one, appending and fsync'ing a row per point (:mod:`.logwriter`), and shows
its progress on stderr (:class:`~workflow.progress.Progress`).  A timed-out or garbled exchange is retried a bounded number of
times; then a clear :class:`InstrumentError` stops the run, with the log intact for a
resume.  The generator is left in its safe state (output off, lowest amplitude, no offset)
at the end, also after an error or an exception raised by a signal (:meth:`Station.shutdown`).

Voltages are peak volts across the ceramics; the station converts them through the
amplifier gain and refuses anything above its safety limit before sending it.  Velocities come from
the vibrometer's analog output read by the lock-in (:mod:`.readout`): each reading waits for the
lock-in to settle, ranges, and converts volts to m/s through the decoder range in effect.
"""

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from instruments.drivers.amplifier import PowerAmplifier
from instruments.drivers.errors import CommunicationError, InstrumentError, SafetyLimitError
from instruments.drivers.generator import FREQUENCY_RANGE, FunctionGenerator, check_voltage_limit
from instruments.drivers.lockin import LockIn
from instruments.drivers.vibrometer import Vibrometer
from instruments.procedures.logwriter import LogWriter, point_key
from instruments.procedures.readout import DEFAULT_TIME_CONSTANT, Readout, VelocityReading
from workflow import logformat
from workflow.errors import InputFileError, TactileError
from workflow.progress import Progress
from workflow.resonance import half_power_bandwidth, parabolic_peak
from workflow.units import MM

DEFAULT_RETRIES = 3
"""Retries of one point after a timeout or a garbled reply."""
DEFAULT_SETTLE_TIME = 0.0
"""Wait after changing the drive on top of the lock-in's settling [s] (the plate's own, Q/(pi f) ~ 2 ms, is far shorter)."""
MIN_POINTS_PER_SWEEP = 3
"""Fewest points of a frequency sweep (a peak needs neighbours)."""
MAX_POINTS_PER_SWEEP = 10_000
"""Most points of one frequency sweep."""
MAX_PLANNED_POINTS = 100_000
"""Most points of one procedure (about 14 h of bench time at the default settle time)."""


class PlanError(TactileError, ValueError):
    """A plan refused before anything is sent: a size or a frequency out of bounds."""


def check_sizes(sweeps: dict, total: int, what: str) -> None:
    """Raise :class:`PlanError` unless each frequency sweep has 3 to 10 000 points and ``total`` is at most 100 000.

    Parameters
    ----------
    sweeps : dict
        Name (as the user gave it, e.g. ``--points``) -> points of that sweep.
    total : int
        Points of the whole procedure.
    what : str
        What ``total`` counts, for the message.
    """
    for name, count in sweeps.items():
        if count < MIN_POINTS_PER_SWEEP:
            raise PlanError(f"{name} must be at least {MIN_POINTS_PER_SWEEP} (a peak needs neighbours), got {count}")
        if count > MAX_POINTS_PER_SWEEP:
            raise PlanError(f"{name} {count} exceeds the limit of {MAX_POINTS_PER_SWEEP} points per sweep")
    if total > MAX_PLANNED_POINTS:
        raise PlanError(f"{what}: {total} points exceed the limit of {MAX_PLANNED_POINTS} points per procedure")


def check_frequencies(low: float, high: float, what: str) -> None:
    """Raise :class:`PlanError` unless [``low``, ``high``] [Hz] is within the generator's sine range."""
    if not FREQUENCY_RANGE[0] <= low <= high <= FREQUENCY_RANGE[1]:
        raise PlanError(f"{what}: {low:.12g} Hz to {high:.12g} Hz is outside the generator's range "
                        f"{FREQUENCY_RANGE[0]:g} Hz to {FREQUENCY_RANGE[1]:.12g} Hz")


@dataclass(frozen=True)
class PlannedPoint:
    """One measurement: drive at ``frequency`` [Hz] with ``voltage`` [V peak across the ceramics], and for a
    scan the laser spot at ``position`` (x, y) [m] from the plate's centre."""

    sweep: int
    frequency: float
    voltage: float
    position: tuple | None = None

    @property
    def position_mm(self) -> tuple | None:
        """``position`` in the log's unit, mm (None without a position)."""
        return None if self.position is None else tuple(value / MM for value in self.position)

    @property
    def key(self) -> tuple:
        """Its identity in a log (:func:`~.logwriter.point_key`)."""
        values = {logformat.SWEEP: self.sweep, logformat.FREQUENCY: self.frequency, logformat.DRIVE_VOLTAGE: self.voltage}
        return point_key({**values, **dict(zip(logformat.POSITION_COLUMNS, self.position_mm or ()))})


class Station:
    """The generator, amplifier, vibrometer controller and lock-in of one bench, with the safety limit.

    Parameters
    ----------
    generator : FunctionGenerator
        Its ``max_peak_voltage`` should be the limit translated through the gain (see
        :func:`open_station`); the station checks the limit itself as well.
    vibrometer : Vibrometer
    lockin : LockIn
    amplifier : PowerAmplifier
    voltage_limit : float
        Safety limit on the peak voltage across the ceramics [V]: finite and > 0 (ValueError otherwise).
    retries : int
        Retries of a point after a timeout or garbled reply.
    settle_time : float
        Wait after changing the drive on top of the lock-in's settling [s].
    clock, sleep : callable
        Time source [s] and wait function (a simulated bench passes its own).
    time_constant : float
        The lock-in's time constant for the readout [s].
    temperature_aux : int or None
        The lock-in's Aux In (1-4) carrying the plate's temperature sensor, or None.
    """

    def __init__(
        self,
        generator: FunctionGenerator,
        vibrometer: Vibrometer,
        lockin: LockIn,
        amplifier: PowerAmplifier,
        voltage_limit: float,
        retries: int = DEFAULT_RETRIES,
        settle_time: float = DEFAULT_SETTLE_TIME,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        time_constant: float = DEFAULT_TIME_CONSTANT,
        temperature_aux: int | None = None,
    ):
        self.generator = generator
        self.vibrometer = vibrometer
        self.lockin = lockin
        self.amplifier = amplifier
        self.voltage_limit = check_voltage_limit(voltage_limit)
        self.retries = retries
        self.settle_time = settle_time
        self.clock = clock
        self.sleep = sleep
        self.readout = Readout(vibrometer, lockin, time_constant, temperature_aux)
        self._voltage = None
        self._frequency = None

    def check_voltage(self, voltage: float) -> None:
        """Raise :class:`SafetyLimitError` if ``voltage`` [V peak across the ceramics] exceeds the limit."""
        if not 0 <= voltage <= self.voltage_limit:
            raise SafetyLimitError(
                f"drive {voltage:g} V peak across the ceramics is outside 0 to the safety limit {self.voltage_limit:g} V"
            )

    def retry(self, action: Callable, what: str):
        """``action()``, retried after timeouts and garbled replies; then :class:`InstrumentError`."""
        for _ in range(self.retries + 1):
            try:
                return action()
            except CommunicationError as error:
                last = error
                for instrument in (self.generator, self.vibrometer, self.lockin):
                    instrument.discard_input()
        raise InstrumentError(f"{what}: giving up after {self.retries + 1} attempts; last: {last}")

    def identify(self) -> dict:
        """Instrument identities and the readout's settings, for the log header."""
        generator = self.retry(lambda: self.generator.identity, "identifying the generator")
        readout = self.retry(self.readout.describe, "identifying the vibrometer and the lock-in")
        return {"generator": generator, **readout}

    def prepare(self) -> None:
        """Sine, no offset, output off, no queued errors; the readout configured, the decoder on its most sensitive range."""

        def configure():
            self.generator.output = False
            self.generator.clear()
            self.generator.load_ohm = math.inf  # High Z: the stated amplitude is what the amplifier gets
            self.generator.function = "SIN"
            self.generator.offset = 0.0
            self.generator.check_errors("configuring the output")
            self.readout.prepare()

        self.retry(configure, "preparing the instruments")
        self._voltage = None

    def drive(self, frequency: float, voltage: float) -> None:
        """Sine at ``frequency`` [Hz] with ``voltage`` [V peak across the ceramics], output on.

        The generator's error queue is read after each setting: a refused setting raises
        :class:`InstrumentError` (the run stops; the point is not logged).
        """
        self.check_voltage(voltage)
        self.generator.frequency = frequency
        self.generator.check_errors(f"setting {frequency:.12g} Hz; that point is not logged")
        self._frequency = frequency
        if voltage != self._voltage:
            self.generator.amplitude_vpp = self.amplifier.generator_vpp(voltage)
            self.generator.check_errors(f"setting {voltage:g} V across the ceramics")
            if self._voltage is None:
                self.generator.output = True
            self._voltage = voltage
        self.sleep(self.settle_time)

    def read_velocity(self) -> VelocityReading:
        """A settled, ranged reading at the frequency last driven (:meth:`.readout.Readout.read`)."""
        return self.readout.read(self._frequency, self.sleep)

    def read_temperature(self) -> float | None:
        """Plate temperature [deg C] from the sensor on the lock-in's Aux In, or None without one."""
        return self.readout.read_temperature()

    def measure(self, point: PlannedPoint) -> VelocityReading:
        """Drive and read one point, with retries."""

        def drive_and_read():
            if point.position is not None:
                self.vibrometer.move_to(*point.position)
            self.drive(point.frequency, point.voltage)
            return self.read_velocity()

        return self.retry(drive_and_read, f"measuring at {point.frequency:.3f} Hz, {point.voltage:g} V")

    def shutdown(self) -> str | None:
        """Leave the generator safe: output off, lowest amplitude, no offset, confirmed by ``OUTP?``.

        Never raises (it runs after errors): returns None once ``OUTP?`` answers 0, else why
        the output could not be confirmed off (e.g. a lost connection).
        """
        self._voltage = None

        def switch_off():
            self.generator.switch_off()
            if self.generator.output:
                raise InstrumentError(f"{self.generator.name} still reports its output on after OUTP 0")

        try:
            self.retry(switch_off, "switching the output off")
        except InstrumentError as error:
            return str(error)
        return None


@dataclass(frozen=True)
class ProcedureResult:
    """What a procedure did.

    Attributes
    ----------
    path : Path
        The log.
    procedure : str
    planned, measured, resumed : int
        Planned points, points measured in this run, points found in the log.
    truncated_bytes : int
        Length of an unterminated last line found on resuming [bytes] (kept: :mod:`.logwriter`).
    summary : dict
        Procedure-specific results (JSON-able).
    warnings : tuple of str
        What the resume tolerated (rows repeating a point, an unterminated last line), one line each.
    """

    path: Path
    procedure: str
    planned: int
    measured: int
    resumed: int
    truncated_bytes: int
    summary: dict
    warnings: tuple = ()


def _measure_points(station: Station, log: LogWriter, points: list[PlannedPoint], label: str) -> int:
    """Measure the points not yet in ``log``; returns how many were measured."""
    todo = [p for p in points if p.key not in log.keys]
    stamps = [float(row[logformat.TIMESTAMP]) for row in log.rows if row[logformat.TIMESTAMP]]
    offset = max(stamps, default=0.0)
    start = station.clock()
    with Progress(len(todo), label, unit="points", enabled=bool(todo)) as bar:
        for point in todo:
            reading = station.measure(point)
            log.append(
                {
                    logformat.FREQUENCY: point.frequency,
                    logformat.DRIVE_VOLTAGE: point.voltage,
                    logformat.VELOCITY: reading.amplitude,
                    logformat.SWEEP: point.sweep,
                    logformat.TIMESTAMP: offset + station.clock() - start,
                    logformat.PHASE: reading.phase_deg,
                    **dict(zip((logformat.X_POSITION, logformat.Y_POSITION), point.position_mm or ())),
                }
            )
            bar.update()
    return len(todo)


def run_procedure(station: Station, path, procedure: str, plan: dict, voltages, stages: Callable, metadata: dict, restart: bool,
         fsync: bool, columns: tuple = logformat.COLUMNS, sweeps=(0,)):
    """Common frame: safety check of ``voltages``, identify, open/resume the log, measure each stage's points.

    ``stages`` yields lists of points; it may look at the log's rows (adaptive plans).  ``columns``:
    the log's header (``logformat.SCAN_COLUMNS`` for points with a position); ``sweeps``: every sweep id
    the stages may plan.  A resumed log's rows must be points of the plan: a row of another sweep, a
    row of a stage that is not one of its points, or a row of a later stage while an earlier one still
    has points to measure is refused before anything is written (:meth:`LogWriter.check_planned`).
    Returns (log rows, counts) for the summary.
    """
    for voltage in voltages:
        station.check_voltage(voltage)
    ids = station.identify()
    header = {
        "procedure": procedure,
        **ids,
        "amplifier_gain": station.amplifier.gain,
        "ceramic_voltage_limit_v": station.voltage_limit,
        **{f"plan_{key}": value for key, value in plan.items()},
        **metadata,
    }
    with LogWriter(path, header, restart=restart, fsync=fsync, columns=columns) as log:
        log.check_sweeps(sweeps)
        logged = {int(row[logformat.SWEEP]) for row in log.rows}
        resumed = len(log.rows)
        planned = measured = 0
        seen = set()
        station.prepare()
        try:
            for points in stages(log):
                stage = {point.sweep for point in points}
                log.check_planned({point.key for point in points}, stage)
                seen |= stage
                later = sorted(logged - seen)
                if later and any(point.key not in log.keys for point in points):
                    raise InputFileError(f"{log.path}: rows of sweep {later[0]} are logged while sweep "
                                         f"{min(stage)} still has points to measure; not resuming an edited log")
                planned += len(points)
                measured += _measure_points(station, log, points, procedure)
        finally:
            station.shutdown()
            note_readout(log, station)
        return log.rows, dict(path=Path(path), procedure=procedure, planned=planned, measured=measured,
                              resumed=resumed, truncated_bytes=log.truncated_bytes, warnings=tuple(log.warnings))


def note_readout(log: LogWriter, station: Station) -> None:
    """After a run's rows, a ``#`` line with the decoder ranges and sensitivities its readings used (none: nothing)."""
    used = station.readout.usage()
    if used:
        log.append_comment(used)


def _sweep_rows(rows: list[dict], sweep: int) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], velocity [m/s]) of a sweep's rows by frequency, a row repeating a frequency left out
    (the first kept: a row pasted twice must not move the peak)."""
    chosen = [row for row in rows if row[logformat.SWEEP] == str(sweep)]
    frequency = np.array([float(row[logformat.FREQUENCY]) for row in chosen])
    velocity = np.array([float(row[logformat.VELOCITY]) for row in chosen])
    frequency, first = np.unique(frequency, return_index=True)
    return frequency, velocity[first]


def q_estimate(frequency: np.ndarray, velocity: np.ndarray, f_peak: float, v_peak: float) -> float | None:
    """Half-power quality factor f_peak / bandwidth of a sweep [-] (:func:`workflow.resonance.half_power_bandwidth`),
    or None when the sweep misses both half-power crossings."""
    bandwidth = half_power_bandwidth(frequency, velocity, v_peak)
    return float(f_peak / bandwidth) if np.isfinite(bandwidth) else None


@dataclass(frozen=True)
class ResonancePlan:
    """Coarse sweep (sweep 0) over [start, stop], then a fine sweep (sweep 1) of +-2 coarse steps around its peak.

    Attributes
    ----------
    start, stop : float
        Coarse sweep bounds [Hz].
    coarse_points, fine_points : int
    voltage : float
        Drive [V peak across the ceramics]; small, so that Q is near its low-velocity value.
    """

    start: float = 25e3
    stop: float = 40e3
    coarse_points: int = 61
    fine_points: int = 41
    voltage: float = 2.0

    def __post_init__(self):
        check_sizes({"coarse_points": self.coarse_points, "fine_points": self.fine_points},
                    self.coarse_points + self.fine_points, "resonance plan")
        check_frequencies(self.start, self.stop, "resonance plan")


def resonance_search(station: Station, path, plan: ResonancePlan = ResonancePlan(), metadata: dict | None = None,
                     restart: bool = False, fsync: bool = True) -> ProcedureResult:
    """Find the resonance; summary keys ``resonance_frequency_hz``, ``peak_velocity_m_s``, ``q_estimate``."""
    coarse = np.linspace(plan.start, plan.stop, plan.coarse_points)
    step = coarse[1] - coarse[0]

    def stages(log):
        yield [PlannedPoint(0, f, plan.voltage) for f in coarse]
        centre, _ = parabolic_peak(*_sweep_rows(log.rows, 0))
        yield [PlannedPoint(1, f, plan.voltage) for f in np.linspace(centre - 2 * step, centre + 2 * step, plan.fine_points)]

    rows, counts = run_procedure(station, path, "resonance", vars(plan), [plan.voltage], stages, metadata or {}, restart, fsync,
                                 sweeps=(0, 1))
    frequency, velocity = _sweep_rows(rows, 1)
    f_r, v_peak = parabolic_peak(frequency, velocity)
    summary = {
        "resonance_frequency_hz": f_r,
        "peak_velocity_m_s": v_peak,
        "q_estimate": q_estimate(frequency, velocity, f_r, v_peak),
    }
    return ProcedureResult(**counts, summary=summary)


def logged_plan_value(path: Path, key: str) -> float | None:
    """The ``plan_<key>`` metadata of an existing log (what a resumed procedure was planned with), or None.

    Raises
    ------
    InputFileError
        If the value is not a finite number, naming the file and line.
    """
    if not Path(path).exists():
        return None
    metadata = logformat.read_metadata(Path(path))
    name = f"plan_{key}"
    return logformat.metadata_number(metadata, name, path) if name in metadata else None


def resonance_log_path(path: Path) -> Path:
    """Where the resonance search that centres a procedure logged at ``path`` is logged: ``<stem>-resonance.csv``."""
    path = Path(path)
    return path.with_name(f"{path.stem}-resonance{path.suffix}")


def working_frequency(station: Station, path: Path, key: str, metadata: dict | None = None,
                      restart: bool = False, search: ResonancePlan = ResonancePlan()) -> tuple[float, ProcedureResult | None]:
    """The frequency a procedure logged at ``path`` is centred on [Hz], and the resonance search behind it.

    A resumed log keeps the frequency it was planned with (its ``plan_<key>`` metadata); otherwise a
    resonance search (``search``, by default the default plan) is run and logged beside it
    (:func:`resonance_log_path`), itself resumable.  Returns (frequency, the search's result or None
    when the log's plan was used).
    """
    planned = None if restart else logged_plan_value(path, key)
    if planned is not None:
        return planned, None
    found = resonance_search(station, resonance_log_path(path), search, metadata=metadata, restart=restart)
    return found.summary["resonance_frequency_hz"], found


@dataclass(frozen=True)
class CampaignPlan:
    """Q(v) campaign: one sweep per voltage (sweep id = index) over centre +- span/2.

    Attributes
    ----------
    center_frequency : float
        [Hz], usually from :func:`resonance_search`.
    span : float
        [Hz]
    points_per_sweep : int
    voltages : tuple of float
        [V peak across the ceramics]
    alternate : bool
        Odd sweeps run downward in frequency (default: every sweep upward).  A resonance drifting within a
        sweep stretches the curves of upward sweeps and compresses those of downward ones, which a change of Q
        cannot do, so the fit's drift rate no longer trades against Q and its bands narrow 2-3 times; the
        laws' shape error (about 1 %) then exceeds them (docs/damping.md), which is why it is not the default.
    """

    center_frequency: float
    span: float = 1600.0
    points_per_sweep: int = 51
    voltages: tuple = (2.5, 5.0, 7.5, 10.0, 12.5, 15.0)
    alternate: bool = False

    def __post_init__(self):
        check_sizes({"points_per_sweep": self.points_per_sweep}, self.points_per_sweep * len(self.voltages),
                    "campaign plan")
        check_frequencies(self.center_frequency - self.span / 2, self.center_frequency + self.span / 2, "campaign plan")

    def points(self) -> list[PlannedPoint]:
        half = self.span / 2
        frequencies = np.linspace(self.center_frequency - half, self.center_frequency + half, self.points_per_sweep)
        return [PlannedPoint(sweep, f, v) for sweep, v in enumerate(self.voltages)
                for f in (frequencies[::-1] if self.alternate and sweep % 2 else frequencies)]

    def header(self) -> dict:
        """The plan's ``plan_*`` header keys: ``alternate`` only when on, so that a log made before the option (every
        sweep upward) resumes with the default plan."""
        return {key: value for key, value in vars(self).items() if key != "alternate" or value}


def q_campaign(station: Station, path, plan: CampaignPlan, metadata: dict | None = None, restart: bool = False,
               fsync: bool = True) -> ProcedureResult:
    """Frequency sweeps at several voltages; summary ``sweeps``: voltage, peak frequency and velocity, Q estimate."""
    points = plan.points()
    rows, counts = run_procedure(station, path, "campaign", plan.header(), plan.voltages, lambda log: [points], metadata or {},
                                 restart, fsync, sweeps=range(len(plan.voltages)))
    sweeps = []
    for sweep, voltage in enumerate(plan.voltages):
        frequency, velocity = _sweep_rows(rows, sweep)
        f_peak, v_peak = parabolic_peak(frequency, velocity)
        sweeps.append({"sweep": sweep, "voltage_v": voltage, "peak_frequency_hz": f_peak, "peak_velocity_m_s": v_peak,
                       "q_estimate": q_estimate(frequency, velocity, f_peak, v_peak)})
    return ProcedureResult(**counts, summary={"sweeps": sweeps})


@dataclass(frozen=True)
class VoltageSweepPlan:
    """Deflection versus voltage at a fixed frequency (sweep 0).

    Attributes
    ----------
    frequency : float
        [Hz], usually the resonance.
    voltages : tuple of float
        [V peak across the ceramics]
    """

    frequency: float
    voltages: tuple = tuple(float(v) for v in range(1, 16))

    def __post_init__(self):
        check_sizes({}, len(self.voltages), "voltage-sweep plan")
        check_frequencies(self.frequency, self.frequency, "voltage-sweep plan")


def voltage_sweep(station: Station, path, plan: VoltageSweepPlan, metadata: dict | None = None, restart: bool = False,
                  fsync: bool = True) -> ProcedureResult:
    """Velocity and deflection w = v / (2 pi f) at each voltage; summary lists ``voltage_v``, ``deflection_um``."""
    points = [PlannedPoint(0, plan.frequency, v) for v in plan.voltages]
    rows, counts = run_procedure(station, path, "voltage-sweep", vars(plan), plan.voltages, lambda log: [points], metadata or {}, restart, fsync)
    voltage = [float(row[logformat.DRIVE_VOLTAGE]) for row in rows]
    deflection = [float(row[logformat.VELOCITY]) / (2 * np.pi * float(row[logformat.FREQUENCY])) / 1e-6 for row in rows]
    return ProcedureResult(**counts, summary={"voltage_v": voltage, "deflection_um": deflection})


def open_station(generator_port, vibrometer_port, lockin_port, amplifier: PowerAmplifier, voltage_limit: float,
                 **options) -> Station:
    """A station on three open ports; the generator driver's limit is ``voltage_limit`` through the gain."""
    generator = FunctionGenerator(generator_port, amplifier.generator_peak_limit(voltage_limit))
    return Station(generator, Vibrometer(vibrometer_port), LockIn(lockin_port), amplifier, voltage_limit, **options)
