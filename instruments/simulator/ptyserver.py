"""Serve a simulated bench on pseudo-terminals, one per instrument, for any serial client.

The server keeps both ends of each pty open, reads the master side, feeds the bytes to
the bench and writes the replies back, never blocking on a port.  An injected disconnect
cannot unplug a pty: the command is lost and its client sees a timeout.
"""

import os
import select
import time
import tty
from functools import partial

from instruments.simulator.bench import INSTRUMENTS, Bench, SimulatedDisconnect

READ_SIZE = 1 << 16
"""Most bytes read from one port per turn [bytes]; ports take turns."""


class PtyPair:
    """A pseudo-terminal in raw mode: the server's master fd and the client's device path."""

    def __init__(self):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)


def open_ptys() -> dict[str, PtyPair]:
    """One pty per instrument of the bench."""
    return {name: PtyPair() for name in INSTRUMENTS}


def serve(bench: Bench, ptys: dict[str, PtyPair], poll: float = 0.2, should_stop=lambda: False) -> None:
    """Answer commands on ``ptys`` until ``should_stop()`` or an interrupt, the bench's time following the wall clock.

    Reads and writes never block, so each port is served on its own: a client that sends
    without reading only fills its instrument's output queue (see :mod:`.buffers`).
    """
    by_fd = {pair.master: name for name, pair in ptys.items()}
    for fd in by_fd:
        os.set_blocking(fd, False)
    start = time.monotonic() - bench.time
    while not should_stop():
        bench.catch_up(time.monotonic() - start)
        waiting = [fd for fd, name in by_fd.items() if bench.output[name]]
        readable, writable, _ = select.select(list(by_fd), waiting, [], poll)
        for fd in readable:
            try:
                data = os.read(fd, READ_SIZE)
            except OSError:
                continue
            bench.catch_up(time.monotonic() - start)
            try:
                bench.receive(by_fd[fd], data)
            except SimulatedDisconnect:
                continue
        for fd in writable:
            try:
                bench.output[by_fd[fd]].send(partial(os.write, fd))
            except BlockingIOError:
                continue
