"""Closed loop: hold the plate at its resonance and at a target velocity for a given time (``tactile measure hold``).

Once per loop period T the station sets (f, V), waits for the lock-in to settle (T is the readout's
settling, 0.4 s at 30 ms: far longer than the plate's own time constant tau = Q / (pi f), 0.5 ms at
Q = 54, so the plate is in its steady state at every reading) and reads the velocity v and its phase
phi against the drive (the decoder's delay removed).  Then:

* phase-locked loop: the velocity is in phase with the drive at resonance and leads it below, with
  d phi / d f = -2 Q / f_r there; so f <- f + K_f phi + r, r <- r + g_d K_f phi, with
  K_f = g_f f / (2 Q(v)) [Hz/rad]: each period removes the fraction g_f = 0.5 of the frequency error
  (a quarter-bandwidth per 45 deg), and r, the drift per period, learns the warm-up's ramp (g_d = 0.1)
  so that the loop follows it without lagging; the error obeys z^2 - (2 - g_f - g_d g_f) z + 1 - g_f,
  |z| = 0.71, stable with K_f off by 2 either way;
* amplitude, a PI in velocity form on e = v* - v: V <- V + K_p (e - e_prev) + K_i e with
  K_i = g_i / S and K_p = g_p / S, g_i = 0.5, g_p = 0.1, S = dv/dV the plant's gain at resonance,
  S = (v / V) / (1 - d ln Q / d ln v) from the Q(v) law (a falling Q makes v grow slower than V);
  the closed loop's error then shrinks as the roots of z^2 - (1 - g_i - g_p) z - g_p, |z| <= 0.57
  per period, and stays stable with S off by 2.5 either way; the small g_p keeps the reading's
  noise, which the velocity form differentiates, out of the drive.  V is clamped to [0, the voltage limit] after each step: the
  velocity form holds no integral beyond the clamp (anti-windup), and no step exceeds a tenth of the
  limit (the slew limit of the acquisition).

Both gains are scheduled with the velocity read (Q(v) from the fitted law), so the acquisition from a
low start voltage uses the same loop.  The hold is locked once |phi| < 10 deg and |e| < 2 % for
three periods; after that a phase beyond 45 deg for five periods, or a velocity under a tenth of the
target, is a lost lock.  Open loop (``closed=False``) freezes f and V once locked.

Samples are logged every ``interval`` of hold time (slots at k x interval, the key of a row): the mean
velocity and phase of the periods read since the last slot, the frequency and drive set then, the
plate temperature where the bench reports it.  A resumed log keeps its rows and holds on from its
first missing slot: the loop locks again from the last logged frequency and the start voltage.
Whatever stops the hold (a lost lock, an overload ranging cannot clear, a lost connection, a signal)
switches the output off and writes why as a ``#`` line in the log, then the error goes on.
"""

import math
from dataclasses import dataclass, fields

import numpy as np

from instruments.drivers.errors import InstrumentError
from instruments.procedures.logwriter import HOLD_KEY_COLUMNS, LogWriter, point_key
from instruments.procedures.sweeps import PlanError, ProcedureResult, Station, check_frequencies, note_readout
from workflow import logformat
from workflow.progress import Progress

FREQUENCY_GAIN = 0.5
"""g_f: fraction of the frequency error removed per period [-]."""
DRIFT_GAIN = 0.1
"""g_d: the PLL's drift integrator, relative to its frequency gain [-]."""
INTEGRAL_GAIN = 0.5
"""g_i: integral gain of the amplitude loop, relative to the plant's gain [-]."""
PROPORTIONAL_GAIN = 0.1
"""g_p: proportional gain of the amplitude loop, relative to the plant's gain [-]."""
MAX_STEP_FRACTION = 0.1
"""Largest drive step per period, as a fraction of the voltage limit [-]."""
LOCK_PHASE = 10.0
"""|phase| below which (with the amplitude within :data:`HOLD_TOLERANCE`) the loop is locked [deg]."""
HOLD_TOLERANCE = 0.02
"""|v - v*| / v* below which (with the phase within :data:`LOCK_PHASE`) the loop is locked; the summary reports
from the first run of logged samples within it [-]."""
LOCK_PERIODS = 3
"""Periods the lock conditions must hold [-]."""
LOST_PHASE = 45.0
"""|phase| beyond which a locked loop counts a period as out of lock [deg]: half a bandwidth off."""
LOST_PERIODS = 5
"""Consecutive periods out of lock that stop the hold [-]."""
LOST_AMPLITUDE = 0.1
"""A locked loop reading under this fraction of the target has lost the plate [-]."""
ACQUISITION_PERIODS = 200
"""Periods allowed to lock (from the start or a resume) before the hold stops [-]."""
DEFAULT_START_VOLTAGE = 1.0
"""Drive the loop starts from [V peak across the ceramics]."""
GAIN_STEP = 1e-3
"""Relative step of v for the numerical d ln Q / d ln v [-]."""


