"""Progress of a long task on stderr: a tqdm bar on a terminal, plain lines otherwise.

When stderr is piped or logged a bar would be hidden (or fill the log with carriage returns),
so :class:`Progress` prints a plain line such as ``FEM: 5/12 (42 %), 6.1 s`` each time the
task has advanced by :data:`LINE_FRACTION` of its size and :data:`LINE_INTERVAL` has passed
since the previous line (or every :data:`HEARTBEAT` regardless), and one line when it ends.
"""

import sys
import time
from typing import Optional

LINE_INTERVAL = 3.0
"""Least time between two plain progress lines [s]."""
LINE_FRACTION = 0.1
"""Advance, as a fraction of the task's size, that earns a new plain line [-]."""
HEARTBEAT = 30.0
"""A plain line after this long without one, whatever the advance [s]."""
QUIET_TASK = 1.0
"""Tasks shorter than this print no plain line at all [s]."""


def format_duration(seconds: float) -> str:
    """``"8.1 s"`` or ``"2 min 05 s"`` for a duration [s]."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    minutes, rest = divmod(round(seconds), 60)
    return f"{minutes} min {rest:02d} s"


class Progress:
    """Count the units of work of a task and show it on ``stream`` (default stderr).

    Parameters
    ----------
    total : int or None
        Size of the task [units]; None when not known yet (see :meth:`update`).
    description : str
        What is being done, e.g. ``"FEM"``; starts every line.
    unit : str
        Name of one unit of work, e.g. ``"steps"`` (shown after the count).
    enabled : bool
        False shows nothing.
    stream : file, optional
        Where to write (default: ``sys.stderr`` at construction).
    clock : callable
        Monotonic time [s] (a test may pass its own).
    """

    def __init__(self, total: Optional[int], description: str, unit: str = "", enabled: bool = True, stream=None,
                 clock=time.perf_counter):
        self.total = total
        self.description = description
        self.unit = unit
        self.done = 0
        self.note = ""
        self.stream = sys.stderr if stream is None else stream
        self.clock = clock
        self.start = clock()
        self.enabled = enabled
        self._bar = None
        self._last_line = (self.start, 0)
        if enabled and self.stream.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=description, unit=f" {unit}" if unit else "it", file=self.stream,
                             leave=False, dynamic_ncols=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()

    def update(self, advance: int = 1, total: Optional[int] = None, note: Optional[str] = None) -> None:
        """Count ``advance`` more units; optionally revise the size and set a short note (e.g. ``"tau 68"``)."""
        self.done += advance
        if total is not None:
            self.total = total
        if note is not None:
            self.note = note
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.total = self.total
            if note is not None:
                self._bar.set_postfix_str(note, refresh=False)
            self._bar.update(advance)
        elif self._line_due():
            self._print_line(self._status())

    def close(self) -> None:
        """End the task: remove the bar, or print the last plain line if the task was long enough to show."""
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self.clock() - self.start >= QUIET_TASK:
            self._print_line(f"{self._count()} done in {format_duration(self.clock() - self.start)}")
        self.enabled = False

    def _line_due(self) -> bool:
        now = self.clock()
        since, done_then = now - self._last_line[0], self._last_line[1]
        if since >= HEARTBEAT:
            return True
        advanced = self.total is None or self.done - done_then >= LINE_FRACTION * self.total
        return since >= LINE_INTERVAL and advanced and (self.total is None or self.done < self.total)

    def _count(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        if not self.total:
            return f"{self.done}{unit}"
        if self.done == self.total:
            return f"{self.done}/{self.total}{unit}"
        return f"{self.done}/{self.total}{unit} ({100 * self.done / self.total:.0f} %)"

    def _status(self) -> str:
        return f"{self._count()}, {format_duration(self.clock() - self.start)}"

    def _print_line(self, text: str) -> None:
        note = f", {self.note}" if self.note else ""
        print(f"{self.description}: {text}{note}", file=self.stream, flush=True)
        self._last_line = (self.clock(), self.done)
