"""Driver for a Keysight/Agilent 33500-series function generator (the SCPI subset of docs/instruments.md).

The driver refuses, before sending anything, any setting whose output peak voltage
(amplitude/2 + |offset|) exceeds ``max_peak_voltage``: the safety limit across the
ceramics translated through the amplifier gain.  The limit is decided on the
instrument's real state, read just before: amplitudes are always volts peak-to-peak,
and every amplitude command *and query* sets ``VOLT:UNIT VPP`` on the same line, so an
instrument left in ``VRMS`` (or ``DBM``) is neither misread nor mis-set.  The peak
amplitude/2 + |offset| bounds the output of every function (for ``DC`` the level is the
offset alone; counting the amplitude too errs on the safe side).  The instrument states
levels into its load setting (``OUTP:LOAD``, 50 ohm after ``*RST``); into the amplifier's
high-impedance input the terminals carry (R_load + 50 ohm) / R_load times that, twice at
50 ohm, so every limit decision reads the load setting and counts that factor.  Levels and
the load are set only through ``amplitude_vpp``, ``offset`` and ``load_ohm``:
:meth:`FunctionGenerator.write` (under ``set`` and ``query``) refuses any other command that
sets a level or the load, and ``write`` refuses queries (an unread reply would answer the next query).
An amplitude-modulation depth above 100 % would raise the output's peak above the carrier's
amplitude: ``AM:DEPT`` is a level command too, set through ``am_depth`` (at most 100 %), and
:meth:`FunctionGenerator.play_modulated` loads and starts an arbitrary-waveform modulation
(:mod:`.arbitrary`) after checking its carrier amplitude against the limit.
"""

import math
import re
from decimal import ROUND_DOWN, Decimal

from instruments.drivers.arbitrary import ModulatedDrive
from instruments.drivers.base import LineInstrument, control, measurement, parse_with
from instruments.drivers.errors import InstrumentError, SafetyLimitError

NO_ERROR_CODE = 0
FREQUENCY_RANGE = (1e-6, 20e6)
"""The 33500 series' sine frequency range [Hz] (what a plan may ask of it; the simulator accepts the same)."""
AMPLITUDE_RANGE = (1e-3, 10.0)
"""The 33500 series' amplitude range of the output stage [V peak-to-peak]."""
LOWEST_AMPLITUDE_VPP = AMPLITUDE_RANGE[0]
"""The smallest amplitude [V peak-to-peak]: the safe state left at the end of a run."""
AMPLITUDE_QUERY = "VOLT:UNIT VPP;:VOLT?"
"""The amplitude in V peak-to-peak whatever unit the instrument was left in."""
_LEVEL_NODE = re.compile(r"VOLT|OFFS|AMPL|APPL|HIGH|LOW|LEV|LOAD|DEPT|AM$", re.IGNORECASE)
"""Header nodes that set an output level, the load the level is stated into, or the modulation depth
(``AM <depth>`` is ``AM:DEPT``'s short form) when given an argument (``VOLT:UNIT`` only renames it)."""
MAX_AM_DEPTH = 100.0
"""Largest amplitude-modulation depth the driver sets [%]: the output's peak stays the carrier's amplitude."""
SOURCE_IMPEDANCE_OHM = 50.0
"""The 33500 series' output impedance [ohm]."""
HIGH_Z_THRESHOLD_OHM = 1e37
"""``OUTP:LOAD?`` answers 9.9E+37 for the High Z setting [ohm]."""


def _scpi_bool(reply: str) -> bool:
    return {"1": True, "0": False, "ON": True, "OFF": False}[reply.strip().upper()]


def _parse_error(reply: str) -> tuple[int, str]:
    code, separator, message = reply.partition(",")
    if not separator:
        raise ValueError(reply)
    return int(code), message.strip().strip('"')


def _parse_load(reply: str) -> float:
    value = float(reply)
    if not value > 0:
        raise ValueError(reply)
    return value


def _number(value: float) -> str:
    return f"{float(value):.9g}"


def _level(value: float) -> str:
    """A level [V] in 9 significant digits rounded toward zero: what the instrument sets is never above what the limit
    was checked on (``:.9g`` rounds to nearest: 1.732421875 Vpp went out as 1.73242188, found by the driver's fuzz
    test)."""
    number = Decimal(repr(float(value)))
    if not number:
        return "0"
    digits = number.quantize(Decimal(1).scaleb(number.adjusted() - 8), rounding=ROUND_DOWN)
    return format(digits.normalize(), "f")