@dataclass(frozen=True)
class LoopGains:
    """The loop's gains at one velocity.

    Attributes
    ----------
    frequency : float
        K_f [Hz/rad].
    integral, proportional : float
        K_i, K_p [V/(m/s)].
    """

    frequency: float
    integral: float
    proportional: float


def log_slope(law, velocity: float) -> float:
    """d ln Q / d ln v of ``law`` at ``velocity`` [m/s] [-]."""
    up, down = velocity * (1 + GAIN_STEP), velocity * (1 - GAIN_STEP)
    return float((np.log(law.quality_factor(up)) - np.log(law.quality_factor(down))) / (np.log(up) - np.log(down)))


def loop_gains(law, frequency: float, velocity: float, voltage: float) -> LoopGains:
    """The gains at antinode ``velocity`` [m/s] driven by ``voltage`` [V] at ``frequency`` [Hz] (module docstring)."""
    q = float(law.quality_factor(velocity))
    plant = velocity / voltage / (1 - log_slope(law, velocity))
    return LoopGains(FREQUENCY_GAIN * frequency / (2 * q), INTEGRAL_GAIN / plant, PROPORTIONAL_GAIN / plant)


def plate_time_constant(law, frequency: float, velocity: float) -> float:
    """The plate's envelope time constant tau = Q(v) / (pi f) [s]."""
    return float(law.quality_factor(velocity)) / (np.pi * frequency)


@dataclass(frozen=True)
class HoldPlan:
    """Hold ``target_velocity`` at resonance for ``duration``, logging every ``interval``.

    Attributes
    ----------
    frequency : float
        Start frequency [Hz], e.g. the resonance a search found.
    target_velocity : float
        Velocity amplitude to hold at the laser spot, an antinode [m/s].
    duration : float
        Hold time [s].
    interval : float
        Time between logged samples [s] (at least the loop period).
    law : object
        The Q(v) law the gains follow (:mod:`workflow.damping.laws`).
    closed : bool
        Closed loop (True) or frozen once locked (False).
    start_voltage : float
        Drive the loop starts from [V peak across the ceramics].
    """

    frequency: float
    target_velocity: float
    duration: float
    interval: float
    law: object
    closed: bool = True
    start_voltage: float = DEFAULT_START_VOLTAGE

    def __post_init__(self):
        check_frequencies(self.frequency, self.frequency, "hold plan")
        if not (math.isfinite(self.target_velocity) and 0 < self.target_velocity <= 10):
            raise PlanError(f"hold plan: the target velocity must be 0 to 10 m/s, got {self.target_velocity:g}")
        if not (0 < self.interval <= self.duration <= 86400 * 7):
            raise PlanError(f"hold plan: 0 < interval ({self.interval:g} s) <= duration ({self.duration:g} s) <= 7 days")
        if self.duration / self.interval > 100_000:
            raise PlanError(f"hold plan: {self.duration / self.interval:.0f} samples exceed the limit of 100000")

    def hold_times(self) -> np.ndarray:
        """The slots: 0, interval, ..., up to the duration [s]."""
        return self.interval * np.arange(int(math.floor(self.duration / self.interval + 1e-9)) + 1)

    def keys(self) -> list:
        """Each slot's log key."""
        return [point_key({logformat.SWEEP: 0, logformat.HOLD_TIME: t}, HOLD_KEY_COLUMNS) for t in self.hold_times()]

    def metadata(self) -> dict:
        """The ``plan_*`` header items (the law by name and parameters): what a resumed log must have been planned with."""
        return {"plan_frequency": self.frequency, "plan_target_velocity": self.target_velocity,
                "plan_duration": self.duration, "plan_interval": self.interval, "plan_closed": self.closed,
                "plan_start_voltage": self.start_voltage, "plan_law": self.law.name,
                **{f"plan_law_{field.name}": getattr(self.law, field.name) for field in fields(self.law)}}


