"""Stop signals as an exception, so that a command's cleanup (the bench's output off) runs on each.

By default SIGTERM and SIGHUP end Python at once, skipping every ``finally``; a service
stop or a CI timeout sends SIGTERM.  Inside :class:`StopSignals` the first SIGINT, SIGTERM
or SIGHUP raises :class:`Stopped` instead, later ones are ignored so that they cannot cut
the cleanup short, and :meth:`StopSignals.held` defers them around a cleanup that must
finish.  SIGKILL cannot be caught: nothing runs then.
"""

import signal
from contextlib import contextmanager

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class Stopped(BaseException):
    """A stop signal arrived (a BaseException, like KeyboardInterrupt: no ``except Exception`` swallows it).

    Attributes
    ----------
    signum : int
    outcome : str
        What the command did about it (e.g. the output switched off), for the one-line message.
    """

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        self.outcome = ""

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name

    @property
    def exit_status(self) -> int:
        """128 + the signal number, the shell's convention (130 SIGINT, 129 SIGHUP, 143 SIGTERM)."""
        return 128 + self.signum


class StopSignals:
    """Context manager: SIGINT/SIGTERM/SIGHUP raise :class:`Stopped` inside; the previous handlers come back after."""

    def __init__(self):
        self.received = None
        self._holding = False
        self._previous = {}

    def __enter__(self):
        for signum in STOP_SIGNALS:
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc):
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        return False

    def _handle(self, signum, frame):
        if self.received is not None:
            return
        self.received = signum
        if not self._holding:
            raise Stopped(signum)

    @contextmanager
    def held(self):
        """Defer a stop signal until the block ends (then :class:`Stopped` is raised, unless one already was)."""
        pending, self._holding = self.received is None, True
        try:
            yield
        finally:
            self._holding = False
        if pending and self.received is not None:
            raise Stopped(self.received)
