"""A line-oriented instrument over an already-open serial port, and declarative properties.

Drivers subclass :class:`LineInstrument` and declare their settings with :func:`control`
and :func:`measurement` (PyMeasure style).  Constructors do no I/O.
"""

import serial

from instruments.drivers.errors import ConnectionLost, GarbledReply, ReplyTimeout

TERMINATOR = b"\n"
MAX_LINE_BYTES = 4096
"""Longest command line the bench's instruments take, without its newline [bytes] (longer ones are discarded)."""
_PRINTABLE = set(range(0x20, 0x7F))


class LineInstrument:
    """Newline-terminated command/reply exchanges on ``port``.

    Parameters
    ----------
    port : serial.SerialBase
        An open pyserial port (a real one, a pty, or a ``tactile-sim://`` URL).
    name : str
        What error messages call this instrument.
    """

    def __init__(self, port, name: str):
        self.port = port
        self.name = name

    def _where(self) -> str:
        return f"{self.name} on {getattr(self.port, 'port', None) or self.port}"

    def write(self, command: str) -> None:
        """Send one command line."""
        self._send(command)

    def _send(self, command: str) -> None:
        """The transport under :meth:`write` (a driver may refuse commands in ``write``, not here)."""
        try:
            self.port.write(command.encode("ascii") + TERMINATOR)
        except (serial.SerialException, OSError) as error:
            raise ConnectionLost(f"{self._where()}: cannot send {command!r}: {error}") from None

    def read_line(self, command: str) -> str:
        """Read one reply line (without its terminator) to ``command``.

        Raises
        ------
        ReplyTimeout
            No complete line before the port's timeout.
        GarbledReply
            Bytes outside printable ASCII (line noise).
        """
        try:
            raw = self.port.read_until(TERMINATOR)
        except (serial.SerialException, OSError) as error:
            raise ConnectionLost(f"{self._where()}: cannot read the reply to {command!r}: {error}") from None
        if not raw.endswith(TERMINATOR):
            raise ReplyTimeout(f"{self._where()}: no reply to {command!r} within the timeout" + (f" (got {raw!r})" if raw else ""))
        body = raw.rstrip(b"\r\n")
        if not set(body) <= _PRINTABLE:
            raise GarbledReply(f"{self._where()}: garbled reply {raw!r} to {command!r}")
        return body.decode("ascii")

    def query(self, command: str) -> str:
        """Send ``command`` and return its reply line."""
        self.write(command)
        return self.read_line(command)

    def discard_input(self) -> None:
        """Drop whatever is waiting to be read (stale or late replies) before a retry."""
        try:
            self.port.reset_input_buffer()
        except (serial.SerialException, OSError) as error:
            raise ConnectionLost(f"{self._where()}: {error}") from None


def parse_with(parse, command: str, reply: str, where: str):
    """``parse(reply)``, turning a parse failure into :class:`GarbledReply`."""
    try:
        return parse(reply)
    except (ValueError, KeyError, IndexError):
        raise GarbledReply(f"{where}: unexpected reply {reply!r} to {command!r}") from None


def measurement(get_command: str, doc: str, parse=str):
    """A read-only property: ``parse(query(get_command))``."""

    def getter(self):
        return parse_with(parse, get_command, self.query(get_command), self._where())

    return property(getter, doc=doc)


def control(get_command: str, set_command: str, doc: str, parse=str, format=str):
    """A read/write property.

    Parameters
    ----------
    get_command : str
        Query sent on read.
    set_command : str
        Template with one ``{}`` for the formatted value, sent on write.
    parse : callable
        Reply text -> value.
    format : callable
        Value -> argument text.
    """

    def setter(self, value):
        self.set(set_command.format(format(value)))

    prop = measurement(get_command, doc, parse)
    return prop.setter(setter)