class HoldStopped(InstrumentError):
    """The hold stopped itself: a lost lock, or no lock within the acquisition."""


class Loop:
    """The loop's state between periods: the drive set, the last amplitude error, the lock bookkeeping."""

    def __init__(self, plan: HoldPlan, limit: float, frequency: float):
        self.plan, self.limit = plan, limit
        self.frequency, self.voltage = frequency, min(plan.start_voltage, limit)
        self.drift = 0.0
        """The PLL's estimate of the resonance's drift per period [Hz]."""
        self.error = None
        self.locked = False
        self.in_lock = self.out_of_lock = self.periods = 0

    def step(self, velocity: float, phase_deg: float) -> None:
        """One period: the reading (``velocity`` [m/s], ``phase_deg`` [deg]) updates the lock state and the next (f, V).

        Raises
        ------
        HoldStopped
            A lost lock, or no lock within :data:`ACQUISITION_PERIODS`.
        """
        plan, target = self.plan, self.plan.target_velocity
        error = target - velocity
        self.periods += 1
        self._watch(velocity, phase_deg, error)
        if self.locked and not plan.closed:
            return
        gains = loop_gains(plan.law, self.frequency, max(velocity, 1e-6 * target), self.voltage)
        correction = gains.frequency * math.radians(phase_deg)
        self.drift += DRIFT_GAIN * correction
        self.frequency += correction + self.drift
        change = gains.integral * error + (0.0 if self.error is None else gains.proportional * (error - self.error))
        step = MAX_STEP_FRACTION * self.limit
        self.voltage = float(np.clip(self.voltage + np.clip(change, -step, step), 0.0, self.limit))
        self.error = error

    def _watch(self, velocity: float, phase_deg: float, error: float) -> None:
        target = self.plan.target_velocity
        if not self.locked:
            good = abs(phase_deg) < LOCK_PHASE and abs(error) < HOLD_TOLERANCE * target
            self.in_lock = self.in_lock + 1 if good else 0
            self.locked = self.in_lock >= LOCK_PERIODS
            if not self.locked and self.periods >= ACQUISITION_PERIODS:
                raise HoldStopped(f"no lock within {ACQUISITION_PERIODS} periods (last: {velocity:.4g} m/s of "
                                  f"{target:.4g}, phase {phase_deg:+.1f} deg at {self.frequency:.1f} Hz, {self.voltage:.3g} V)")
            return
        if not self.plan.closed:
            return
        if velocity < LOST_AMPLITUDE * target:
            raise HoldStopped(f"lost lock: {velocity:.4g} m/s, under {LOST_AMPLITUDE:g} of the target {target:.4g} m/s "
                              f"(the laser spot off the plate, or the plate's resonance gone)")
        self.out_of_lock = self.out_of_lock + 1 if abs(phase_deg) > LOST_PHASE else 0
        if self.out_of_lock >= LOST_PERIODS:
            raise HoldStopped(f"lost lock: phase {phase_deg:+.1f} deg beyond {LOST_PHASE:g} deg for {LOST_PERIODS} periods "
                              f"at {self.frequency:.1f} Hz")


def _resume_frequency(log: LogWriter, plan: HoldPlan) -> float:
    """Where a resumed hold starts: the frequency of the last logged sample, else the plan's."""
    rows = [row for row in log.rows if row[logformat.FREQUENCY]]
    return float(max(rows, key=lambda row: float(row[logformat.HOLD_TIME]))[logformat.FREQUENCY]) if rows else plan.frequency


def hold(station: Station, path, plan: HoldPlan, metadata: dict | None = None, restart: bool = False,
         fsync: bool = True) -> ProcedureResult:
    """Hold the plan's target; summary: the target, the locked share and the amplitude and frequency statistics."""
    station.check_voltage(plan.start_voltage)
    header = {"procedure": "hold", **station.identify(), "amplifier_gain": station.amplifier.gain,
              "ceramic_voltage_limit_v": station.voltage_limit, **plan.metadata(), **(metadata or {})}
    times, keys = plan.hold_times(), plan.keys()
    with LogWriter(path, header, restart=restart, fsync=fsync, columns=logformat.HOLD_COLUMNS,
                   keys=HOLD_KEY_COLUMNS) as log:
        log.check_sweeps((0,))
        log.check_planned(set(keys), (0,))
        resumed = len(log.rows)
        todo = [k for k, key in enumerate(keys) if key not in log.keys]
        if todo:
            _run(station, log, plan, times, keys, todo)
        rows = log.rows
    counts = dict(path=log.path, procedure="hold", planned=len(keys), measured=len(todo), resumed=resumed,
                  truncated_bytes=log.truncated_bytes)
    return ProcedureResult(**counts, summary=hold_summary(rows, plan), warnings=tuple(log.warnings))


