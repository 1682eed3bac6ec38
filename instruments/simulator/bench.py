"""The simulated bench: a plate, the amplifier, a generator, a vibrometer controller and a lock-in sharing one clock.

Wiring (docs/instruments.md#wiring): generator -> amplifier -> ceramics; the laser spot's velocity ->
the vibrometer's decoder -> its analog output (velocity / range, delayed by the decoder's signal
delay, clipped at +-10 V) -> the lock-in's signal input; the generator's sync -> the lock-in's
reference input; the generator's trigger (a burst's start, a modulation period's start) -> the
lock-in's TRIG IN; the plate's temperature sensor (a thermocouple amplifier, 5 mV/deg C) -> the
lock-in's Aux In 1.

Time is simulated: each command line takes ``command_time`` of bench time (a serial exchange) and
:meth:`Bench.sleep` advances it, so simulated campaigns run as fast as the CPU allows and are
reproducible from their seeds.  Served on pseudo-terminals, the bench follows the wall clock instead
(:meth:`Bench.catch_up`): a client waiting for the lock-in to settle waits in real time.  After every command the plate's steady response to the drive is the
lock-in's input and sets the power it dissipates (:mod:`.thermal`); both are held until the next one.

A burst (``*TRG``) builds the plate up from rest and lets it ring down; an amplitude-modulated output
(``AM:STAT ON``) drives the envelope through the envelope equation (:mod:`workflow.damping.envelope`)
from rest at the last change of the output.  The lock-in's capture records them from its trigger.
"""

import itertools
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from instruments.drivers.amplifier import DEFAULT_CERAMIC_VOLTAGE_LIMIT, DEFAULT_GAIN, PowerAmplifier
from instruments.drivers.lockin import TEMPERATURE_SENSOR_SCALE
from instruments.simulator.builtplate import BuiltPlateModel
from instruments.simulator.buffers import OVERRUN, InputBuffer, OutputQueue
from instruments.simulator.faults import Fault, FaultInjector, FaultSettings
from instruments.simulator.generator import GeneratorDevice
from instruments.simulator.lockin import LockInDevice
from instruments.simulator.physics import PlateResponse, plate_response
from instruments.simulator.thermal import ThermalState
from instruments.simulator.vibrometer import DECODER_DELAY, DECODER_FULL_SCALE_OUTPUT, DECODER_RANGES, VibrometerDevice
from workflow import logformat
from workflow.damping.envelope import envelope_at, periodic_play, play
from workflow.damping.laws import law_parameters
from workflow.damping.mode_shape import BeamMode, measurement_factor
from workflow.models.plate import ORIGINAL_PLATE, Plate
from workflow.units import MM

INSTRUMENTS = ("generator", "vibrometer", "lockin")
DEFAULT_DRIFT_RATE = -0.02
"""Slow drift of the simulated resonance [Hz/s] (the room warming), on top of the plate's own heating."""
SETTLED_TIME_CONSTANTS = 30
"""A modulated drive playing for this many of the plate's slowest time constants is in its periodic steady state [-]."""
TEMPERATURE_AUX = 0
"""Aux In of the temperature sensor (0 is Aux In 1)."""
RESONANCE_RESOLUTION = 0.2
"""The plate's response is solved again once its resonance moved this much [Hz] (a thousandth of any tactile
plate's bandwidth: 0.04 deg of phase at Q = 54)."""


class SimulatedDisconnect(Exception):
    """The simulated port went dead (fault injection)."""


