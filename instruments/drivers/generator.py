"""Driver for a Keysight/Agilent 33500-series function generator (the SCPI subset of docs/instruments.md).

The driver refuses, before sending anything, any setting whose output peak voltage
(amplitude/2 + |offset|) exceeds ``max_peak_voltage``: the safety limit across the
ceramics translated through the amplifier gain.  Amplitudes are always volts
peak-to-peak: the amplitude command sets ``VOLT:UNIT VPP`` on the same line.
"""

from instruments.drivers.base import LineInstrument, control, measurement, parse_with
from instruments.drivers.errors import InstrumentError, SafetyLimitError

NO_ERROR_CODE = 0


def _scpi_bool(reply: str) -> bool:
    return {"1": True, "0": False, "ON": True, "OFF": False}[reply.strip().upper()]


def _parse_error(reply: str) -> tuple[int, str]:
    code, separator, message = reply.partition(",")
    if not separator:
        raise ValueError(reply)
    return int(code), message.strip().strip('"')


def _number(value: float) -> str:
    return f"{float(value):.9g}"


def _check_amplitude(generator, vpp: float) -> None:
    generator.check_peak_voltage(vpp, generator.offset)


def _check_offset(generator, offset: float) -> None:
    generator.check_peak_voltage(generator.amplitude_vpp, offset)


class FunctionGenerator(LineInstrument):
    """A 33500-series generator, channel 1, on an open serial port.

    Parameters
    ----------
    port : serial.SerialBase
        Open port; replies end with a newline.
    max_peak_voltage : float
        Largest output peak voltage allowed, amplitude/2 + |offset| [V].
    """

    def __init__(self, port, max_peak_voltage: float):
        super().__init__(port, "signal generator")
        self.max_peak_voltage = max_peak_voltage

    identity = measurement("*IDN?", "Manufacturer, model, serial number, firmware (str).")
    function = control("FUNC?", "FUNC {}", "Waveform shape, e.g. ``SIN`` (str).", parse=str.upper)
    frequency = control("FREQ?", "FREQ {}", "Output frequency [Hz] (float).", parse=float, format=_number)
    amplitude_vpp = control(
        "VOLT?",
        "VOLT:UNIT VPP;:VOLT {}",
        "Output amplitude [V peak-to-peak] (float); refused above the peak-voltage limit.",
        parse=float,
        format=_number,
        check=_check_amplitude,
    )
    amplitude_unit = control("VOLT:UNIT?", "VOLT:UNIT {}", "Unit of ``VOLT``: ``VPP`` or ``VRMS`` (str).", parse=str.upper)
    offset = control(
        "VOLT:OFFS?", "VOLT:OFFS {}", "DC offset [V] (float); refused above the peak-voltage limit.", parse=float,
        format=_number, check=_check_offset,
    )
    output = control("OUTP?", "OUTP {}", "Output enabled (bool).", parse=_scpi_bool, format=lambda on: "1" if on else "0")

    def set(self, command: str) -> None:
        """Send a setting (SCPI settings have no reply)."""
        self.write(command)

    def check_peak_voltage(self, vpp: float, offset: float) -> None:
        """Raise :class:`SafetyLimitError` if ``vpp``/2 + |``offset``| exceeds the limit (nothing is sent)."""
        peak = abs(vpp) / 2 + abs(offset)
        if peak > self.max_peak_voltage * (1 + 1e-12):
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
