"""Driver for a Polytec OFV-5000 vibrometer controller over RS-232: ``Get``/``Set``/``GetDevInfo`` lines.

Protocol in ``docs/instruments.md``.  The controller sets the decoder's range and tells the decoder's
signal delay; the velocity itself leaves on its analog output (read by the lock-in,
:mod:`.lockin`).  Ranges travel as ``<n>mm/s/V``, delays as ``<n>us``; the driver speaks SI.  A
``Set`` is acknowledged only when the controller's acknowledge is on, so the driver switches it off
and reads every setting back with its ``Get``: a setting the controller ignored (an invalid value) is
an :class:`InstrumentError` naming both values.
"""

import re

from instruments.drivers.base import LineInstrument, control, measurement
from instruments.drivers.errors import InstrumentError

_RANGE = re.compile(r"(\d+(?:\.\d+)?)mm/s/V", re.IGNORECASE)
_DELAY = re.compile(r"(\d+(?:\.\d+)?)\s*us", re.IGNORECASE)
_MM = 1e-3
"""One millimetre [m]: positions travel in mm."""
ACKNOWLEDGE_LINES = 2
"""Lines read at most while switching acknowledge off (the old setting may acknowledge the command itself)."""


def parse_range(text: str) -> float:
    """``25mm/s/V`` -> 0.025 [m/s/V]."""
    match = _RANGE.fullmatch(text.strip())
    if not match:
        raise ValueError(text)
    return float(match.group(1)) * 1e-3


def format_range(m_s_v: float) -> str:
    """0.025 [m/s/V] -> ``25mm/s/V``."""
    return f"{m_s_v * 1e3:g}mm/s/V"


def parse_delay(text: str) -> float:
    """``8.16us`` (or ``8.16 us``) -> 8.16e-6 [s]."""
    match = _DELAY.fullmatch(text.strip())
    if not match:
        raise ValueError(text)
    return float(match.group(1)) * 1e-6


def format_delay(seconds: float) -> str:
    """8.16e-6 [s] -> ``8.16us``."""
    return f"{seconds * 1e6:g}us"


def parse_position(text: str) -> float:
    """``12.3450`` [mm] -> 0.012345 [m]."""
    return float(text) * _MM


def format_position(metres: float) -> str:
    """0.012345 [m] -> ``12.3450`` [mm] (0.1 um steps)."""
    return f"{metres / _MM:.4f}"


def parse_scan_range(reply: str) -> tuple[float, float, float, float]:
    """``xmin,xmax,ymin,ymax`` [mm] -> the same [m]."""
    values = tuple(parse_position(item) for item in reply.split(","))
    if len(values) != 4:
        raise ValueError(reply)
    return values


class Vibrometer(LineInstrument):
    """An OFV-5000-class controller with velocity decoder 1 (and, on the simulated bench, a scanning head)."""

    def __init__(self, port):
        super().__init__(port, "vibrometer")

    controller = measurement("GetDevInfo,Controller,0,Name", "Controller name (str).")
    version = measurement("GetDevInfo,Controller,0,Version", "Controller firmware (str).")
    sensor_head = measurement("GetDevInfo,SensorHead,0,Name", "Sensor head name (str).")
    decoder = measurement("GetDevInfo,VeloDec,1,Name", "Velocity decoder name (str).")
    ranges = measurement(
        "GetDevInfo,VeloDec,1,Range",
        "Available decoder ranges [m/s/V], ascending (list of float).",
        parse=lambda reply: sorted(parse_range(item) for item in reply.split(";")),
    )
    decoder_range = control(
        "Get,VeloDec,1,Range", "Set,VeloDec,1,Range,{}", "Velocity decoder range [m/s/V] (float).",
        parse=parse_range, format=format_range,
    )
    signal_delay = measurement("Get,VeloDec,1,SignalDelay", "Decoder signal transit time [s] (float).",
                               parse=parse_delay)
    signal_level = measurement("Get,SignalLevel,0,Value", "Signal level of the laser spot (str, as the controller "
                               "states it).")

    scan_range = measurement(
        "GetDevInfo,Scanner,0,Range",
        "Reachable points of the scanner, (x_min, x_max, y_min, y_max) [m] from the plate's centre.",
        parse=parse_scan_range,
    )
    position_x = control("Get,Scanner,0,X", "Set,Scanner,0,X,{}", "Laser spot along the length, from the centre [m] (float).",
                         parse=parse_position, format=format_position)
    position_y = control("Get,Scanner,0,Y", "Set,Scanner,0,Y,{}", "Laser spot across the width, from the centre [m] (float).",
                         parse=parse_position, format=format_position)

    def move_to(self, x: float, y: float) -> None:
        """Put the laser spot on (``x``, ``y``) [m] from the plate's centre (an off-plate point is an InstrumentError)."""
        self.position_x = x
        self.position_y = y

    def query(self, command: str) -> str:
        """Send ``command``; its reply, or :class:`InstrumentError` for an ``Error,...`` reply."""
        reply = super().query(command)
        if reply.startswith("Error,"):
            raise InstrumentError(f"{self._where()} answered {reply!r} to {command!r}")
        return reply

    def acknowledge_off(self) -> None:
        """``Set,Interface,0,Acknowledge,Off``, dropping its acknowledgement if the controller had acknowledge on."""
        self.write("Set,Interface,0,Acknowledge,Off")
        for _ in range(ACKNOWLEDGE_LINES):
            if self.query("Get,Interface,0,Acknowledge") == "Off":
                return
        raise InstrumentError(f"{self._where()}: acknowledge still on after Set,Interface,0,Acknowledge,Off")

    def set(self, command: str) -> None:
        """Send a ``Set`` line and read the setting back: an ignored setting is an :class:`InstrumentError`."""
        verb, device, index, name, sent = command.split(",")
        self.write(command)
        now = self.query(f"Get,{device},{index},{name}")
        if now.strip().lower() != sent.strip().lower():
            raise InstrumentError(f"{self._where()} kept {name} at {now!r} after {command!r} (a value it refuses)")

    def settings(self) -> dict:
        """Identity and decoder facts for a log's metadata."""
        return {"vibrometer": f"{self.controller} {self.version}, sensor head {self.sensor_head}, decoder {self.decoder}",
                "vibrometer_decoder_ranges_mm_s_v": [round(r * 1e3, 6) for r in self.ranges],
                "vibrometer_signal_delay_us": self.signal_delay * 1e6,
                "vibrometer_signal_level": self.signal_level}