@dataclass(frozen=True)
class BenchSettings:
    """Everything that defines a simulated bench.

    Attributes
    ----------
    response : PlateResponse
        The plate's physics (f_r, gain, Q(v) law, drift, heating).
    amplifier_gain : float
        Voltage gain between generator and ceramics [V/V].
    ceramic_voltage_limit : float
        Safety limit on the peak voltage across the ceramics [V]; the simulated generator
        refuses settings beyond it (translated through the gain).
    command_time : float
        Bench time one command line takes (the serial exchange) [s].
    relative_noise : float
        Relative standard deviation of the velocity amplitude of a reading [-].
    floor_fraction : float
        Additive noise at the decoder's output, as a fraction of the lock-in's 1 V input range [-].
    phase_noise : float
        Phase noise of a reading [deg].
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
    decoder_ranges : tuple of float
        The vibrometer decoder's ranges [m/s/V].
    """

    response: PlateResponse
    amplifier_gain: float = DEFAULT_GAIN
    ceramic_voltage_limit: float = DEFAULT_CERAMIC_VOLTAGE_LIMIT
    command_time: float = 2e-3
    relative_noise: float = 0.005
    floor_fraction: float = 1e-3
    phase_noise: float = 0.2
    seed: int = 0
    faults: FaultSettings = field(default_factory=FaultSettings)
    wavelength: float = ORIGINAL_PLATE.wavelength
    measurement_point: tuple = (0.0, 0.0)
    built_plate: BuiltPlateModel | None = None
    decoder_ranges: tuple = DECODER_RANGES

    def mode_factor(self) -> float:
        """|phi| at the measurement point: the velocity read over the antinode's [-]."""
        return float(measurement_factor(BeamMode(self.wavelength), *self.measurement_point))

    def point_metadata(self) -> dict:
        """``x_mm``, ``y_mm`` and ``lambda_mm`` for the log header when the point is off the centre (else empty)."""
        if self.measurement_point == (0.0, 0.0):
            return {}
        x, y = self.measurement_point
        return {logformat.X_POSITION: x / MM, logformat.Y_POSITION: y / MM, logformat.LAMBDA_MM: self.wavelength / MM}

    def metadata(self) -> dict:
        """Flat ``simulator_*`` metadata for log headers: law, parameters, noise, drift, heating, seeds."""
        response = self.response
        items = {
            "law": response.law.name,
            **{f"law_{name}": value for name, value in law_parameters(response.law).items()},
            "resonance_frequency_hz": response.resonance_frequency,
            "deflection_per_volt_m_v": response.deflection_per_volt,
            "drift_rate_hz_s": response.drift_rate,
            **({"softening_s2_m2": response.softening} if response.softening else {}),
            **({} if response.thermal is None else response.thermal.metadata()),
            "amplifier_gain": self.amplifier_gain,
            "ceramic_voltage_limit_v": self.ceramic_voltage_limit,
            "command_time_s": self.command_time,
            "decoder_delay_us": DECODER_DELAY * 1e6,
            "relative_noise": self.relative_noise,
            "floor_fraction": self.floor_fraction,
            "phase_noise_deg": self.phase_noise,
            "seed": self.seed,
            **{f"fault_{name}": value for name, value in asdict(self.faults).items()},
            **({} if self.built_plate is None else self.built_plate.metadata()),
        }
        return {f"simulator_{key}": value for key, value in items.items()}


def default_bench_settings(plate: Plate = ORIGINAL_PLATE, law=None, drift_rate: float = DEFAULT_DRIFT_RATE,
                           softening: float = 0.0, heating: bool = True, **changes) -> BenchSettings:
    """Bench settings for ``plate`` (default law: :func:`.physics.default_law`, no softening, heating on);
    ``changes`` override fields."""
    changes.setdefault("wavelength", float(plate.wavelength))
    return BenchSettings(response=plate_response(plate, law, drift_rate, softening, heating), **changes)


def built_bench_settings(model: BuiltPlateModel, law=None, drift_rate: float = DEFAULT_DRIFT_RATE, **changes) -> BenchSettings:
    """Bench settings playing the built plate ``model`` (default law: that of its nominal plate); ``changes`` override fields."""
    return BenchSettings(response=model.response(law, drift_rate), built_plate=model, **changes)


