"""Ring-down procedure: bursts at resonance, and the free decay of the velocity envelope after each.

For each burst level the generator is put in triggered burst mode (``BURS:MODE TRIG``,
``BURS:NCYC``, ``TRIG:SOUR BUS``, ``BURS:STAT ON``) at the plan's frequency and amplitude, the
lock-in's capture is armed on its TRIG IN, one burst fires (``*TRG``) and the capture gives the
velocity envelope from the burst's end on (:mod:`.capture`: the one place an envelope is captured;
the texture rendering's playback uses it too).  An input overload steps the decoder range up and
fires again.  The samples kept start once the lock-in's filter has forgotten the burst's end (10
time constants); their decay times, since the burst's end, account for the filter's delay.  Each
burst's samples are appended in one write with the plate temperature where the bench reports it
(docs/log-format.md, ring-down logs).  A resumed log skips the bursts whose every sample it holds
(matched by value: burst, frequency, level, decay time); a burst cut short is recorded again in full
after its rows, which are kept (a decay is one record: its missing samples cannot be measured alone).
"""

from dataclasses import dataclass

import numpy as np

from instruments.drivers.lockin import capture_interval
from instruments.procedures.capture import (
    CaptureWindow,
    EnvelopeRecord,
    capture_envelope,
    capture_settings,
    prepare_capture,
)
from instruments.procedures.logwriter import LogWriter, point_key, row_key
from instruments.procedures.sweeps import PlanError, ProcedureResult, Station, check_frequencies, check_sizes, note_readout
from workflow import logformat
from workflow.progress import Progress

MAX_BURSTS = 1000
"""Most bursts of one ring-down procedure."""


RINGDOWN_INTERVAL_ASKED = 50e-6
"""The sample interval asked for by default [s]; the plan takes the lock-in's nearest capture interval (51.2 us)."""


@dataclass(frozen=True)
class RingdownPlan:
    """Bursts at one frequency, one per level (burst id = index).

    Attributes
    ----------
    frequency : float
        Burst frequency [Hz], usually the resonance.
    voltages : tuple of float
        Burst level of each burst [V peak across the ceramics].
    cycles : int
        Cycles per burst (enough to reach the steady state: a few Q / pi).
    samples : int
        Envelope samples recorded after each burst.
    interval : float
        Time between samples [s]: a capture interval of the lock-in, 2^k x 0.8 us (:func:`capture_interval`
        gives the nearest to any).
    """

    frequency: float
    voltages: tuple = (5.0, 10.0, 15.0)
    cycles: int = 2000
    samples: int = 100
    interval: float = capture_interval(RINGDOWN_INTERVAL_ASKED)

    def __post_init__(self):
        check_frequencies(self.frequency, self.frequency, "ring-down plan")
        check_sizes({}, len(self.voltages), "ring-down plan")
        if not 1 <= len(self.voltages) <= MAX_BURSTS:
            raise PlanError(f"ring-down plan: 1 to {MAX_BURSTS} burst levels, got {len(self.voltages)}")
        if not (isinstance(self.cycles, int) and 1 <= self.cycles <= 100_000_000):
            raise PlanError(f"ring-down plan: cycles must be an integer from 1 to 100000000, got {self.cycles!r}")
        try:
            self.window()
        except PlanError as error:
            raise PlanError(f"ring-down plan: {error}") from None

    @property
    def burst_duration(self) -> float:
        """[s]"""
        return self.cycles / self.frequency

    def window(self) -> CaptureWindow:
        """The capture samples kept: from the trigger (the burst's start), once the filter forgot the burst's end."""
        return CaptureWindow.after_kink(self.interval, self.burst_duration, self.samples)

    def decay_times(self) -> np.ndarray:
        """Time of each envelope sample after the burst's end [s]."""
        return self.window().times() - self.burst_duration

    def sample_keys(self, burst: int) -> list:
        """The log keys (:func:`~.logwriter.point_key`) of the samples of burst ``burst``, in time order."""
        base = {logformat.SWEEP: burst, logformat.FREQUENCY: self.frequency, logformat.DRIVE_VOLTAGE: self.voltages[burst]}
        return [point_key({**base, logformat.DECAY_TIME: t}) for t in self.decay_times()]


