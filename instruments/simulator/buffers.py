"""An instrument's bounded I/O buffers: an input buffer that assembles command lines, an output queue.

Real instruments have finite buffers: a line longer than the input buffer is discarded (SCPI
-363, input buffer overrun) and a reply that finds the output queue full is lost (IEEE 488.2
-430, query deadlocked: the client sends queries without reading).  Both cost time linear in
the bytes received, however the client behaves.
"""

from instruments.drivers.base import MAX_LINE_BYTES

INPUT_BUFFER_BYTES = MAX_LINE_BYTES
"""Longest command line, without its newline [bytes]."""
OUTPUT_BUFFER_BYTES = 4096
"""Most reply bytes queued and not yet read by the client [bytes]."""
OVERRUN = None
"""Marks, among the lines :meth:`InputBuffer.feed` returns, a line that overran the input buffer."""


class InputBuffer:
    """Splits received bytes into lines; a line over ``size`` bytes is dropped up to its newline."""

    def __init__(self, size: int = INPUT_BUFFER_BYTES):
        self.size = size
        self._partial = bytearray()
        self._overrun = False

    def clear(self) -> None:
        """Forget a partial line."""
        self._partial.clear()
        self._overrun = False

    def feed(self, data: bytes) -> list:
        """The lines ``data`` completes (bytes, newline removed), in order.

        An over-long line appears once as :data:`OVERRUN`, where it first exceeds ``size``;
        its remaining bytes are skipped up to the next newline.
        """
        lines, start = [], 0
        while True:
            end = data.find(b"\n", start)
            stop = len(data) if end < 0 else end
            if not self._overrun:
                if len(self._partial) + stop - start > self.size:
                    self._overrun = True
                    self._partial.clear()
                    lines.append(OVERRUN)
                else:
                    self._partial += data[start:stop]
            if end < 0:
                return lines
            if not self._overrun:
                lines.append(bytes(self._partial))
            self.clear()
            start = end + 1


class OutputQueue:
    """Reply bytes waiting for the client, at most ``size``; a reply that does not fit whole is refused."""

    def __init__(self, size: int = OUTPUT_BUFFER_BYTES):
        self.size = size
        self._bytes = bytearray()

    def __len__(self) -> int:
        return len(self._bytes)

    def put(self, reply: bytes) -> bool:
        """Queue ``reply``; False (nothing queued) when it does not fit."""
        if len(self._bytes) + len(reply) > self.size:
            return False
        self._bytes += reply
        return True

    def send(self, write) -> None:
        """Offer the queued bytes to ``write`` (bytes -> count written) and drop those it wrote."""
        del self._bytes[: write(self._bytes)]

    def take(self, count: int) -> bytes:
        """Remove and return the first ``count`` queued bytes."""
        head = bytes(self._bytes[:count])
        del self._bytes[:count]
        return head

    def clear(self) -> None:
        """Drop everything queued."""
        self._bytes.clear()
