"""pyserial URL handler: ``tactile-sim://BENCH/INSTRUMENT`` opens a port onto a simulated bench.

``BENCH`` names a bench registered with :func:`.bench.register_bench` (``default`` is
created on first use); ``INSTRUMENT`` is ``generator`` or ``vibrometer``.  Writes are
executed at once and their replies queued in the instrument's bounded output queue; reads
never wait: a dropped reply reads as nothing, i.e. an immediate timeout.  pyserial finds this class through the module
``protocol_tactile-sim`` of this package once :func:`register_url_handler` ran.
"""

from urllib.parse import urlsplit

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from instruments.simulator.bench import INSTRUMENTS, SimulatedDisconnect, get_bench

URL_SCHEME = "tactile-sim"
_PACKAGE = __name__.rsplit(".", 1)[0]


def register_url_handler() -> None:
    """Let ``serial.serial_for_url`` open ``tactile-sim://`` URLs (idempotent)."""
    if _PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(_PACKAGE)


def bench_url(bench_name: str, instrument: str) -> str:
    """The URL of one instrument of a registered bench."""
    return f"{URL_SCHEME}://{bench_name}/{instrument}"


class SimulatedSerial(SerialBase):
    """A pyserial port connected to one instrument of a simulated bench."""

    def open(self):
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        parts = urlsplit(self._port)
        instrument = parts.path.strip("/")
        if parts.scheme != URL_SCHEME or instrument not in INSTRUMENTS:
            raise SerialException(f"expected {URL_SCHEME}://BENCH/{'|'.join(INSTRUMENTS)}, got {self._port!r}")
        try:
            self._bench = get_bench(parts.netloc)
        except KeyError as error:
            raise SerialException(str(error.args[0])) from None
        self._instrument = instrument
        self._output = self._bench.output[instrument]
        self._bench.reset_port(instrument)
        self._dead = False
        self.is_open = True

    def close(self):
        self.is_open = False

    def _reconfigure_port(self, *args):
        """Line settings mean nothing to a simulated port."""

    def _check(self):
        if not self.is_open:
            raise PortNotOpenError()
        if self._dead:
            raise SerialException(f"{self._port}: device disconnected")

    @property
    def in_waiting(self):
        self._check()
        return len(self._output)

    def read(self, size=1):
        self._check()
        return self._output.take(size)

    def write(self, data):
        self._check()
        data = bytes(data)
        try:
            self._bench.receive(self._instrument, data)
        except SimulatedDisconnect as error:
            self._dead = True
            raise SerialException(str(error)) from None
        return len(data)

    def reset_input_buffer(self):
        self._check()
        self._output.clear()

    def reset_output_buffer(self):
        self._check()

    @property
    def out_waiting(self):
        return 0
