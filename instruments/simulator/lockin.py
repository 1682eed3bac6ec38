"""Simulated SR860 lock-in amplifier: the command subset of docs/instruments.md, an output filter that settles.

The signal input is the vibrometer decoder's analog output, a sine whose peak phasor u [V] (relative to
the reference) the bench supplies; between two commands it is held.  The outputs follow it through the
output filter, ``poles`` cascaded first-order stages of time constant TC, integrated exactly, so that a
reading taken too soon after a step of frequency, drive or decoder range is not settled.  Outputs are
in V rms, as the SR860's: X + iY = u e^{-i PHAS} / sqrt(2) once settled.  An input beyond the input
range is clipped (the fundamental of the clipped sine is what survives) and flagged; outputs beyond
the sensitivity are flagged, not clipped.  Noise (seeded) is added to each reading: a relative
amplitude error, a phase error, and a complex floor at the decoder output.

The reference is the generator's sync (``RSRC 1``: locked while the generator plays a continuous sine,
else ``CUROVLDSTAT?`` bit 3) or the internal oscillator (``RSRC 0``, ``FREQ``): an input off that
frequency comes out attenuated by the filter and rotating.

The capture buffer records R and theta (``CAPTURECFG 2``; X, XY, XYRT too) at ``CAPTURERATEMAX?`` / 2^n
from the trigger (``CAPTURESTART ONE|CONT, IMM|TRIG``): the bench supplies the input phasor at any time
(a burst building up and ringing down, a modulated envelope), the device filters it on a fine grid and
adds the noise.  The simulator's maximum rate is the largest 1.25 MHz / 2^m at most 8 / TC.
"""

import math
import struct
from collections.abc import Callable

import numpy as np
from scipy.signal import lfilter

from instruments.drivers.lockin import (
    CAPTURE_BASE_RATE,
    CAPTURE_CONFIGS,
    CAPTURE_LENGTH_KB,
    CAPTURE_MAX_RATE_EXPONENT,
    INPUT_RANGES,
    OVERLOAD_INPUT,
    OVERLOAD_UNLOCKED,
    REFERENCE_SOURCES,
    SENSITIVITIES,
    SLOPE_POLES,
    TIME_CONSTANTS,
)

IDENTITY = "Stanford_Research_Systems,SR860,TACTILE-SIM,1.0-sim"
"""``*IDN?`` reply (manufacturer, model, serial, firmware) in the SR860's format."""
FREQUENCY_RANGE = (1e-3, 500e3)
"""Reference frequency range [Hz]."""
SAMPLES_PER_TIME_CONSTANT = 8.0
"""The simulator's fastest capture rate is the largest 1.25 MHz / 2^m at most this over TC [-]."""
FILTER_STEPS_PER_CONSTANT = 8
"""Steps of the capture's filter integration per time constant (at least per sample) [-]."""
SNAP_PARAMETERS = ("X", "Y", "R", "THeta", "IN1", "IN2", "IN3", "IN4", "XNOise", "YNOise", "OUT1", "OUT2",
                   "PHAse", "SAMp", "LEVel", "FInt", "FExt")
"""``OUTP?``/``SNAP?`` parameters by index; the capitals are the short form."""
CMD_ERROR = 5
EXE_ERROR = 4
"""``*ESR?`` bits: an unknown command, a parameter out of range."""


class _Refused(Exception):
    def __init__(self, bit: int):
        self.bit = bit


def _parameter(text: str) -> int:
    """Index of an ``OUTP?``/``SNAP?`` parameter given by number or (short or long) name."""
    word = text.strip()
    if word.isdigit() and int(word) < len(SNAP_PARAMETERS):
        return int(word)
    for index, name in enumerate(SNAP_PARAMETERS):
        if word.upper() in (name.upper(), "".join(c for c in name if c.isupper())):
            return index
    raise _Refused(EXE_ERROR)


