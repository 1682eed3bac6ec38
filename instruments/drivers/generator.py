"""Driver for a Keysight/Agilent 33500-series function generator (the SCPI subset of docs/instruments.md).

The driver refuses, before sending anything, any setting whose output peak voltage
(amplitude/2 + |offset|) exceeds ``max_peak_voltage``: the safety limit across the
ceramics translated through the amplifier gain.  The limit is decided on the
instrument's real state, read just before: amplitudes are always volts peak-to-peak,
and every amplitude command *and query* sets ``VOLT:UNIT VPP`` on the same line, so an
instrument left in ``VRMS`` (or ``DBM``) is neither misread nor mis-set.  The peak
amplitude/2 + |offset| bounds the output of every function (for ``DC`` the level is the
offset alone; counting the amplitude too errs on the safe side).  Levels are set only
through ``amplitude_vpp`` and ``offset``: :meth:`FunctionGenerator.write` (under ``set``
and ``query``) refuses any other command that sets a level.
"""

import math
import re

from instruments.drivers.base import LineInstrument, control, measurement, parse_with
from instruments.drivers.errors import InstrumentError, SafetyLimitError

NO_ERROR_CODE = 0
LOWEST_AMPLITUDE_VPP = 1e-3
"""The 33500 series' smallest amplitude [V peak-to-peak]: the safe state left at the end of a run."""
AMPLITUDE_QUERY = "VOLT:UNIT VPP;:VOLT?"
"""The amplitude in V peak-to-peak whatever unit the instrument was left in."""
_LEVEL_NODE = re.compile(r"VOLT|OFFS|AMPL|APPL|HIGH|LOW|LEV", re.IGNORECASE)
"""Header nodes that set an output level when given an argument (``VOLT:UNIT`` only renames it)."""


def _scpi_bool(reply: str) -> bool:
    return {"1": True, "0": False, "ON": True, "OFF": False}[reply.strip().upper()]


def _parse_error(reply: str) -> tuple[int, str]:
    code, separator, message = reply.partition(",")
    if not separator:
        raise ValueError(reply)
    return int(code), message.strip().strip('"')


def _number(value: float) -> str:
    return f"{float(value):.9g}"


def _sets_level(line: str) -> bool:
    """Whether a program line holds a command setting an output level (amplitude, offset, high/low, APPLy)."""
    for command in re.split(r"[;\r\n]", line):
        header, _, argument = command.strip().partition(" ")
        if argument.strip() and _LEVEL_NODE.search(header) and not header.upper().endswith(":UNIT"):
            return True
    return False


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
    output = control("OUTP?", "OUTP {}", "Output enabled (bool).", parse=_scpi_bool, format=lambda on: "1" if on else "0")

    amplitude_unit = measurement("VOLT:UNIT?", "Unit of ``VOLT`` (str); the driver sets ``VPP`` whenever it uses ``VOLT``.",
                                 parse=str.upper)

    @property
    def amplitude_vpp(self) -> float:
        """Output amplitude [V peak-to-peak], read in ``VPP`` whatever unit the instrument was left in."""
        return parse_with(float, AMPLITUDE_QUERY, self.query(AMPLITUDE_QUERY), self._where())

    @amplitude_vpp.setter
    def amplitude_vpp(self, vpp: float) -> None:
        self.check_peak_voltage(vpp, self.offset)
        self._send(f"VOLT:UNIT VPP;:VOLT {_number(vpp)}")

    @property
    def offset(self) -> float:
        """DC offset [V] (the level of the ``DC`` function); refused above the peak-voltage limit."""
        return parse_with(float, "VOLT:OFFS?", self.query("VOLT:OFFS?"), self._where())

    @offset.setter
    def offset(self, offset: float) -> None:
        self.check_peak_voltage(self.amplitude_vpp, offset)
        self._send(f"VOLT:OFFS {_number(offset)}")

    def write(self, command: str) -> None:
        """Send one command line; :class:`SafetyLimitError` (nothing sent) if it sets a level.

        Levels go through ``amplitude_vpp`` and ``offset`` only, which check the limit first.
        """
        if _sets_level(command):
            raise SafetyLimitError(f"{self._where()}: refusing {command!r}: levels are set through amplitude_vpp and "
                                   "offset, which check the limit")
        self._send(command)

    def set(self, command: str) -> None:
        """Send a setting (SCPI settings have no reply); level settings are refused as by :meth:`write`."""
        self.write(command)

    def switch_off(self) -> None:
        """The safe state: output off, then the lowest amplitude and no offset (each only lowers the peak).

        Starts with an empty line, which ends a command a signal may have cut short, and drops
        any stale reply.
        """
        self._send("")
        self.discard_input()
        self._send("OUTP 0")
        self._send(f"VOLT:UNIT VPP;:VOLT {_number(LOWEST_AMPLITUDE_VPP)}")
        self._send("VOLT:OFFS 0")

    def check_peak_voltage(self, vpp: float, offset: float) -> None:
        """Raise :class:`SafetyLimitError` if ``vpp``/2 + |``offset``| exceeds the limit (nothing is sent)."""
        peak = abs(vpp) / 2 + abs(offset)
        if not peak <= self.max_peak_voltage * (1 + 1e-12):
            raise SafetyLimitError(
                f"{self._where()}: refusing {vpp:g} Vpp with offset {offset:g} V: output peak {peak:g} V "
                f"exceeds the limit {self.max_peak_voltage:g} V"
            )

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
