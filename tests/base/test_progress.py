"""Progress on stderr: plain lines at a readable rate when piped, a bar on a terminal."""

import io
import re

import pytest

from workflow.progress import HEARTBEAT, LINE_FRACTION, LINE_INTERVAL, QUIET_TASK, Progress, format_duration


class Clock:
    """A clock the test advances by hand [s]."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


class Terminal(io.StringIO):
    def isatty(self):
        return True


LINE = re.compile(r"^FEM: (\d+)/100 \((\d+) %\), ([\d.]+) s$")


def test_piped_lines_come_every_tenth_and_no_closer_than_the_interval():
    clock, stream = Clock(), io.StringIO()
    with Progress(100, "FEM", stream=stream, clock=clock) as progress:
        for _ in range(100):
            clock.now += 0.5  # 50 s in all
            progress.update()
    lines = stream.getvalue().splitlines()
    assert lines[-1] == "FEM: 100/100 done in 50.0 s"
    shown = [LINE.match(line) for line in lines[:-1]]
    assert all(shown), lines
    done = [int(m.group(1)) for m in shown]
    times = [float(m.group(3)) for m in shown]
    assert 5 <= len(shown) <= 10
    assert min(b - a for a, b in zip([0] + done, done)) >= LINE_FRACTION * 100
    assert min(b - a for a, b in zip([0.0] + times, times)) >= LINE_INTERVAL


def test_a_slow_task_without_advance_still_shows_a_heartbeat():
    clock, stream = Clock(), io.StringIO()
    progress = Progress(1000, "FEM", stream=stream, clock=clock)
    clock.now = HEARTBEAT + 1
    progress.update()
    assert stream.getvalue() == f"FEM: 1/1000 (0 %), {HEARTBEAT + 1:.1f} s\n"


def test_a_quick_task_prints_nothing_and_a_disabled_one_never():
    clock, stream = Clock(), io.StringIO()
    with Progress(10, "FEM", stream=stream, clock=clock) as progress:
        clock.now = QUIET_TASK / 2
        progress.update(10)
    with Progress(10, "FEM", stream=stream, clock=clock, enabled=False) as progress:
        clock.now += 100.0
        progress.update(10)
    assert stream.getvalue() == ""


def test_the_size_can_be_revised_and_a_note_added():
    clock, stream = Clock(), io.StringIO()
    with Progress(None, "emcee", unit="steps", stream=stream, clock=clock) as progress:
        clock.now = 5.0
        progress.update(100)
        clock.now = 10.0
        progress.update(100, total=1000, note="tau 20")
    assert stream.getvalue().splitlines() == [
        "emcee: 100 steps, 5.0 s",
        "emcee: 200/1000 steps (20 %), 10.0 s, tau 20",
        "emcee: 200/1000 steps (20 %) done in 10.0 s, tau 20",
    ]


def test_a_terminal_gets_a_bar_and_no_plain_lines():
    clock, stream = Clock(), Terminal()
    with Progress(100, "FEM", stream=stream, clock=clock) as progress:
        for _ in range(100):
            clock.now += 1.0
            progress.update()
    assert "\r" in stream.getvalue() and "done in" not in stream.getvalue()


@pytest.mark.parametrize("seconds, text", [(0.04, "0.0 s"), (8.14, "8.1 s"), (59.9, "59.9 s"), (125.4, "2 min 05 s")])
def test_durations_read_as_seconds_then_minutes(seconds, text):
    assert format_duration(seconds) == text