@dataclass(frozen=True)
class Burst:
    """A burst fired at ``start`` [s]: ``cycles`` at ``frequency`` [Hz] and ``voltage`` [V peak across the ceramics]."""

    start: float
    cycles: int
    frequency: float
    voltage: float
    heating: float

    @property
    def end(self) -> float:
        return self.start + self.cycles / self.frequency


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
        self.peak_ceramic_voltage = 0.0
        """The largest peak voltage the ceramics saw [V] (every output change checked)."""
        self.vibrometer = VibrometerDevice(
            scanner=None if settings.built_plate is None else (settings.built_plate.surface.half_length,
                                                               settings.built_plate.surface.half_width),
            ranges=settings.decoder_ranges,
        )
        self.thermal = ThermalState(settings.response.thermal)
        self.resonance_shift = 0.0
        """An extra shift of the resonance [Hz] (a test knocking the plate off its resonance)."""
        self._mode_factor = settings.mode_factor()
        self._deflection = None
        """The plate's antinode deflection at the last update [m] (None: at rest): a softening plate's branch."""
        self._steady_key, self._steady = None, (0.0, 0j)
        self._bursts: list[Burst] = []
        self.lockin = LockInDevice(self.clock, self._lockin_signal, self._reference, self._trigger_after,
                                   self._aux_input, np.random.default_rng(settings.seed), settings.relative_noise,
                                   settings.phase_noise, settings.floor_fraction)
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

    def catch_up(self, elapsed: float) -> None:
        """Bring bench time to ``elapsed`` [s] if it is behind (a bench served in real time: the pseudo-terminals)."""
        self.time = max(self.time, elapsed)

    def ceramic_voltage(self) -> float:
        """Peak voltage across the ceramics now [V] (0 when the output is off or not a sine)."""
        state = self.generator.state
        if not state.output or state.function != "SIN":
            return 0.0
        return float(self.amplifier.ceramic_voltage(state.terminal_amplitude_vpp))

    def heating(self) -> float:
        """The plate's temperature rise over the ambient now [K]."""
        return self.thermal.advance(self.time)

    def temperature(self) -> float:
        """The plate's temperature now [deg C]."""
        return float(self.settings.response.temperature_at(self.time, self.heating()))

    def resonance(self) -> float:
        """The plate's small-amplitude resonance now [Hz]."""
        return float(self.settings.response.resonance_at(self.time, self.heating())) + self.resonance_shift

    # --- the plate's response -------------------------------------------------------------------

    def _response(self):
        """The plate's response with the test shift folded into its resonance."""
        response = self.settings.response
        if not self.resonance_shift:
            return response
        return replace(response, resonance_frequency=response.resonance_frequency + self.resonance_shift)

    def _steady_drive(self) -> float:
        """Drive amplitude the plate settles under now [V] (0 in burst mode; the mean of a modulated envelope)."""
        state = self.generator.state
        voltage = self.ceramic_voltage()
        if state.burst or not voltage:
            return 0.0
        modulation = self.generator.modulation()
        if modulation is not None:
            voltage *= (1 + state.am_depth / 100 * float(np.mean(modulation[0]))) / 2
        return voltage

    def _point_factor(self, frequency: float, antinode: float) -> complex:
        """Velocity phasor at the laser spot over the antinode's [-] (the beam mode, or the built plate's surface)."""
        model = self.settings.built_plate
        if model is None:
            return complex(self._mode_factor)
        q = float(self.settings.response.law.quality_factor(antinode))
        relative = frequency * model.resonance_frequency / self.resonance()
        return model.spatial_factor(*self.vibrometer.position, relative, q)

    def steady(self) -> tuple[float, complex]:
        """(antinode velocity amplitude [m/s], velocity phasor at the laser spot [m/s]) under the drive now."""
        state = self.generator.state
        voltage, heating = self._steady_drive(), self.heating()
        key = (state, voltage, self.vibrometer.position, round(self.resonance() / RESONANCE_RESOLUTION))
        if key != self._steady_key:
            self._steady_key = key
            if voltage == 0.0:
                self._deflection, self._steady = None, (0.0, 0j)
            else:
                velocity, phase = self._response().velocity(state.frequency, voltage, self.time, self._deflection, heating)
                velocity = float(velocity)
                self._deflection = velocity / (2 * np.pi * state.frequency)
                point = velocity * np.exp(1j * np.radians(float(phase))) * self._point_factor(state.frequency, velocity)
                self._steady = (velocity, complex(point))
        return self._steady

    def _decoder_output(self, point, frequency: float):
        """The decoder's analog output phasor [V peak] for the velocity phasor ``point`` [m/s] at ``frequency`` [Hz]:
        delayed by the decoder's signal delay, scaled by the range, clipped at +-10 V."""
        volts = np.asarray(point) * self.vibrometer.output_scale * np.exp(-2j * np.pi * frequency * DECODER_DELAY)
        magnitude = np.abs(volts)
        return np.where(magnitude > DECODER_FULL_SCALE_OUTPUT, volts * DECODER_FULL_SCALE_OUTPUT / np.maximum(magnitude, 1e-300), volts)

    # --- what the lock-in sees ------------------------------------------------------------------

    def _reference(self) -> tuple[float, bool]:
        """The generator's sync: (frequency [Hz], whether it is a continuous sine the lock-in can lock to)."""
        state = self.generator.state
        return state.frequency, state.function == "SIN" and not state.burst

    def _aux_input(self, channel: int) -> float:
        """Aux In ``channel`` (0-3) [V]: the temperature sensor on the first, nothing on the others."""
        return self.temperature() * TEMPERATURE_SENSOR_SCALE if channel == TEMPERATURE_AUX else 0.0

    def _lockin_signal(self, times=None, trigger: float | None = None):
        """The lock-in's input phasor [V peak]: now (``times`` None), or at ``times`` [s] after its capture's ``trigger`` [s]."""
        frequency = self.generator.state.frequency
        if times is None:
            return complex(self._decoder_output(self.steady()[1], frequency))
        burst = next((b for b in reversed(self._bursts) if b.start == trigger), None)
        if burst is not None:
            return self._decoder_output(self._burst_phasor(burst, np.asarray(times)), burst.frequency)
        if self.generator.modulation() is not None:
            return self._decoder_output(self._modulated_phasor(trigger + np.asarray(times)), frequency)
        return np.full(len(times), self._lockin_signal())

    def _burst_phasor(self, burst: Burst, times: np.ndarray) -> np.ndarray:
        """Velocity phasor at the laser spot [m/s] ``times`` [s] after ``burst`` started: build-up, then ring-down."""
        response = self._response()
        steady, phase = response.velocity(burst.frequency, burst.voltage, burst.start, heating=burst.heating)
        duration = burst.end - burst.start
        velocity = np.zeros_like(times)
        during, after = (times >= 0) & (times < duration), times >= duration
        velocity[during] = response.burst_build_up(burst.frequency, burst.voltage, times[during], burst.start, burst.heating)
        end = float(response.burst_build_up(burst.frequency, burst.voltage, duration, burst.start, burst.heating))
        velocity[after] = response.ringdown(end, times[after] - duration, burst.end, burst.heating)
        factor = self._point_factor(burst.frequency, float(steady))
        return velocity * np.exp(1j * np.radians(float(phase))) * factor

    def _modulated_phasor(self, times: np.ndarray) -> np.ndarray:
        """Velocity phasor at the laser spot [m/s] at ``times`` [s] under the modulated output, the plate at rest when
        the output last changed."""
        state = self.generator.state
        waveform, rate = self.generator.modulation()
        full = float(self.amplifier.ceramic_voltage(state.terminal_amplitude_vpp))
        drive = full * (1 + state.am_depth / 100 * waveform) / 2
        period, step = len(waveform) / rate, 1 / rate
        model = self._response().envelope_model(state.frequency, self.time, self.heating())
        elapsed = np.asarray(times) - self._output_since
        first = max(0.0, np.floor(np.min(elapsed) / period) * period)
        repeats = int(round(first / period))
        if first >= SETTLED_TIME_CONSTANTS * float(model.time_constant(0.0)):
            start = periodic_play(model, drive, step)[0]
        else:
            start = play(model, np.tile(drive, repeats), step)[-1] if repeats else 0.0
        relative = np.clip(elapsed - first, 0.0, None)
        looped = np.tile(drive, int(np.ceil(np.max(relative) / period)) + 1)
        envelope = envelope_at(model, looped, step, play(model, looped, step, start), relative)
        envelope = np.where(elapsed >= 0, envelope, 0.0)
        return envelope * self._point_factor(state.frequency, float(np.max(np.abs(envelope), initial=0.0)))

    def _trigger_after(self, after: float) -> float | None:
        """The first trigger on the lock-in's TRIG IN at or after ``after`` [s] that already came: a burst's start, or
        under modulation the start of a modulation period."""
        for burst in self._bursts:
            if after <= burst.start <= self.time:
                return burst.start
        modulation = self.generator.modulation()
        if modulation is None:
            return None
        period = len(modulation[0]) / modulation[1]
        start = self._output_since + np.ceil(max(0.0, after - self._output_since) / period - 1e-12) * period
        return float(start) if start <= self.time else None

    # --- events ---------------------------------------------------------------------------------

    def _burst(self) -> None:
        """A burst fired (``*TRG``): the plate builds up from rest for NCYC cycles, then rings down."""
        state = self.generator.state
        voltage = float(self.amplifier.ceramic_voltage(state.terminal_amplitude_vpp))
        self._bursts = [*self._bursts[-7:], Burst(self.time, state.burst_cycles, state.frequency, voltage, self.heating())]

    def _output_changed(self) -> None:
        self._output_since = self.time
        state = self.generator.state
        if state.output:
            peak = self.amplifier.ceramic_voltage(state.terminal_amplitude_vpp) * state.modulation_peak
            self.peak_ceramic_voltage = max(self.peak_ceramic_voltage, float(peak))

    def _update(self) -> None:
        """After a command: the power the plate now dissipates, and the lock-in's input."""
        velocity, _ = self.steady()
        self.thermal.set_power(self.time, self.settings.response.dissipated_power(self.generator.state.frequency, velocity))
        self.lockin.follow()

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
            fault = self.faults.next_fault(instrument)
            if fault is Fault.DISCONNECT:
                self._input[instrument].clear()
                raise SimulatedDisconnect(f"simulated {instrument} disconnected at command {self.faults.commands}")
            self.time += self.settings.command_time
            reply = device.handle_line(line)
            self._update()
            if fault is not Fault.DROP:
                self._queue(instrument, reply, garble=fault is Fault.GARBLE)

    def _queue(self, instrument: str, reply, garble: bool = False) -> None:
        if reply is None:
            return
        encoded = (reply if isinstance(reply, bytes) else reply.encode("ascii")) + b"\n"
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
