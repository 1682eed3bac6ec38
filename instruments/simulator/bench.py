"""The simulated bench: a plate, the amplifier, a generator and a vibrometer sharing one clock.

Time is simulated: each vibrometer readout takes ``measurement_time`` of bench time and
:meth:`Bench.sleep` advances it, so simulated campaigns run as fast as the CPU allows
and are reproducible from their seeds.

An amplitude-modulated output (``AM:STAT ON``) drives the plate's envelope through the
envelope equation (:mod:`workflow.damping.envelope`) from rest at the last change of the
output; the vibrometer's envelope record then starts at the next start of the modulating
waveform's period (on a real bench its trigger input on the generator's Sync output).
"""

import itertools
from dataclasses import asdict, dataclass, field

import numpy as np

from instruments.drivers.amplifier import DEFAULT_CERAMIC_VOLTAGE_LIMIT, DEFAULT_GAIN, PowerAmplifier
from instruments.simulator.builtplate import BuiltPlateModel, surface_velocity
from instruments.simulator.buffers import OVERRUN, InputBuffer, OutputQueue
from instruments.simulator.faults import Fault, FaultInjector, FaultSettings
from instruments.simulator.generator import GeneratorDevice
from instruments.simulator.physics import PlateResponse, plate_response
from instruments.simulator.vibrometer import VibrometerDevice
from workflow import logformat
from workflow.damping.envelope import envelope_at, periodic_play, play
from workflow.damping.laws import law_parameters
from workflow.damping.mode_shape import BeamMode, measurement_factor
from workflow.models.plate import ORIGINAL_PLATE, Plate
from workflow.units import MM

INSTRUMENTS = ("generator", "vibrometer")
DEFAULT_DRIFT_RATE = -0.02
"""Thermal drift of the simulated resonance [Hz/s] (the plate warms while driven)."""
SETTLED_TIME_CONSTANTS = 30
"""A modulated drive playing for this many of the plate's slowest time constants is in its periodic steady state [-]."""


class SimulatedDisconnect(Exception):
    """The simulated port went dead (fault injection)."""


@dataclass(frozen=True)
class BenchSettings:
    """Everything that defines a simulated bench.

    Attributes
    ----------
    response : PlateResponse
        The plate's physics (f_r, gain, Q(v) law, drift).
    amplifier_gain : float
        Voltage gain between generator and ceramics [V/V].
    ceramic_voltage_limit : float
        Safety limit on the peak voltage across the ceramics [V]; the simulated generator
        refuses settings beyond it (translated through the gain).
    measurement_time : float
        Bench time one vibrometer readout takes (settling and lock-in integration) [s].
    relative_noise : float
        Relative standard deviation of the velocity amplitude [-].
    floor_fraction : float
        Additive velocity noise as a fraction of the decoder's full scale [-].
    phase_noise : float
        Phase noise [deg].
    seed : int
        Seed of the measurement noise.
    faults : FaultSettings
    wavelength : float
        The plate's wavelength [m]: maps the measurement point onto the beam mode.
    measurement_point : tuple of float
        Where the vibrometer points, (x, y) from the plate's centre [m]; the centre is an antinode.
    built_plate : BuiltPlateModel or None
        A built plate (:mod:`.builtplate`) whose FEM gives ``response``'s f_r and gain and the
        velocity over the plate; the vibrometer then has a scanner.  None: the single-point bench.
    """

    response: PlateResponse
    amplifier_gain: float = DEFAULT_GAIN
    ceramic_voltage_limit: float = DEFAULT_CERAMIC_VOLTAGE_LIMIT
    measurement_time: float = 1.0
    relative_noise: float = 0.005
    floor_fraction: float = 1e-3
    phase_noise: float = 0.2
    seed: int = 0
    faults: FaultSettings = field(default_factory=FaultSettings)
    wavelength: float = ORIGINAL_PLATE.wavelength
    measurement_point: tuple = (0.0, 0.0)

    def mode_factor(self) -> float:
        """|phi| at the measurement point: the velocity read over the antinode's [-]."""
        return float(measurement_factor(BeamMode(self.wavelength), *self.measurement_point))

    def point_metadata(self) -> dict:
        """``x_mm``, ``y_mm`` and ``lambda_mm`` for the log header when the point is off the centre (else empty)."""
        if self.measurement_point == (0.0, 0.0):
            return {}
        x, y = self.measurement_point
        return {logformat.X_POSITION: x / MM, logformat.Y_POSITION: y / MM, logformat.LAMBDA_MM: self.wavelength / MM}
    built_plate: BuiltPlateModel | None = None

    def metadata(self) -> dict:
        """Flat ``simulator_*`` metadata for log headers: law, parameters, noise, drift, seeds."""
        response = self.response
        items = {
            "law": response.law.name,
            **{f"law_{name}": value for name, value in law_parameters(response.law).items()},
            "resonance_frequency_hz": response.resonance_frequency,
            "deflection_per_volt_m_v": response.deflection_per_volt,
            "drift_rate_hz_s": response.drift_rate,
            **({"softening_s2_m2": response.softening} if response.softening else {}),
            "amplifier_gain": self.amplifier_gain,
            "ceramic_voltage_limit_v": self.ceramic_voltage_limit,
            "measurement_time_s": self.measurement_time,
            "relative_noise": self.relative_noise,
            "floor_fraction": self.floor_fraction,
            "phase_noise_deg": self.phase_noise,
            "seed": self.seed,
            **{f"fault_{name}": value for name, value in asdict(self.faults).items()},
            **({} if self.built_plate is None else self.built_plate.metadata()),
        }
        return {f"simulator_{key}": value for key, value in items.items()}


