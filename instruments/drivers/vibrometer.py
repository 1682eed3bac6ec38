"""Driver for the laser vibrometer: Polytec-style ``Get``/``Set`` lines plus the lock-in readout.

Protocol in ``docs/instruments.md``.  Decoder ranges travel as ``<n>mm/s/V``; the driver
speaks SI (m/s per volt).  An over-range readout is returned flagged, never as a value.
"""

import re
from dataclasses import dataclass

import numpy as np

from instruments.drivers.base import LineInstrument, control, measurement, parse_with
from instruments.drivers.errors import GarbledReply, InstrumentError

FULL_SCALE_OUTPUT = 10.0
"""Decoder analog output at full scale [V]: full-scale velocity = range x 10 V."""
_RANGE = re.compile(r"(\d+(?:\.\d+)?)mm/s/V", re.IGNORECASE)
_STATUS = {"OK": False, "OVER": True}
_MM = 1e-3
"""One millimetre [m]: positions travel in mm."""


def parse_range(text: str) -> float:
    """``25mm/s/V`` -> 0.025 [m/s/V]."""
    match = _RANGE.fullmatch(text.strip())
    if not match:
        raise ValueError(text)
    return float(match.group(1)) * 1e-3


def format_range(m_s_v: float) -> str:
    """0.025 [m/s/V] -> ``25mm/s/V``."""
    return f"{m_s_v * 1e3:g}mm/s/V"


def full_scale(decoder_range: float) -> float:
    """Largest readable velocity amplitude [m/s] on ``decoder_range`` [m/s/V]."""
    return decoder_range * FULL_SCALE_OUTPUT


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


@dataclass(frozen=True)
class VelocityReading:
    """One lock-in readout at the drive frequency.

    Attributes
    ----------
    amplitude : float
        Peak velocity amplitude [m/s] (the full-scale value when ``over_range``).
    phase_deg : float
        Phase of the velocity relative to the drive [deg].
    over_range : bool
        The velocity exceeded the decoder range: ``amplitude`` is not a measurement.
    """

    amplitude: float
    phase_deg: float
    over_range: bool


@dataclass(frozen=True)
class EnvelopeRecord:
    """The velocity envelope recorded after a burst's end (``Get,Record,0,Envelope``).

    Attributes
    ----------
    time : numpy.ndarray
        Time of each sample since the end of the burst [s].
    amplitude : numpy.ndarray
        Envelope (peak velocity) [m/s]; the full-scale value where over range.
    over_range : bool
        Some sample exceeded the decoder range.
    """

    time: np.ndarray
    amplitude: np.ndarray
    over_range: bool


def _parse_record(reply: str) -> EnvelopeRecord:
    status, interval_us, count, values = reply.split(",", 3)
    amplitude = np.array([float(v) for v in values.split(";")])
    if len(amplitude) != int(count) or not np.all(amplitude >= 0) or not int(interval_us) > 0:
        raise ValueError(reply)
    return EnvelopeRecord(int(interval_us) * 1e-6 * np.arange(len(amplitude)), amplitude, _STATUS[status.strip().upper()])


def _parse_reading(reply: str) -> VelocityReading:
    amplitude, phase, status = reply.split(",")
    reading = VelocityReading(float(amplitude), float(phase), _STATUS[status.strip().upper()])
    if not reading.amplitude >= 0:
        raise ValueError(reply)
    return reading


class Vibrometer(LineInstrument):
    """A vibrometer controller with velocity decoder 1 and the lock-in readout, on an open serial port."""

    READOUT = "Get,LockIn,0,Velocity"

    def __init__(self, port):
        super().__init__(port, "vibrometer")

    controller = measurement("GetDevInfo,Controller,0,Name", "Controller name (str).")
    version = measurement("GetDevInfo,Controller,0,Version", "Controller firmware (str).")
    decoder = measurement("GetDevInfo,VeloDec,1,Name", "Velocity decoder name (str).")
    ranges = measurement(
        "GetDevInfo,VeloDec,1,Ranges",
        "Available decoder ranges [m/s/V], ascending (list of float).",
        parse=lambda reply: sorted(parse_range(item) for item in reply.split(";")),
    )
    decoder_range = control(
        "Get,VeloDec,1,Range", "Set,VeloDec,1,Range,{}", "Velocity decoder range [m/s/V] (float).",
        parse=parse_range, format=format_range,
    )

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

    def set(self, command: str) -> None:
        """Send a ``Set`` line and check that the acknowledged value is the one sent."""
        sent = command.rsplit(",", 1)[1]
        reply = self.query(command)
        if reply.strip().lower() != sent.lower():
            raise GarbledReply(f"{self._where()}: acknowledged {reply!r} to {command!r}")

    record_samples = control("Get,Record,0,Samples", "Set,Record,0,Samples,{}", "Samples of an envelope record (int).",
                             parse=int, format=lambda n: f"{int(n):d}")
    record_interval = control("Get,Record,0,Interval", "Set,Record,0,Interval,{}",
                              "Time between envelope record samples [s] (float; sent in whole microseconds).",
                              parse=lambda reply: int(reply) * 1e-6, format=lambda seconds: f"{round(seconds * 1e6):d}")

    RECORD = "Get,Record,0,Envelope"
    TEMPERATURE = "Get,Sensor,0,Temperature"

    def read_record(self) -> EnvelopeRecord:
        """The envelope recorded from the end of the latest burst (the generator's trigger output arms it)."""
        return parse_with(_parse_record, self.RECORD, self.query(self.RECORD), self._where())

    def read_temperature(self) -> float | None:
        """Plate temperature from the controller's sensor input [deg C], or None if it has none."""
        try:
            return parse_with(float, self.TEMPERATURE, self.query(self.TEMPERATURE), self._where())
        except InstrumentError as error:
            if "Unknown command" in str(error):
                return None
            raise

    def read_velocity(self) -> VelocityReading:
        """Velocity amplitude and phase at the drive frequency, flagged when over range."""
        return parse_with(_parse_reading, self.READOUT, self.query(self.READOUT), self._where())