def _index(text: str, count: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise _Refused(EXE_ERROR) from None
    if not 0 <= value < count:
        raise _Refused(EXE_ERROR)
    return value


def _number(text: str, low: float, high: float) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _Refused(EXE_ERROR) from None
    if not (math.isfinite(value) and low <= value <= high):
        raise _Refused(EXE_ERROR)
    return value


def clipped_fundamental(amplitude, limit):
    """Fundamental of a sine of ``amplitude`` clipped at +-``limit`` [same unit]: (2A/pi)(asin c + c sqrt(1-c^2)), c = limit/A."""
    amplitude = np.asarray(amplitude, dtype=float)
    ratio = np.clip(limit / np.maximum(amplitude, 1e-300), 0.0, 1.0)
    clipped = 2 * amplitude / np.pi * (np.arcsin(ratio) + ratio * np.sqrt(1 - ratio**2))
    return np.where(amplitude > limit, clipped, amplitude)


def filter_error(x: float, poles: int, errors: np.ndarray) -> np.ndarray:
    """Stage errors after x = t / TC of a cascade whose stage errors were ``errors`` (complex, first stage first)."""
    out = np.empty_like(errors)
    for k in range(poles):
        out[k] = math.exp(-x) * sum(errors[j] * x ** (k - j) / math.factorial(k - j) for j in range(k + 1))
    return out


class LockInDevice:
    """The SR860's command interpreter, output filter and capture buffer.

    Parameters
    ----------
    clock : callable
        () -> bench time [s].
    signal : callable
        (times [s] array or None, trigger [s]) -> input phasor u [V peak] relative to the external reference:
        at the bench's present state (None), or at ``times`` after a capture's ``trigger``.
    reference : callable
        () -> the external reference: (frequency [Hz], locked) from the generator's sync.
    trigger : callable
        (after [s]) -> time [s] of the first trigger on TRIG IN at or after ``after`` that already came (None if none).
    aux : callable
        (channel 0-3) -> voltage on Aux In [V].
    rng : numpy.random.Generator
    relative_noise, phase_noise, floor : float
        Noise of a reading: relative amplitude [-], phase [deg], complex floor at the input [V peak].
    """

    def __init__(self, clock: Callable, signal: Callable, reference: Callable, trigger: Callable, aux: Callable,
                 rng, relative_noise: float, phase_noise: float, floor: float):
        self.clock, self.signal, self.external, self.trigger, self.aux = clock, signal, reference, trigger, aux
        self.rng = rng
        self.relative_noise, self.phase_noise, self.floor = relative_noise, phase_noise, floor
        self._filter_time = clock()
        self._input = 0j
        self._reset()
        self.event_status = 0
        self._commands = {
            "*IDN?": lambda args: IDENTITY, "*RST": lambda args: self._reset(), "*CLS": self._clear,
            "*ESR?": self._read_esr, "*STB?": lambda args: "0",
            "RSRC": lambda args: self._set_index("reference", args, len(REFERENCE_SOURCES)),
            "RSRC?": lambda args: str(self.state["reference"]),
            "RTRG": lambda args: self._set_index("trigger_mode", args, 3), "RTRG?": lambda args: str(self.state["trigger_mode"]),
            "REFZ": lambda args: self._set_index("reference_impedance", args, 2),
            "REFZ?": lambda args: str(self.state["reference_impedance"]),
            "FREQ": self._set_frequency, "FREQ?": lambda args: f"{self._reference_frequency():.9g}",
            "FREQINT": self._set_frequency, "FREQINT?": lambda args: f"{self.state['frequency']:.9g}",
            "FREQEXT?": lambda args: f"{self.external()[0]:.9g}",
            "FREQDET?": lambda args: f"{self._reference_frequency():.9g}",
            "PHAS": lambda args: self._set_number("phase", args, -360000.0, 360000.0),
            "PHAS?": lambda args: f"{self.state['phase']:.7f}",
            "HARM": lambda args: self._set_number("harmonic", args, 1, 99), "HARM?": lambda args: f"{self.state['harmonic']:g}",
            "SLVL": lambda args: self._set_number("sine_level", args, 0.0, 2.0), "SLVL?": lambda args: f"{self.state['sine_level']:.9e}",
            "SOFF": lambda args: self._set_number("sine_offset", args, -5.0, 5.0), "SOFF?": lambda args: f"{self.state['sine_offset']:.4f}",
            "IVMD": lambda args: self._set_index("input_mode", args, 2), "IVMD?": lambda args: str(self.state["input_mode"]),
            "ISRC": lambda args: self._set_index("input_config", args, 2), "ISRC?": lambda args: str(self.state["input_config"]),
            "ICPL": lambda args: self._set_index("coupling", args, 2), "ICPL?": lambda args: str(self.state["coupling"]),
            "IGND": lambda args: self._set_index("shield", args, 2), "IGND?": lambda args: str(self.state["shield"]),
            "IRNG": lambda args: self._set_index("input_range", args, len(INPUT_RANGES)),
            "IRNG?": lambda args: str(self.state["input_range"]),
            "SCAL": lambda args: self._set_index("sensitivity", args, len(SENSITIVITIES)),
            "SCAL?": lambda args: str(self.state["sensitivity"]),
            "OFLT": lambda args: self._set_index("time_constant", args, len(TIME_CONSTANTS)),
            "OFLT?": lambda args: str(self.state["time_constant"]),
            "OFSL": lambda args: self._set_index("slope", args, len(SLOPE_POLES)), "OFSL?": lambda args: str(self.state["slope"]),
            "SYNC": lambda args: self._set_index("sync", args, 2), "SYNC?": lambda args: str(self.state["sync"]),
            "ILVL?": self._input_level, "ENBW?": lambda args: f"{self._noise_bandwidth():.6g}",
            "OUTP?": self._output, "SNAP?": self._snap, "SNAPD?": lambda args: self._snap(["0", "1", "2", "3"]),
            "OAUX?": lambda args: f"{self.aux(_index(self._one(args), 4)):.6g}",
            "AUXV": self._set_aux_out, "AUXV?": lambda args: f"{self.state['aux_out'][_index(self._one(args), 4)]:.4f}",
            "CUROVLDSTAT?": lambda args: str(self._overload()), "LIAS?": self._read_latched,
            "LIAE": lambda args: None, "LIAE?": lambda args: "0", "ERRS?": lambda args: "0",
            "APHS": self._auto_phase,
            "CAPTURELEN": lambda args: self._set_number("capture_kb", args, *CAPTURE_LENGTH_KB, integer=True),
            "CAPTURELEN?": lambda args: str(self.state["capture_kb"]),
            "CAPTURECFG": self._set_capture_config, "CAPTURECFG?": lambda args: str(self.state["capture_config"]),
            "CAPTURERATEMAX?": lambda args: f"{self.max_capture_rate():.9g}",
            "CAPTURERATE": lambda args: self._set_index("capture_exponent", args, CAPTURE_MAX_RATE_EXPONENT + 1),
            "CAPTURERATE?": lambda args: f"{self._capture_rate():.9g}",
            "CAPTURESTART": self._capture_start, "CAPTURESTOP": self._capture_stop,
            "CAPTURESTAT?": lambda args: str(self._capture_status()),
            "CAPTUREBYTES?": lambda args: str(self._captured_samples() * self._capture_width() * 4),
            "CAPTUREPROG?": lambda args: str(2 * math.ceil(self._captured_samples() * self._capture_width() * 4 / 2048)),
            "CAPTUREVAL?": self._capture_value, "CAPTUREGET?": self._capture_get,
        }

    # --- state, settings ------------------------------------------------------------------------

    def _reset(self):
        self.state = {"reference": 0, "trigger_mode": 0, "reference_impedance": 1, "frequency": 1000.0, "phase": 0.0,
                      "harmonic": 1, "sine_level": 0.0, "sine_offset": 0.0, "input_mode": 0, "input_config": 0,
                      "coupling": 0, "shield": 0, "input_range": 0, "sensitivity": 0, "time_constant": 10, "slope": 1,
                      "sync": 0, "aux_out": [0.0] * 4, "capture_kb": 256, "capture_config": 0, "capture_exponent": 0}
        self.latched = 0
        self._capture = None
        self._stages = np.zeros(SLOPE_POLES[-1], dtype=complex)

    def _clear(self, args):
        self.event_status = 0
        self.latched = 0

    def _read_esr(self, args):
        value, self.event_status = self.event_status, 0
        return str(value)

    def _read_latched(self, args):
        if self._triggered() is not None and not self._capture_status() & 1:
            self._capture_data()  # a finished capture's overloads are latched once it is computed
        value = self.latched | self._overload()
        self.latched = 0
        return str(value)

    @staticmethod
    def _one(args: list) -> str:
        if len(args) != 1:
            raise _Refused(EXE_ERROR)
        return args[0]

    def _set_index(self, key: str, args: list, count: int):
        self.follow()
        self.state[key] = _index(self._one(args), count)

    def _set_number(self, key: str, args: list, low: float, high: float, integer: bool = False):
        value = _number(self._one(args), low, high)
        if integer and value != int(value):
            raise _Refused(EXE_ERROR)
        self.follow()
        self.state[key] = int(value) if integer or key == "harmonic" else value

    def _set_frequency(self, args: list):
        self._set_number("frequency", args, *FREQUENCY_RANGE)

    def _set_aux_out(self, args: list):
        if len(args) != 2:
            raise _Refused(EXE_ERROR)
        self.state["aux_out"][_index(args[0], 4)] = _number(args[1], -10.5, 10.5)

    def _set_capture_config(self, args: list):
        word = self._one(args).strip().upper()
        self.state["capture_config"] = CAPTURE_CONFIGS.index(word) if word in CAPTURE_CONFIGS else _index(word, 4)
        self._capture = None

    @property
    def time_constant(self) -> float:
        return TIME_CONSTANTS[self.state["time_constant"]]

    @property
    def poles(self) -> int:
        return SLOPE_POLES[self.state["slope"]]

    def _noise_bandwidth(self) -> float:
        """Equivalent noise bandwidth of the output filter [Hz]: 1/4, 1/8, 3/32, 5/64 over TC for 1 to 4 poles."""
        factor = {1: 1 / 4, 2: 1 / 8, 3: 3 / 32, 4: 5 / 64}[self.poles]
        return factor / self.time_constant

    # --- the signal through the reference and the output filter ---------------------------------

    def _reference_frequency(self) -> float:
        return self.external()[0] if self.state["reference"] == 1 else self.state["frequency"]

    def _relative(self, phasor, frequency_offset: float, time):
        """The input seen against the reference: rotated by an internal reference off the signal's frequency."""
        return phasor * np.exp(2j * np.pi * frequency_offset * np.asarray(time))

    def _response(self, frequency_offset: float) -> complex:
        """The output filter's response to an input ``frequency_offset`` [Hz] off the reference, (1 + i w TC)^-n."""
        return (1 + 2j * np.pi * frequency_offset * self.time_constant) ** -self.poles

    def _offset(self) -> float:
        """Signal frequency minus reference frequency [Hz] (0 when locked to the generator's sync)."""
        return 0.0 if self.state["reference"] == 1 else self.external()[0] - self.state["frequency"]

    def _conditioned(self, phasor):
        """The input after the input stage: clipped at the range, as X + iY [V rms] before the filter."""
        limit = INPUT_RANGES[self.state["input_range"]]
        amplitude = clipped_fundamental(np.abs(phasor), limit)
        return amplitude * np.exp(1j * (np.angle(phasor) - np.radians(self.state["phase"]))) / math.sqrt(2)

    def follow(self) -> None:
        """Integrate the output filter to now with the input held since the last update, then take the present input."""
        now = self.clock()
        x = (now - self._filter_time) / self.time_constant
        if x > 0:
            errors = self._stages[: self.poles] - self._input
            self._stages[: self.poles] = self._input + filter_error(x, self.poles, errors)
        self._filter_time = now
        unlocked = self.state["reference"] == 1 and not self.external()[1]
        self._input = 0j if unlocked else complex(self._conditioned(self.signal(None)))

    def _overload(self) -> int:
        bits = 0
        if abs(self.signal(None)) > INPUT_RANGES[self.state["input_range"]]:
            bits |= OVERLOAD_INPUT
        if self.state["reference"] == 1 and not self.external()[1]:
            bits |= OVERLOAD_UNLOCKED
        output = self._stages[self.poles - 1]
        scale = SENSITIVITIES[self.state["sensitivity"]]
        bits |= (abs(output.real) > scale) | (abs(output.imag) > scale) << 1
        self.latched |= bits
        return bits

    def _noisy(self, output, size=None):
        """``output`` [V rms, complex] with the reading's noise."""
        noise = self.rng.standard_normal((4,) if size is None else (4, size))
        floor = self.floor / math.sqrt(2) * (noise[2] + 1j * noise[3]) / math.sqrt(2)
        return output * (1 + self.relative_noise * noise[0]) * np.exp(1j * np.radians(self.phase_noise * noise[1])) + floor

    def _values(self, output) -> dict:
        return {0: output.real, 1: output.imag, 2: np.abs(output), 3: np.degrees(np.angle(output))}

    def _reading(self, indices: list) -> str:
        self.follow()
        offset = self._offset()
        output = self._noisy(self._relative(self._stages[self.poles - 1] * self._response(offset), offset, self.clock()))
        values = self._values(complex(output))
        other = {12: self.state["phase"], 13: self.state["sine_level"], 14: self.state["sine_offset"],
                 15: self.state["frequency"], 16: self.external()[0]}
        replies = []
        for index in indices:
            if index in values:
                replies.append(values[index])
            elif 4 <= index <= 7:
                replies.append(self.aux(index - 4))
            elif index in (10, 11):
                replies.append(self.state["aux_out"][index - 10])
            elif index in other:
                replies.append(other[index])
            else:
                replies.append(0.0)
        return ",".join(f"{value:.10e}" for value in replies)

    def _output(self, args: list):
        return self._reading([_parameter(self._one(args))])

    def _snap(self, args: list):
        if not 2 <= len(args) <= 3:
            raise _Refused(EXE_ERROR)
        return self._reading([_parameter(arg) for arg in args])

    def _input_level(self, args):
        ratio = abs(self.signal(None)) / INPUT_RANGES[self.state["input_range"]]
        return str(4 if ratio > 1 else 3 if ratio > 0.5 else 2 if ratio > 0.1 else 1 if ratio > 0.01 else 0)

    def _auto_phase(self, args):
        self.follow()
        output = self._stages[self.poles - 1]
        if abs(output):
            self.state["phase"] = (self.state["phase"] + math.degrees(np.angle(output)) + 180) % 360 - 180

    # --- capture buffer ------------------------------------------------------------------------

    def max_capture_rate(self) -> float:
        """The largest 1.25 MHz / 2^m at most 8 / TC [Sa/s]."""
        m = max(0, math.ceil(math.log2(CAPTURE_BASE_RATE * self.time_constant / SAMPLES_PER_TIME_CONSTANT) - 1e-9))
        return CAPTURE_BASE_RATE / 2**m

    def _capture_rate(self) -> float:
        return self.max_capture_rate() / 2 ** self.state["capture_exponent"]

    def _capture_width(self) -> int:
        return (1, 2, 2, 4)[self.state["capture_config"]]

    def _capture_length(self) -> int:
        """Samples the buffer holds."""
        return self.state["capture_kb"] * 1024 // (4 * self._capture_width())

    def _capture_start(self, args: list):
        if len(args) != 2:
            raise _Refused(EXE_ERROR)
        acquisition = {"ONE": 0, "0": 0, "CONT": 1, "1": 1}.get(args[0].strip().upper())
        start = {"IMM": 0, "0": 0, "TRIG": 1, "1": 1, "SAMP": 2, "2": 2}.get(args[1].strip().upper())
        if acquisition is None or start is None or start == 2:
            raise _Refused(EXE_ERROR)
        now = self.clock()
        self._capture = {"armed": now, "trigger": now if start == 0 else None, "stopped": None, "continuous": acquisition,
                         "rate": self._capture_rate(), "length": self._capture_length(), "data": None}

    def _capture_stop(self, args):
        if self._capture is not None and self._capture["stopped"] is None:
            self._capture["stopped"] = self.clock()

    def _triggered(self):
        """The capture's start time, once its trigger came (None while waiting or without a capture)."""
        capture = self._capture
        if capture is None:
            return None
        if capture["trigger"] is None:
            capture["trigger"] = self.trigger(capture["armed"])
        return capture["trigger"]

    def _captured_samples(self) -> int:
        start = self._triggered()
        if start is None:
            return 0
        capture = self._capture
        end = self.clock() if capture["stopped"] is None else capture["stopped"]
        count = int(max(0.0, end - start) * capture["rate"]) + 1
        if capture["continuous"]:
            return min(count, capture["length"])
        if count >= capture["length"] and capture["stopped"] is None:
            capture["stopped"] = start + (capture["length"] - 1) / capture["rate"]
        return min(count, capture["length"])

    def _capture_status(self) -> int:
        start = self._triggered()
        if start is None:
            return 0
        count = self._captured_samples()
        recording = self._capture["stopped"] is None
        return int(recording) | 2 | (4 if count >= self._capture["length"] else 0)

    def _capture_data(self) -> np.ndarray:
        """The captured samples (rows: samples; columns: the configured values), computed once the capture stopped."""
        capture = self._capture
        if capture["data"] is None:
            count = self._captured_samples()
            times = np.arange(count) / capture["rate"]
            output = self._filtered(capture["trigger"], times)
            values = self._values(output)
            columns = {0: (0,), 1: (0, 1), 2: (2, 3), 3: (0, 1, 2, 3)}[self.state["capture_config"]]
            capture["data"] = np.column_stack([np.asarray(values[c], dtype=np.float32) for c in columns])
        return capture["data"]

    def _filtered(self, start: float, times: np.ndarray) -> np.ndarray:
        """The outputs [V rms] at ``times`` after ``start``, the input recorded from the trigger, filtered on a fine grid."""
        tc, poles = self.time_constant, self.poles
        step = min(tc / FILTER_STEPS_PER_CONSTANT, 1 / self._capture["rate"])
        preroll = 12 * poles * tc
        grid = np.arange(-preroll, times[-1] + step, step)
        phasor = self.signal(grid, start)
        limit = INPUT_RANGES[self.state["input_range"]]
        if np.any(np.abs(phasor[grid >= 0]) > limit):
            self.latched |= OVERLOAD_INPUT
        seen = self._relative(self._conditioned(phasor), self._offset(), start + grid)
        decay = math.exp(-step / tc)
        for _ in range(poles):
            seen = lfilter([1 - decay], [1, -decay], seen)
        output = np.interp(times, grid, seen.real) + 1j * np.interp(times, grid, seen.imag)
        return self._noisy(output, len(times))

    def _stopped_data(self):
        if self._triggered() is None or self._capture_status() & 1:
            raise _Refused(EXE_ERROR)
        return self._capture_data()

    def _capture_value(self, args: list):
        data = self._stopped_data()
        index = _index(self._one(args), max(1, len(data)))
        return ",".join(f"{value:.7e}" for value in data[index]) if index < len(data) else "0"

    def _capture_get(self, args: list):
        if len(args) != 2:
            raise _Refused(EXE_ERROR)
        offset, length = _index(args[0], 4097), _index(args[1], 65)
        flat = self._stopped_data().ravel()
        values = np.zeros(self.state["capture_kb"] * 256, dtype=np.float32)
        values[: len(flat)] = flat
        block = np.roll(values, -offset * 256)[: length * 256]
        body = struct.pack(f"<{len(block)}f", *block)
        return f"#{len(str(len(body)))}{len(body)}".encode("ascii") + body

    # --- lines ---------------------------------------------------------------------------------

    def handle_line(self, line: str):
        """Execute one line (commands separated by ``;``); the reply (str, or bytes for a binary block) or None."""
        replies = []
        for command in (part.strip() for part in line.split(";")):
            if not command:
                continue
            mnemonic, _, rest = command.partition(" ")
            args = [arg.strip() for arg in rest.split(",")] if rest.strip() else []
            handler = self._commands.get(mnemonic.upper())
            try:
                if handler is None:
                    raise _Refused(CMD_ERROR)
                reply = handler(args)
            except _Refused as refused:
                self.event_status |= 1 << refused.bit
                break
            if reply is not None:
                replies.append(reply)
        if not replies:
            return None
        if any(isinstance(reply, bytes) for reply in replies):
            return b";".join(r if isinstance(r, bytes) else r.encode("ascii") for r in replies)
        return ";".join(replies)

    def input_overrun(self) -> None:
        """A command line overran the input buffer: a command error."""
        self.event_status |= 1 << CMD_ERROR

    def reply_lost(self) -> None:
        """A reply found the output queue full (*ESR? bit 2, query error)."""
        self.event_status |= 1 << 2