def default_bench_settings(plate: Plate = ORIGINAL_PLATE, law=None, drift_rate: float = DEFAULT_DRIFT_RATE,
                           softening: float = 0.0, **changes) -> BenchSettings:
    """Bench settings for ``plate`` (default law: :func:`.physics.default_law`, no softening); ``changes`` override fields."""
    changes.setdefault("wavelength", float(plate.wavelength))
    return BenchSettings(response=plate_response(plate, law, drift_rate, softening), **changes)


def built_bench_settings(model: BuiltPlateModel, law=None, drift_rate: float = DEFAULT_DRIFT_RATE, **changes) -> BenchSettings:
    """Bench settings playing the built plate ``model`` (default law: that of its nominal plate); ``changes`` override fields."""
    return BenchSettings(response=model.response(law, drift_rate), built_plate=model, **changes)


class Bench:
    """One simulated bench (state, clock, devices, faults)."""

    def __init__(self, settings: BenchSettings):
        self.settings = settings
        self.time = 0.0
        self.amplifier = PowerAmplifier(settings.amplifier_gain)
        self.generator = GeneratorDevice(self.amplifier.generator_peak_limit(settings.ceramic_voltage_limit), self._burst,
                                         self._output_changed)
        self._output_since = 0.0
        """Bench time of the generator's last change of output [s] (a modulated drive plays from then)."""
        self.vibrometer = VibrometerDevice(
            self._surface_velocity,
            np.random.default_rng(settings.seed),
            settings.relative_noise,
            settings.floor_fraction,
            settings.phase_noise,
            record=self._decay_record,
            temperature=lambda: float(settings.response.temperature_at(self.time)),
            scanner=None if settings.built_plate is None else (settings.built_plate.surface.half_length,
                                                                settings.built_plate.surface.half_width),
        )
        self._mode_factor = settings.mode_factor()
        self._deflection = None
        """The plate's deflection at the last readout [m] (None: at rest or off resonance drive)."""
        self._last_burst = None
        """(end time [s], antinode velocity then [m/s], f_r [Hz]) of the latest burst not yet read out."""
        self.faults = FaultInjector(settings.faults)
        self._input = {name: InputBuffer() for name in INSTRUMENTS}
        self.output = {name: OutputQueue() for name in INSTRUMENTS}
        """Replies waiting for each instrument's client."""

    def clock(self) -> float:
        """Bench time [s]."""
        return self.time

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` of bench time pass, instantly."""
        self.time += seconds

    def ceramic_voltage(self) -> float:
        """Peak voltage across the ceramics now [V] (0 when the output is off or not a sine)."""
        state = self.generator.state
        if not state.output or state.function != "SIN":
            return 0.0
        return float(self.amplifier.ceramic_voltage(state.terminal_amplitude_vpp))

    def _surface_velocity(self):
        self.time += self.settings.measurement_time
        frequency = self.generator.state.frequency
        voltage = 0.0 if self.generator.state.burst else self.ceramic_voltage()
        if self.settings.built_plate is not None:
            return surface_velocity(self.settings.built_plate, self.settings.response, self.vibrometer.position,
                                    frequency, voltage, self.time)
        if voltage == 0.0:
            self._deflection = None
            return 0.0, 0.0
        velocity, phase = self.settings.response.velocity(frequency, voltage, self.time, self._deflection)
        self._deflection = float(velocity) / (2 * np.pi * frequency)
        return float(velocity) * self._mode_factor, float(phase)

    def _burst(self) -> None:
        """A burst fired: the plate builds up for NCYC cycles, then rings down from the burst's end."""
        state = self.generator.state
        duration = state.burst_cycles / state.frequency
        voltage = float(self.amplifier.ceramic_voltage(state.terminal_amplitude_vpp))
        initial = self.settings.response.burst_velocity(state.frequency, voltage, state.burst_cycles, self.time)
        self.time += duration
        self._deflection = None
        self._last_burst = (self.time, initial)

    def _output_changed(self) -> None:
        self._output_since = self.time

    def _decay_record(self, samples: int, interval: float):
        """The antinode-to-point velocity envelope at ``samples`` times ``interval`` [s] apart from the latest
        burst's end [m/s], or None when no burst fired since the last record (an IMM trigger fires one now).
        Under amplitude modulation, the envelope from the next start of the modulating waveform."""
        if self.generator.modulation() is not None:
            return self._modulated_record(samples, interval)
        if self.generator.state.trigger_source == "IMM" and self.generator.bursting():
            self._burst()
        if self._last_burst is None:
            return None
        end, initial = self._last_burst
        self._last_burst = None
        decay_time = interval * np.arange(samples)
        self.time = max(self.time, end + decay_time[-1]) + self.settings.measurement_time
        return self.settings.response.ringdown(initial, decay_time, end) * self._mode_factor

    def _modulated_record(self, samples: int, interval: float) -> np.ndarray:
        """The envelope at the measurement point [m/s], ``samples`` times ``interval`` [s] apart, from the first
        start of a modulation period after now; the plate started from rest when the output last changed."""
        state = self.generator.state
        waveform, rate = self.generator.modulation()
        full = float(self.amplifier.ceramic_voltage(state.terminal_amplitude_vpp))
        drive = full * (1 + state.am_depth / 100 * waveform) / 2
        period, step = len(waveform) / rate, 1 / rate
        model = self.settings.response.envelope_model(state.frequency, self.time)
        start = self._output_since + np.ceil((self.time - self._output_since) / period) * period
        slowest = float(model.time_constant(0.0))
        if start - self._output_since >= SETTLED_TIME_CONSTANTS * slowest:
            envelope = periodic_play(model, drive, step)[0]
        else:
            repeats = int(round((start - self._output_since) / period))
            envelope = play(model, np.tile(drive, repeats), step)[-1] if repeats else 0.0
        times = interval * np.arange(samples)
        looped = np.tile(drive, int(np.ceil(times[-1] / period)) + 1)
        within = envelope_at(model, looped, step, play(model, looped, step, envelope), times)
        self.time = start + times[-1] + self.settings.measurement_time
        return np.abs(within) * self._mode_factor

    def reset_port(self, instrument: str) -> None:
        """Forget a partial command line and the queued replies (a port was reopened)."""
        self._input[instrument].clear()
        self.output[instrument].clear()

    def receive(self, instrument: str, data: bytes) -> None:
        """Feed bytes written to ``instrument``; the replies of its complete lines join ``output[instrument]``.

        A reply that finds the output queue full is lost and reported by the instrument, like
        a line that overruns the input buffer (:mod:`.buffers`).

        Raises
        ------
        SimulatedDisconnect
            When fault injection cuts the line; the command is not executed.
        """
        device = getattr(self, instrument)
        for raw in self._input[instrument].feed(data):
            if raw is OVERRUN:
                self._queue(instrument, device.input_overrun())
                continue
            line = raw.decode("ascii", errors="replace").strip()
            if not line:
                continue
            fault = self.faults.next_fault()
            if fault is Fault.DISCONNECT:
                self._input[instrument].clear()
                raise SimulatedDisconnect(f"simulated {instrument} disconnected at command {self.faults.commands}")
            reply = device.handle_line(line)
            if fault is not Fault.DROP:
                self._queue(instrument, reply, garble=fault is Fault.GARBLE)

    def _queue(self, instrument: str, reply: str | None, garble: bool = False) -> None:
        if reply is None:
            return
        encoded = reply.encode("ascii") + b"\n"
        if not self.output[instrument].put(self.faults.garble(encoded) if garble else encoded):
            getattr(self, instrument).reply_lost()


_BENCHES: dict[str, Bench] = {}
_NAMES = (f"bench{index}" for index in itertools.count(1))
DEFAULT_BENCH = "default"


def register_bench(bench: Bench, name: str | None = None) -> str:
    """Make ``bench`` reachable as ``tactile-sim://NAME/...``; returns NAME."""
    name = name or next(_NAMES)
    _BENCHES[name] = bench
    return name


def get_bench(name: str) -> Bench:
    """The bench registered as ``name``; ``default`` is created on first use with default settings."""
    if name == DEFAULT_BENCH and name not in _BENCHES:
        register_bench(Bench(default_bench_settings()), DEFAULT_BENCH)
    try:
        return _BENCHES[name]
    except KeyError:
        raise KeyError(f"no simulated bench named {name!r}; known: {', '.join(sorted(_BENCHES)) or 'none'}") from None
