"""Texture playback: each drive played as the generator's amplitude modulation, its envelope captured and logged.

For each playback of the plan (e.g. plain switching, then the pre-compensated drive) the
generator is switched off, loaded with the drive's arbitrary waveform and set to modulate the
carrier with it (:meth:`~instruments.drivers.generator.FunctionGenerator.play_modulated`), and
switched on; after ``settle`` seconds of looping the lock-in's capture records the envelope from the
start of a period of the waveform (:mod:`.capture`, an input overload stepping the decoder up); the
capture times account for the lock-in filter's delay.  Each playback's samples are appended in one write, with
the drive envelope, and the wanted and model-predicted envelopes at the same times that the plan
carries (docs/log-format.md, render logs).  A resumed log skips the playbacks whose every sample
it holds (matched by value: playback, carrier, drive, time); a playback cut short is played again in
full after its rows, which are kept (a capture is one record).
"""

from dataclasses import dataclass

import numpy as np

from instruments.drivers.arbitrary import ModulatedDrive, drive_of_codes
from instruments.procedures.capture import CaptureWindow, capture_envelope, prepare_capture
from instruments.procedures.logwriter import LogWriter, point_key
from instruments.procedures.sweeps import PlanError, ProcedureResult, Station, check_frequencies, note_readout
from workflow import logformat
from workflow.progress import Progress

DEFAULT_SETTLE = 0.5
"""Looping time before each capture [s]: hundreds of the envelope's time constants (~1 ms)."""


@dataclass(frozen=True)
class Playback:
    """One drive to play and what it should give.

    Attributes
    ----------
    name : str
        E.g. ``plain`` or ``precompensated`` (logged in the plan).
    drive : ModulatedDrive
    wanted, predicted : tuple of float
        The antinode velocity amplitude wanted and predicted at each capture sample [m/s].
    """

    name: str
    drive: ModulatedDrive
    wanted: tuple
    predicted: tuple


@dataclass(frozen=True)
class RenderPlan:
    """Playbacks (playback id = index) and the capture after each.

    Attributes
    ----------
    playbacks : tuple of Playback
    samples : int
        Envelope samples captured per playback.
    interval : float
        Time between samples [s]: a capture interval of the lock-in, 2^k x 0.8 us.
    settle : float
        Looping time before the capture [s].
    """

    playbacks: tuple
    samples: int
    interval: float
    settle: float = DEFAULT_SETTLE

    def __post_init__(self):
        if not self.playbacks:
            raise PlanError("render plan: at least one playback")
        try:
            self.window()
        except PlanError as error:
            raise PlanError(f"render plan: {error}") from None
        for playback in self.playbacks:
            check_frequencies(playback.drive.carrier_frequency, playback.drive.carrier_frequency, "render plan")
            if not len(playback.wanted) == len(playback.predicted) == self.samples:
                raise PlanError(f"render plan: playback {playback.name} needs {self.samples} wanted and predicted values")

    def window(self) -> CaptureWindow:
        """The capture samples kept: from the trigger (a loop's start) on, delay-corrected times from 0."""
        return CaptureWindow.after(self.interval, 0.0, self.samples)

    def capture_times(self) -> np.ndarray:
        """Time of each captured sample from the start of a loop [s]."""
        return self.window().times()

    def sample_keys(self, playback: int, full_scale: float) -> list:
        """The log keys (:func:`~.logwriter.point_key`) of the samples of ``playback`` whose drive reaches ``full_scale``
        [V across the ceramics], in time order."""
        drive, times = self.playbacks[playback].drive, self.capture_times()
        return [point_key({logformat.SWEEP: playback, logformat.FREQUENCY: drive.carrier_frequency,
                           logformat.DRIVE_VOLTAGE: v, logformat.RENDER_TIME: t})
                for t, v in zip(times, drive_at(drive, full_scale, times))]

    def metadata(self) -> dict:
        """The ``plan_*`` header keys: what a resumed log must have been planned with."""
        keys = {"plan_samples": self.samples, "plan_interval": self.interval, "plan_settle": self.settle,
                "plan_playbacks": [p.name for p in self.playbacks]}
        for p in self.playbacks:
            keys.update({f"plan_{p.name}_carrier_hz": p.drive.carrier_frequency,
                         f"plan_{p.name}_amplitude_vpp": p.drive.amplitude_vpp,
                         f"plan_{p.name}_sample_rate": p.drive.sample_rate, f"plan_{p.name}_codes": list(p.drive.codes)})
        return keys


