"""Simulated laser vibrometer controller, OFV-5000-like: RS-232 settings lines and an analog velocity output.

The controller is configured over RS-232 (``Get``/``Set``/``GetDevInfo`` lines on ``Controller``,
``SensorHead``, ``VeloDec``, ``Interface``, ``SignalLevel``; docs/instruments.md); it measures nothing
over the line.  The velocity leaves as an analog voltage, velocity / range [V], which the bench feeds
to the lock-in: the decoder clips it at +-10 V (its overload).  A ``Get`` answers one line; a ``Set``
answers the value in effect only with acknowledge on (``Set,Interface,0,Acknowledge,On``; off after
power-on), and an invalid setting is ignored.  The laser spot is moved by a scanner when the bench
plays a built plate (``Scanner`` lines: the simulator's scanning head, an extension).
"""

from instruments.drivers.vibrometer import format_delay, format_position, format_range

CONTROLLER_NAME = "OFV-5000"
CONTROLLER_VERSION = "tactile-sim 1.0"
SENSOR_HEAD_NAME = "OFV-505"
SENSOR_HEAD_VERSION = "tactile-sim 1.0"
DECODER_NAME = "VD-09"
DECODER_RANGES = tuple(mm_s_v * 1e-3 for mm_s_v in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000))
"""The simulated decoder's ranges [m/s per volt of analog output]."""
DECODER_FULL_SCALE_OUTPUT = 10.0
"""The decoder's analog output clips at this peak voltage [V] (its overload)."""
DECODER_DELAY = 8.16e-6
"""Signal transit time of the simulated decoder [s] (``Get,VeloDec,1,SignalDelay``): the output lags the surface."""
SIGNAL_LEVEL = 85
"""``Get,SignalLevel,0,Value`` of a focused spot on the simulated plate [%]."""
BAUD_RATE = 115200
"""The controller's RS-232 rate [baud] (its default)."""
ERROR_UNKNOWN = "Error,1,Unknown command"


class VibrometerDevice:
    """The controller's command interpreter.

    Parameters
    ----------
    scanner : tuple of float or None
        (L/2, b/2) [m]: the plate's half extents, within which the laser spot can be positioned
        (``Set,Scanner,0,X|Y,<mm>``); None for a single-point head without a scanner.
    ranges : tuple of float
        The decoder's ranges [m/s/V].

    Attributes
    ----------
    decoder_range : float
        The range in effect [m/s/V] (the largest after power-on).
    position : tuple of float
        Laser spot (x, y) from the plate's centre [m].
    """

    def __init__(self, scanner: tuple | None = None, ranges: tuple = DECODER_RANGES):
        self.ranges = tuple(sorted(ranges))
        self.decoder_range = self.ranges[-1]
        self.acknowledge = False
        self.scanner = scanner
        self.position = (0.0, 0.0)
        self._gets = {
            ("GetDevInfo", "Controller", "0", "Name"): lambda: CONTROLLER_NAME,
            ("GetDevInfo", "Controller", "0", "Version"): lambda: CONTROLLER_VERSION,
            ("GetDevInfo", "SensorHead", "0", "Name"): lambda: SENSOR_HEAD_NAME,
            ("GetDevInfo", "SensorHead", "0", "Version"): lambda: SENSOR_HEAD_VERSION,
            ("GetDevInfo", "VeloDec", "1", "Name"): lambda: DECODER_NAME,
            ("GetDevInfo", "VeloDec", "1", "Range"): lambda: ";".join(map(format_range, self.ranges)),
            ("Get", "VeloDec", "1", "Range"): lambda: format_range(self.decoder_range),
            ("Get", "VeloDec", "1", "SignalDelay"): lambda: format_delay(DECODER_DELAY),
            ("Get", "SignalLevel", "0", "Value"): lambda: str(SIGNAL_LEVEL),
            ("Get", "Interface", "0", "BaudRate"): lambda: str(BAUD_RATE),
            ("Get", "Interface", "0", "Acknowledge"): lambda: "On" if self.acknowledge else "Off",
        }

    @property
    def output_scale(self) -> float:
        """Analog output per unit velocity [V/(m/s)] on the range in effect."""
        return 1.0 / self.decoder_range

    def handle_line(self, line: str) -> str | None:
        """Execute one command line; its reply line, or None (a ``Set`` without acknowledge, an ignored setting)."""
        fields = tuple(field.strip() for field in line.strip().split(","))
        if fields in self._gets:
            return self._gets[fields]()
        if self.scanner is not None and fields[1:3] == ("Scanner", "0"):
            return self._scanner(fields)
        if fields[0] != "Set" or len(fields) != 5:
            return ERROR_UNKNOWN
        setter = {("VeloDec", "1", "Range"): self._set_range, ("Interface", "0", "Acknowledge"): self._set_acknowledge}
        if fields[1:4] not in setter:
            return ERROR_UNKNOWN
        value = setter[fields[1:4]](fields[4])
        return value if self.acknowledge and value is not None else None

    def _set_range(self, text: str) -> str | None:
        choices = {format_range(r).lower(): r for r in self.ranges}
        if text.lower() not in choices:
            return None
        self.decoder_range = choices[text.lower()]
        return format_range(self.decoder_range)

    def _set_acknowledge(self, text: str) -> str | None:
        if text not in ("On", "Off"):
            return None
        self.acknowledge = text == "On"
        return text

    def _scanner(self, fields: tuple) -> str | None:
        """The positioning commands: range, and the spot's x and y in mm from the plate's centre."""
        half = dict(zip("XY", self.scanner))
        if fields == ("GetDevInfo", "Scanner", "0", "Range"):
            return ",".join(format_position(sign * half[axis]) for axis in "XY" for sign in (-1, 1))
        if len(fields) == 4 and fields[0] == "Get" and fields[3] in half:
            return format_position(self.position["XY".index(fields[3])])
        if len(fields) == 5 and fields[0] == "Set" and fields[3] in half:
            try:
                value = float(fields[4]) * 1e-3
            except ValueError:
                return None
            if not abs(value) <= half[fields[3]] * (1 + 1e-9):
                return None
            position = list(self.position)
            position["XY".index(fields[3])] = value
            self.position = tuple(position)
            return format_position(value) if self.acknowledge else None
        return ERROR_UNKNOWN

    def input_overrun(self) -> str:
        """The reply to a command line that overran the input buffer and was discarded."""
        return "Error,3,Input buffer overrun"

    def reply_lost(self) -> None:
        """A reply found the output queue full: the controller has no error queue, the reply is just lost."""