def _run(station: Station, log: LogWriter, plan: HoldPlan, times: np.ndarray, keys: list, todo: list) -> None:
    """The loop from the first missing slot to the end, logging the missing slots; output off whatever ends it."""
    loop = Loop(plan, station.voltage_limit, _resume_frequency(log, plan))
    origin, start = float(times[todo[0]]), None
    pending, readings = list(todo), []
    station.prepare()
    try:
        with Progress(len(pending), "hold", unit="samples", enabled=True) as bar:
            while pending:
                reading = station.retry(lambda: _drive_and_read(station, loop.frequency, loop.voltage),
                                        f"holding at {loop.frequency:.3f} Hz, {loop.voltage:.4g} V")
                readings.append((reading.amplitude, reading.phase_deg))
                now = station.clock()
                start = now if start is None else start
                due = [k for k in pending if times[k] <= origin + now - start + 1e-9]
                if due:
                    velocity, phase = np.mean(readings, axis=0)
                    temperature = station.retry(station.read_temperature, "reading the plate temperature")
                    log.append_rows([{logformat.SWEEP: 0, logformat.TIMESTAMP: now, logformat.HOLD_TIME: times[k],
                                      logformat.FREQUENCY: loop.frequency, logformat.DRIVE_VOLTAGE: loop.voltage,
                                      logformat.VELOCITY: velocity, logformat.PHASE: phase,
                                      logformat.TEMPERATURE: temperature} for k in due])
                    pending, readings = [k for k in pending if k not in due], []
                    bar.update(len(due))
                loop.step(reading.amplitude, reading.phase_deg)
    except BaseException as error:
        note_readout(log, station)
        log.append_comment(f"hold stopped at hold time {origin + (station.clock() - start if start else 0.0):.3f} s: "
                           f"{_reason(error)}; generator output switched off")
        raise
    else:
        note_readout(log, station)
    finally:
        station.shutdown()


def _drive_and_read(station: Station, frequency: float, voltage: float):
    """Set the drive, read the settled velocity."""
    station.drive(frequency, voltage)
    return station.read_velocity()


def _reason(error: BaseException) -> str:
    """One line saying why the hold stopped (a stop signal's exception carries its ``signum`` and names it)."""
    return f"stopped by {error}" if hasattr(error, "signum") else f"{type(error).__name__}: {error}"


def hold_summary(rows: list, plan: HoldPlan) -> dict:
    """The target and, over the logged samples once held (from the first run of three samples within
    :data:`HOLD_TOLERANCE` of it on), the velocity's worst and rms error, the frequency's range and the drive's range."""
    velocity = np.array([float(row[logformat.VELOCITY]) for row in rows])
    frequency = np.array([float(row[logformat.FREQUENCY]) for row in rows])
    voltage = np.array([float(row[logformat.DRIVE_VOLTAGE]) for row in rows])
    order = np.argsort([float(row[logformat.HOLD_TIME]) for row in rows])
    velocity, frequency, voltage = velocity[order], frequency[order], voltage[order]
    relative = velocity / plan.target_velocity - 1
    close = np.abs(relative) < HOLD_TOLERANCE
    runs = np.convolve(close, np.ones(LOCK_PERIODS), "valid") >= LOCK_PERIODS
    locked = int(np.argmax(runs)) if runs.any() else len(rows)
    held = slice(locked, None)
    summary = {"target_velocity_m_s": plan.target_velocity, "closed_loop": plan.closed, "samples": len(rows),
               "final_velocity_error": float(relative[-1]) if len(rows) else None, "held_from_sample": locked}
    if locked < len(rows):
        summary.update({
            "max_velocity_error": float(np.max(np.abs(relative[held]))),
            "rms_velocity_error": float(np.sqrt(np.mean(relative[held] ** 2))),
            "frequency_range_hz": [float(frequency[held].min()), float(frequency[held].max())],
            "drive_range_v": [float(voltage[held].min()), float(voltage[held].max())],
        })
    return summary