def play_and_capture(station: Station, drive: ModulatedDrive, window: CaptureWindow, settle: float):
    """Play ``drive`` looping from the output off, wait ``settle`` [s], capture ``window`` of its envelope.

    The carrier's peak across the ceramics is checked against the station's limit before anything
    is sent; the generator's error queue after loading the drive.
    """
    station.check_voltage(station.amplifier.ceramic_voltage(drive.amplitude_vpp))
    generator = station.generator
    generator.output = False
    exponent = prepare_capture(station, window, drive.carrier_frequency)
    generator.play_modulated(drive)
    generator.check_errors(f"loading the modulated drive ({len(drive.codes)} samples at {drive.sample_rate:.6g} Sa/s)")
    generator.output = True
    station.sleep(settle)
    return capture_envelope(station, window, exponent)


def drive_at(drive: ModulatedDrive, full_scale: float, time) -> np.ndarray:
    """The drive envelope across the ceramics [V] at ``time`` [s] of the loop (each sample held)."""
    index = np.floor(np.asarray(time) * drive.sample_rate + 1e-9).astype(int) % len(drive.codes)
    return drive_of_codes(np.asarray(drive.codes)[index], full_scale)


def render_playback(station: Station, path, plan: RenderPlan, metadata: dict | None = None, restart: bool = False,
                    fsync: bool = True) -> ProcedureResult:
    """Play each drive of the plan and log its captured envelope; summary ``playbacks``: name, carrier, peak drive."""
    for playback in plan.playbacks:
        station.check_voltage(station.amplifier.ceramic_voltage(playback.drive.amplitude_vpp))
    header = {"procedure": "render", **station.identify(), "amplifier_gain": station.amplifier.gain,
              "ceramic_voltage_limit_v": station.voltage_limit, **plan.metadata(), **(metadata or {})}
    full_scale = [station.amplifier.ceramic_voltage(p.drive.amplitude_vpp) for p in plan.playbacks]
    samples = {j: plan.sample_keys(j, full_scale[j]) for j in range(len(plan.playbacks))}
    with LogWriter(path, header, restart=restart, fsync=fsync, columns=logformat.RENDER_COLUMNS) as log:
        log.check_sweeps(samples)
        log.check_planned({key for keys in samples.values() for key in keys}, samples)
        resumed = len(log.rows)
        todo = [j for j, keys in samples.items() if any(key not in log.keys for key in keys)]
        station.prepare()
        try:
            with Progress(len(todo), "render", unit="playbacks", enabled=bool(todo)) as bar:
                for j in todo:
                    playback = plan.playbacks[j]
                    record = station.retry(lambda: play_and_capture(station, playback.drive, plan.window(), plan.settle),
                                           f"playing the {playback.name} drive")
                    drive = drive_at(playback.drive, full_scale[j], record.time)
                    stamp = station.clock()
                    log.append_rows([
                        {logformat.SWEEP: j, logformat.TIMESTAMP: stamp, logformat.RENDER_TIME: t,
                         logformat.FREQUENCY: playback.drive.carrier_frequency, logformat.DRIVE_VOLTAGE: v,
                         logformat.VELOCITY: measured, logformat.WANTED_VELOCITY: wanted,
                         logformat.PREDICTED_VELOCITY: predicted}
                        for t, v, measured, wanted, predicted in zip(record.time, drive, record.amplitude,
                                                                     playback.wanted, playback.predicted)
                    ])
                    bar.update()
        finally:
            station.shutdown()
            note_readout(log, station)
    playbacks = [{"playback": j, "name": p.name, "carrier_hz": p.drive.carrier_frequency,
                  "peak_drive_v": float(station.amplifier.ceramic_voltage(p.drive.amplitude_vpp))}
                 for j, p in enumerate(plan.playbacks)]
    counts = dict(path=log.path, procedure="render", planned=len(plan.playbacks) * plan.samples,
                  measured=len(todo) * plan.samples, resumed=resumed, truncated_bytes=log.truncated_bytes)
    return ProcedureResult(**counts, summary={"playbacks": playbacks}, warnings=tuple(log.warnings))
