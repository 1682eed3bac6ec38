"""Driver for a Stanford Research SR860 lock-in amplifier (its RS-232/USB-serial command set, docs/instruments.md).

Commands are a mnemonic, a space and comma-separated arguments; queries end the mnemonic with
``?``; indices stand for the discrete settings (``SCAL 0`` is 1 V, ``OFLT 8`` is 10 ms), as in the
SR860 manual's command reference and PyMeasure's ``SR860`` class.  The instrument has no SCPI
error queue: a refused command sets a bit of the standard event status register, which
:meth:`LockIn.check_status` reads (``*ESR?``).

The capture buffer (``CAPTURECFG``, ``CAPTURERATE``, ``CAPTURELEN``, ``CAPTURESTART``,
``CAPTURESTAT?``, ``CAPTUREGET?``) records R and theta at rates 1.25 MHz / 2^k after a trigger on the
rear TRIG IN; ``CAPTUREGET? i,j`` answers j kB from kB i as an IEEE 488.2 binary block, ``#`` then one
digit n, n digits of length and the little-endian float32 values.  The pure functions below
(:func:`settle_time`, :func:`capture_interval`, :func:`capture_time_constant`) are the facts a plan
needs before talking to the instrument.
"""

import math
import struct
from dataclasses import dataclass

import numpy as np

from instruments.drivers.base import TERMINATOR, LineInstrument, control, measurement, parse_with
from instruments.drivers.errors import GarbledReply, InstrumentError, ReplyTimeout

TIME_CONSTANTS = tuple(m * 10.0**e for e in range(-6, 5) for m in (1, 3))
"""``OFLT`` index -> output filter time constant [s], 1 us to 30 ks."""
SENSITIVITIES = tuple(m * 10.0**e for e in range(0, -10, -1) for m in (1, 0.5, 0.2))[:28]
"""``SCAL`` index -> full-scale sensitivity [V rms], 1 V down to 1 nV."""
INPUT_RANGES = (1.0, 0.3, 0.1, 0.03, 0.01)
"""``IRNG`` index -> voltage input range [V peak]."""
SLOPE_POLES = (1, 2, 3, 4)
"""``OFSL`` index -> poles of the output filter (6, 12, 18, 24 dB/oct)."""
REFERENCE_SOURCES = ("INT", "EXT", "DUAL", "CHOP")
"""``RSRC`` index -> reference source."""
CAPTURE_CONFIGS = ("X", "XY", "RT", "XYRT")
"""``CAPTURECFG`` index -> what each capture sample holds."""
CAPTURE_BASE_RATE = 1.25e6
"""Every capture rate is this over a power of two [Sa/s]."""
CAPTURE_MAX_RATE_EXPONENT = 20
"""``CAPTURERATE n``: rate = ``CAPTURERATEMAX?`` / 2^n, n from 0 to this."""
CAPTURE_LENGTH_KB = (1, 4096)
"""``CAPTURELEN`` range [kB]."""
CAPTURE_GET_KB = 2
"""kB read per ``CAPTUREGET?`` (the SR860 answers up to 64 kB; 2 kB fits any instrument's output buffer here)."""
BYTES_PER_VALUE = 4
"""A captured value is a float32 [bytes]."""
OVERLOAD_OUTPUT = 0b11
"""``CUROVLDSTAT?`` bits 0 and 1: CH1 or CH2 output over its scale (the sensitivity)."""
OVERLOAD_UNLOCKED = 1 << 3
"""``CUROVLDSTAT?`` bit 3 (and ``LIAS?`` bit 3): the external reference is not locked."""
OVERLOAD_INPUT = 1 << 4
"""``CUROVLDSTAT?`` bit 4 (and ``LIAS?`` bit 4, latched): the signal input over its range."""
ESR_ERRORS = {4: "execution error (a parameter out of range)", 5: "command error (not a command)"}
"""``*ESR?`` bits the driver reports."""
TEMPERATURE_SENSOR_SCALE = 5e-3
"""The plate's temperature sensor on an Aux In: a thermocouple amplifier (AD8495 class), 5 mV per deg C [V/K]."""
CAPTURE_FILTER_POLES = 4
"""Output filter of a capture: 24 dB/oct."""
CAPTURE_MAX_TIME_CONSTANT = 10e-6
"""Longest time constant of a capture [s]: it follows a plate's envelope (tau >= 0.2 ms) and still removes the 2f
ripple of a 25-35 kHz carrier (-49 dB at 64 kHz with 24 dB/oct)."""
CAPTURE_SETTLE_CONSTANTS = 10
"""A capture's filter has forgotten a kink in the signal after this many time constants [-]."""