def _sets_level(line: str) -> bool:
    """Whether a program line holds a command setting an output level (amplitude, offset, high/low, APPLy)."""
    for command in re.split(r"[;\r\n]", line):
        header, _, argument = command.strip().partition(" ")
        if argument.strip() and _LEVEL_NODE.search(header) and not header.upper().endswith(":UNIT"):
            return True
    return False


def _open_circuit_gain(load_ohm: float) -> float:
    """(R_load + 50 ohm) / R_load, 1 for High Z [-]."""
    return 1.0 if math.isinf(load_ohm) else (load_ohm + SOURCE_IMPEDANCE_OHM) / load_ohm


def amplitude_command(vpp: float) -> str:
    """The line that sets the amplitude to ``vpp`` [V peak-to-peak] whatever unit the instrument was left in."""
    return f"VOLT:UNIT VPP;:VOLT {_level(vpp)}"


def modulation_script(drive: ModulatedDrive) -> list:
    """Every line that plays ``drive`` on a 33500 from any state: output off and High Z load (the amplifier's
    input), no offset, the modulation setup, the carrier amplitude, output on (what ``tactile render`` writes
    for a user's own client; the procedures send the same through :meth:`FunctionGenerator.play_modulated`)."""
    return ["OUTP 0", "OUTP:LOAD INF", "VOLT:OFFS 0", *drive.setup_commands(), amplitude_command(drive.amplitude_vpp),
            "OUTP 1"]


def check_voltage_limit(limit: float) -> float:
    """``limit`` [V] if it is a finite number > 0, else ValueError naming the accepted range."""
    if not (isinstance(limit, (int, float)) and math.isfinite(limit) and limit > 0):
        raise ValueError(f"a safety limit must be a finite number of volts > 0, got {limit!r}")
    return float(limit)


