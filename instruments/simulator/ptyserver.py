"""Serve a simulated bench on pseudo-terminals, one per instrument, for any serial client.

The server keeps both ends of each pty open, reads the master side, feeds the bytes to
the bench and writes the replies back.  An injected disconnect cannot unplug a pty: the
command is lost and its client sees a timeout.
"""

import os
import select
import tty

from instruments.simulator.bench import INSTRUMENTS, Bench, SimulatedDisconnect


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
    """Answer commands on ``ptys`` until ``should_stop()`` or an interrupt."""
    by_fd = {pair.master: name for name, pair in ptys.items()}
    while not should_stop():
        readable, _, _ = select.select(list(by_fd), [], [], poll)
        for fd in readable:
            try:
                data = os.read(fd, 4096)
            except OSError:
                continue
            try:
                reply = bench.receive(by_fd[fd], data)
            except SimulatedDisconnect:
                continue
            if reply:
                os.write(fd, reply)