def settle_time(time_constant: float, poles: int, tolerance: float = 1e-3) -> float:
    """Time [s] for an output filter of ``poles`` stages of ``time_constant`` [s] to come within ``tolerance`` of a step.

    The error after t is exp(-x) sum_{j<n} x^j / j!, x = t / TC (n cascaded first-order stages).
    """
    def error(x):
        return math.exp(-x) * sum(x**j / math.factorial(j) for j in range(poles))

    low, high = 0.0, 1.0
    while error(high) > tolerance:
        low, high = high, 2 * high
    for _ in range(60):
        middle = (low + high) / 2
        low, high = (middle, high) if error(middle) > tolerance else (low, middle)
    return high * time_constant


def nearest_index(values, value: float) -> int:
    """Index of the entry of ``values`` nearest ``value`` on a log scale."""
    return int(np.argmin(np.abs(np.log(np.asarray(values)) - math.log(value))))


def capture_interval(requested: float, at_least: bool = False) -> float:
    """The capture interval 2^k / 1.25 MHz [s] nearest ``requested`` [s] (log scale), or the shortest not below it."""
    k = math.log2(requested * CAPTURE_BASE_RATE)
    return 2.0 ** max(0, math.ceil(k - 1e-9) if at_least else round(k)) / CAPTURE_BASE_RATE


def is_capture_interval(interval: float) -> bool:
    """Whether ``interval`` [s] is one of the capture intervals 2^k / 1.25 MHz."""
    return interval > 0 and math.isclose(capture_interval(interval), interval, rel_tol=1e-9)


def capture_time_constant(interval: float) -> float:
    """The output filter time constant [s] a capture at ``interval`` [s] uses: the longest at most interval / 4 and
    :data:`CAPTURE_MAX_TIME_CONSTANT`."""
    fitting = [tc for tc in TIME_CONSTANTS if tc <= min(interval / 4, CAPTURE_MAX_TIME_CONSTANT) * (1 + 1e-9)]
    return fitting[-1] if fitting else TIME_CONSTANTS[0]


def capture_delay(interval: float) -> float:
    """The group delay of a capture's output filter [s]: poles x time constant (a decay comes out this late)."""
    return CAPTURE_FILTER_POLES * capture_time_constant(interval)


def parse_binary_block(data: bytes) -> tuple:
    """The float32 little-endian values of an IEEE 488.2 definite-length block ``#n<length><bytes>``."""
    if len(data) < 2 or data[:1] != b"#" or not data[1:2].isdigit() or data[1:2] == b"0":
        raise ValueError(data[:16])
    digits = int(data[1:2])
    length = int(data[2:2 + digits])
    body = data[2 + digits:]
    if len(body) != length or length % BYTES_PER_VALUE:
        raise ValueError(data[:16])
    return struct.unpack(f"<{length // BYTES_PER_VALUE}f", body)


@dataclass(frozen=True)
class LockInReading:
    """R and theta at one instant (``SNAP? 2,3``) and the overload status then (``CUROVLDSTAT?``).

    Attributes
    ----------
    magnitude : float
        R [V rms].
    phase_deg : float
        theta, the signal's phase relative to the reference [deg].
    overload : int
        ``CUROVLDSTAT?`` bits (:data:`OVERLOAD_OUTPUT`, :data:`OVERLOAD_UNLOCKED`, :data:`OVERLOAD_INPUT`).
    """

    magnitude: float
    phase_deg: float
    overload: int


def _parse_status(reply: str) -> int:
    value = int(reply)
    if not 0 <= value < 1 << 16:
        raise ValueError(reply)
    return value


def _parse_reading(reply: str) -> LockInReading:
    """``R,theta;status`` (the replies of ``SNAP? 2,3;CUROVLDSTAT?``) -> a :class:`LockInReading`."""
    snap, status = reply.split(";")
    magnitude, phase = (float(item) for item in snap.split(","))
    if not (math.isfinite(magnitude) and magnitude >= 0 and math.isfinite(phase) and abs(phase) <= 180.0001):
        raise ValueError(reply)
    return LockInReading(magnitude, phase, _parse_status(status))


def _index_setting(mnemonic: str, values: tuple, doc: str):
    """A property setting the entry of ``values`` nearest the value given (log scale) and reading it back."""
    return control(f"{mnemonic}?", f"{mnemonic} {{}}", doc, parse=lambda reply: values[int(reply)],
                   format=lambda value: str(nearest_index(values, value)))