class FunctionGenerator(LineInstrument):
    """A 33500-series generator, channel 1, on an open serial port.

    Parameters
    ----------
    port : serial.SerialBase
        Open port; replies end with a newline.
    max_peak_voltage : float
        Largest output peak voltage allowed, amplitude/2 + |offset| [V]: finite and > 0
        (ValueError otherwise); fixed for the driver's life.
    """

    def __init__(self, port, max_peak_voltage: float):
        super().__init__(port, "signal generator")
        self._max_peak_voltage = check_voltage_limit(max_peak_voltage)

    @property
    def max_peak_voltage(self) -> float:
        """Largest output peak voltage allowed [V] (read-only)."""
        return self._max_peak_voltage

    identity = measurement("*IDN?", "Manufacturer, model, serial number, firmware (str).")
    function = control("FUNC?", "FUNC {}", "Waveform shape, e.g. ``SIN`` (str).", parse=str.upper)
    frequency = control("FREQ?", "FREQ {}", "Output frequency [Hz] (float).", parse=float, format=_number)

    amplitude_unit = measurement("VOLT:UNIT?", "Unit of ``VOLT`` (str); the driver sets ``VPP`` whenever it uses ``VOLT``.",
                                 parse=str.upper)

    @property
    def amplitude_vpp(self) -> float:
        """Output amplitude [V peak-to-peak], read in ``VPP`` whatever unit the instrument was left in."""
        return parse_with(float, AMPLITUDE_QUERY, self.query(AMPLITUDE_QUERY), self._where())

    @amplitude_vpp.setter
    def amplitude_vpp(self, vpp: float) -> None:
        self.check_peak_voltage(vpp, self.offset)
        self._send(amplitude_command(vpp))

    @property
    def output(self) -> bool:
        """Output enabled (bool); switching it on checks the limit on the instrument's state first
        (``*RST`` leaves 0.1 Vpp into 50 ohm, above a limit under 0.1 V)."""
        return parse_with(_scpi_bool, "OUTP?", self.query("OUTP?"), self._where())

    @output.setter
    def output(self, on: bool) -> None:
        if on:
            self.check_peak_voltage(self.amplitude_vpp, self.offset)
        self.set("OUTP 1" if on else "OUTP 0")

    @property
    def load_ohm(self) -> float:
        """Load setting [ohm] (``math.inf`` for High Z): the instrument states levels into it."""
        value = parse_with(_parse_load, "OUTP:LOAD?", self.query("OUTP:LOAD?"), self._where())
        return math.inf if value >= HIGH_Z_THRESHOLD_OHM else value

    @load_ohm.setter
    def load_ohm(self, ohm: float) -> None:
        self.check_peak_voltage(self.amplitude_vpp, self.offset, _open_circuit_gain(ohm))
        self._send("OUTP:LOAD " + ("INF" if math.isinf(ohm) else _number(ohm)))

    @property
    def open_circuit_gain(self) -> float:
        """Terminal voltage into a high-impedance input over the stated level [-], from the load setting."""
        return _open_circuit_gain(self.load_ohm)

    @property
    def offset(self) -> float:
        """DC offset [V] (the level of the ``DC`` function); refused above the peak-voltage limit."""
        return parse_with(float, "VOLT:OFFS?", self.query("VOLT:OFFS?"), self._where())

    @offset.setter
    def offset(self, offset: float) -> None:
        self.check_peak_voltage(self.amplitude_vpp, offset)
        self._send(f"VOLT:OFFS {_level(offset)}")

    def write(self, command: str) -> None:
        """Send one command line that has no reply; :class:`SafetyLimitError` (nothing sent) if it sets a level.

        Levels go through ``amplitude_vpp``, ``offset`` and ``load_ohm`` only, which check the limit first.
        A query is refused too (:class:`InstrumentError`, nothing sent): use :meth:`query`, since an unread
        reply would be taken for the answer to the next query, on which a limit decision may rest.
        """
        self._check_command(command)
        if "?" in command:
            raise InstrumentError(
                f"{self._where()}: refusing {command!r} as a write: a query's reply must be read (query)"
            )
        self._send(command)

    def query(self, command: str) -> str:
        """Send one command line and return its reply line; level settings are refused as by :meth:`write`."""
        self._check_command(command)
        self._send(command)
        return self.read_line(command)

    def _check_command(self, command: str) -> None:
        """Refuse (nothing sent) a line that sets a level, or is not one line of printable ASCII."""
        if _sets_level(command):
            raise SafetyLimitError(f"{self._where()}: refusing {command!r}: levels are set through amplitude_vpp, "
                                   "offset and am_depth, which check the limit")
        self._check_printable(command)

    def _check_printable(self, command: str) -> None:
        if not (command.isascii() and command.isprintable()):
            raise InstrumentError(f"{self._where()}: refusing {command!r}: not one line of printable ASCII")

    def set(self, command: str) -> None:
        """Send a setting (SCPI settings have no reply); level settings are refused as by :meth:`write`."""
        self.write(command)

    def switch_off(self) -> None:
        """The safe state: output off, then the lowest amplitude, no offset, burst mode and modulation off (each only
        lowers the peak or keeps it).

        Starts with an empty line, which ends a command a signal may have cut short, and drops
        any stale reply.
        """
        self._send("")
        self.discard_input()
        self._send("OUTP 0")
        self._send(amplitude_command(LOWEST_AMPLITUDE_VPP))
        self._send("VOLT:OFFS 0;:BURS:STAT 0;:AM:STAT 0")

    def check_peak_voltage(self, vpp: float, offset: float, gain: float | None = None) -> None:
        """Raise :class:`SafetyLimitError` if the terminal peak (``vpp``/2 + |``offset``|) x ``gain``
        exceeds the limit (nothing is sent); ``gain`` defaults to the instrument's
        :attr:`open_circuit_gain`, read now."""
        gain = self.open_circuit_gain if gain is None else gain
        peak = (abs(vpp) / 2 + abs(offset)) * gain
        if not peak <= self.max_peak_voltage * (1 + 1e-12):
            load = "" if gain == 1 else f" (x{gain:g} into the amplifier: the load setting is not High Z)"
            raise SafetyLimitError(
                f"{self._where()}: refusing {vpp:g} Vpp with offset {offset:g} V: output peak {peak:g} V{load} "
                f"exceeds the limit {self.max_peak_voltage:g} V"
            )

    burst_state = control("BURS:STAT?", "BURS:STAT {}", "Burst mode on (bool).", parse=_scpi_bool,
                          format=lambda on: "1" if on else "0")
    burst_mode = control("BURS:MODE?", "BURS:MODE {}", "Burst mode, ``TRIG`` or ``GAT`` (str).", parse=str.upper)
    burst_cycles = control("BURS:NCYC?", "BURS:NCYC {}", "Cycles per burst (int).", parse=lambda reply: int(round(float(reply))),
                           format=lambda cycles: f"{int(cycles):d}")
    burst_period = control("BURS:INT:PER?", "BURS:INT:PER {}", "Period of internally triggered bursts [s] (float).",
                           parse=float, format=_number)
    trigger_source = control("TRIG:SOUR?", "TRIG:SOUR {}", "Trigger source, ``IMM``, ``EXT`` or ``BUS`` (str).",
                             parse=str.upper)

    am_state = control("AM:STAT?", "AM:STAT {}", "Amplitude modulation on (bool).", parse=_scpi_bool,
                       format=lambda on: "1" if on else "0")
    am_function = control("AM:INT:FUNC?", "AM:INT:FUNC {}", "Internal modulating shape, e.g. ``ARB`` (str).", parse=str.upper)
    arb_function = control("FUNC:ARB?", "FUNC:ARB {}", "Selected arbitrary waveform's name (str).",
                           parse=lambda reply: reply.strip().strip('"').upper())
    arb_sample_rate = control("FUNC:ARB:SRAT?", "FUNC:ARB:SRAT {}", "Arbitrary waveform's sample rate [Sa/s] (float).",
                              parse=float, format=_number)

    @property
    def am_depth(self) -> float:
        """Amplitude-modulation depth [%]; set up to :data:`MAX_AM_DEPTH` (:class:`SafetyLimitError` above, nothing sent)."""
        return parse_with(float, "AM:DEPT?", self.query("AM:DEPT?"), self._where())

    @am_depth.setter
    def am_depth(self, percent: float) -> None:
        if not 0 <= percent <= MAX_AM_DEPTH:
            raise SafetyLimitError(f"{self._where()}: refusing AM depth {percent:g} %: 0 to {MAX_AM_DEPTH:g} % keeps the "
                                   "output's peak within the carrier amplitude the limit was checked on")
        self._send(f"AM:DEPT {_number(percent)}")

    def play_modulated(self, drive: ModulatedDrive) -> None:
        """Load ``drive``'s waveform and modulate the carrier with it (:meth:`ModulatedDrive.setup_commands`), then
        set its carrier amplitude; the output is left as it was.  The amplitude is checked against the limit
        first (:class:`SafetyLimitError`, nothing sent); the depth of its setup is 100 %."""
        self.check_peak_voltage(drive.amplitude_vpp, self.offset)
        for command in drive.setup_commands():
            self._check_printable(command)
            self._send(command)
        self.amplitude_vpp = drive.amplitude_vpp

    def configure_burst(self, cycles: int) -> None:
        """Triggered bursts of ``cycles`` cycles fired by :meth:`trigger` (bus trigger), burst mode on.

        The burst carries the amplitude set through :attr:`amplitude_vpp`, which checked the limit.
        """
        self.burst_mode = "TRIG"
        self.burst_cycles = cycles
        self.trigger_source = "BUS"
        self.burst_state = True

    def trigger(self) -> None:
        """``*TRG``: fire one burst (bus trigger source)."""
        self.write("*TRG")

    def reset(self) -> None:
        """``*RST``: default state, output off."""
        self.write("*RST")

    def clear(self) -> None:
        """``*CLS``: empty the error queue."""
        self.write("*CLS")

    def next_error(self) -> tuple[int, str]:
        """Pop the error queue: (code, message); code 0 when empty."""
        return parse_with(_parse_error, "SYST:ERR?", self.query("SYST:ERR?"), self._where())

    def check_errors(self, after: str) -> None:
        """Raise :class:`InstrumentError` naming every queued error (``after`` says what was done)."""
        errors = []
        while (error := self.next_error())[0] != NO_ERROR_CODE:
            errors.append(f"{error[0]},{error[1]}")
            if len(errors) > 20:
                break
        if errors:
            raise InstrumentError(f"{self._where()} reported {'; '.join(errors)} after {after}")