def record_ringdown(station: Station, plan: RingdownPlan, voltage: float, exponent: int) -> EnvelopeRecord:
    """Fire one burst of the plan at ``voltage`` [V peak across the ceramics]; its decay, captured.

    The limit is checked before anything is sent; the generator's error queue after the setup.
    An input overload steps the decoder range up and fires again.
    """
    station.check_voltage(voltage)
    generator, frequency, cycles = station.generator, plan.frequency, plan.cycles
    generator.output = False
    generator.frequency = frequency
    generator.amplitude_vpp = station.amplifier.generator_vpp(voltage)
    generator.configure_burst(cycles)
    generator.check_errors(f"configuring a burst of {cycles} cycles at {frequency:.12g} Hz, {voltage:g} V")
    generator.output = True
    return capture_envelope(station, plan.window(), exponent, generator.trigger, plan.burst_duration)


def ringdown(station: Station, path, plan: RingdownPlan, metadata: dict | None = None, restart: bool = False,
             fsync: bool = True) -> ProcedureResult:
    """Ring-downs at the plan's levels; summary ``bursts``: voltage, initial velocity, temperature."""
    for voltage in plan.voltages:
        station.check_voltage(voltage)
    ids = station.identify()
    header = {
        "procedure": "ringdown",
        **ids,
        **capture_settings(plan.window()),  # a ring-down reads the lock-in's capture, not the sweeps' readout
        "amplifier_gain": station.amplifier.gain,
        "ceramic_voltage_limit_v": station.voltage_limit,
        **{f"plan_{key}": value for key, value in vars(plan).items()},
        **(metadata or {}),
    }
    samples = {j: plan.sample_keys(j) for j in range(len(plan.voltages))}
    with LogWriter(path, header, restart=restart, fsync=fsync, columns=logformat.RINGDOWN_COLUMNS) as log:
        log.check_sweeps(samples)
        log.check_planned({key for keys in samples.values() for key in keys}, samples)
        resumed = len(log.rows)
        todo = [j for j, keys in samples.items() if any(key not in log.keys for key in keys)]
        station.prepare()
        try:
            exponent = station.retry(lambda: prepare_capture(station, plan.window(), plan.frequency),
                                     "preparing the lock-in's capture")
            with Progress(len(todo), "ringdown", unit="bursts", enabled=bool(todo)) as bar:
                for j in todo:
                    voltage = plan.voltages[j]
                    record = station.retry(lambda: record_ringdown(station, plan, voltage, exponent),
                                           f"ring-down at {voltage:g} V")
                    temperature = station.retry(station.read_temperature, "reading the plate temperature")
                    stamp = station.clock()
                    log.append_rows([
                        {logformat.SWEEP: j, logformat.TIMESTAMP: stamp, logformat.DECAY_TIME: t,
                         logformat.FREQUENCY: plan.frequency, logformat.DRIVE_VOLTAGE: voltage,
                         logformat.VELOCITY: v, logformat.TEMPERATURE: temperature}
                        for t, v in zip(record.time, record.amplitude)
                    ])
                    bar.update()
        finally:
            station.shutdown()
            note_readout(log, station)
        rows = log.rows
    bursts = []
    for j, voltage in enumerate(plan.voltages):
        first = [row for row in rows if row_key(row) == samples[j][0]][-1]  # the burst's latest record
        bursts.append({"burst": j, "voltage_v": voltage, "initial_velocity_m_s": float(first[logformat.VELOCITY]),
                       "temperature_c": float(first[logformat.TEMPERATURE]) if first[logformat.TEMPERATURE] else None})
    counts = dict(path=log.path, procedure="ringdown", planned=len(plan.voltages) * plan.samples,
                  measured=len(todo) * plan.samples, resumed=resumed, truncated_bytes=log.truncated_bytes)
    return ProcedureResult(**counts, summary={"bursts": bursts}, warnings=tuple(log.warnings))