class LockIn(LineInstrument):
    """An SR860 on an open serial port (newline-terminated lines)."""

    def __init__(self, port):
        super().__init__(port, "lock-in")

    identity = measurement("*IDN?", "Manufacturer, model, serial number, firmware (str).")
    reference_source = control("RSRC?", "RSRC {}", "Reference source, INT or EXT (str).",
                               parse=lambda reply: REFERENCE_SOURCES[int(reply)],
                               format=lambda name: str(REFERENCE_SOURCES.index(name)))
    reference_trigger = control("RTRG?", "RTRG {}", "External reference trigger, 0 sine, 1 positive TTL, 2 negative TTL "
                                "(int).", parse=int, format=lambda mode: f"{int(mode):d}")
    frequency = control("FREQ?", "FREQ {}", "Reference frequency [Hz]: the internal one set, the external one measured "
                        "(float).", parse=float, format=lambda hz: f"{float(hz):.9g}")
    time_constant = _index_setting("OFLT", TIME_CONSTANTS, "Output filter time constant [s] (float).")
    sensitivity = _index_setting("SCAL", SENSITIVITIES, "Full-scale sensitivity [V rms] (float).")
    input_range = _index_setting("IRNG", INPUT_RANGES, "Voltage input range [V peak] (float).")
    filter_poles = control("OFSL?", "OFSL {}", "Poles of the output filter, 1 to 4 (int).",
                           parse=lambda reply: SLOPE_POLES[int(reply)], format=lambda n: str(SLOPE_POLES.index(int(n))))
    overload = measurement("CUROVLDSTAT?", "Overload status now (int bits).", parse=_parse_status)
    latched_status = measurement("LIAS?", "LIA status bits latched since the last read, which clears them (int).",
                                 parse=_parse_status)
    capture_max_rate = measurement("CAPTURERATEMAX?", "Fastest capture rate at this time constant [Sa/s] (float).",
                                   parse=float)
    capture_rate = measurement("CAPTURERATE?", "Capture rate [Sa/s] (float).", parse=float)
    capture_status = measurement("CAPTURESTAT?", "Capture state bits: 0 recording, 1 triggered, 2 wrapped (int).",
                                 parse=_parse_status)

    def aux_input(self, channel: int) -> float:
        """Voltage on rear Aux In ``channel`` (1 to 4) [V] (``OAUX? channel-1``)."""
        command = f"OAUX? {channel - 1}"
        return parse_with(float, command, self.query(command), self._where())

    READ = "SNAP? 2,3;CUROVLDSTAT?"
    """R and theta at one instant and the overload status, on one line (the replies joined by ``;``)."""

    def read(self) -> LockInReading:
        """R, theta and the overload status (:data:`READ`)."""
        return parse_with(_parse_reading, self.READ, self.query(self.READ), self._where())

    def set(self, command: str) -> None:
        """Send a setting (no reply)."""
        self.write(command)

    def check_status(self, after: str) -> None:
        """Raise :class:`InstrumentError` if ``*ESR?`` reports a refused command since the last check."""
        status = parse_with(_parse_status, "*ESR?", self.query("*ESR?"), self._where())
        problems = [text for bit, text in ESR_ERRORS.items() if status & 1 << bit]
        if problems:
            raise InstrumentError(f"{self._where()} reported {' and '.join(problems)} after {after}")

    def start_capture(self, config: str, rate_exponent: int, length_kb: int) -> None:
        """Stop any capture, configure one of ``length_kb`` kB of ``config`` values at the maximum rate / 2^``rate_exponent``,
        and arm it to start on the rear TRIG IN (``CAPTURESTART ONE, TRIG``)."""
        for command in ("CAPTURESTOP", f"CAPTURECFG {CAPTURE_CONFIGS.index(config)}", f"CAPTURERATE {rate_exponent:d}",
                        f"CAPTURELEN {length_kb:d}", "CAPTURESTART ONE, TRIG"):
            self.write(command)

    def capture_block(self, offset_kb: int, length_kb: int) -> tuple:
        """``length_kb`` kB of the stopped capture from kB ``offset_kb``: its float32 values, in order."""
        command = f"CAPTUREGET? {offset_kb:d}, {length_kb:d}"
        self.write(command)
        try:
            head = self.port.read(2)
            digits = int(head[1:2]) if head[:1] == b"#" and head[1:2].isdigit() else None
            if digits is None:
                raise GarbledReply(f"{self._where()}: reply {head!r} to {command!r} is no binary block")
            count = self.port.read(digits)
            body = self.port.read(int(count)) if count.isdigit() else b""
        except (OSError, ValueError) as error:
            raise GarbledReply(f"{self._where()}: unreadable binary block to {command!r}: {error}") from None
        data = head + count + body
        if not count.isdigit() or len(body) != int(count):
            raise ReplyTimeout(f"{self._where()}: binary block to {command!r} cut short ({len(data)} bytes)")
        if self.port.read(len(TERMINATOR)) not in (TERMINATOR, b""):
            raise GarbledReply(f"{self._where()}: binary block to {command!r} not followed by a line end")
        return parse_with(parse_binary_block, command, data, self._where())
