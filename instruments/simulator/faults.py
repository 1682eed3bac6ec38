"""Fault injection for the simulated instruments: dropped replies, garbled lines, a disconnect."""

from dataclasses import dataclass
from enum import Enum

import numpy as np


class Fault(Enum):
    """What happens to one command's reply."""

    NONE = "none"
    DROP = "drop"
    GARBLE = "garble"
    DISCONNECT = "disconnect"


@dataclass(frozen=True)
class FaultSettings:
    """Rates and triggers of injected faults (all off by default).

    Attributes
    ----------
    drop_rate : float
        Probability that a reply is never sent (the client times out) [-].
    garble_rate : float
        Probability that a reply arrives garbled (line noise: bytes outside printable ASCII) [-].
    disconnect_at : int or None
        The bench's command count (both instruments, from 1) at which the port goes dead,
        once; a reopened port works again.
    seed : int
        Seed of the fault generator, separate from the measurement noise.
    instruments : tuple of str or None
        The instruments whose replies are dropped or garbled (None: all).
    """

    drop_rate: float = 0.0
    garble_rate: float = 0.0
    disconnect_at: int | None = None
    seed: int = 0
    instruments: tuple | None = None

    def __post_init__(self):
        for name in ("drop_rate", "garble_rate"):
            if not 0.0 <= getattr(self, name) < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {getattr(self, name)!r}")
        if self.disconnect_at is not None and self.disconnect_at < 1:
            raise ValueError(f"disconnect_at must be a positive command count, got {self.disconnect_at!r}")


class FaultInjector:
    """Draws the fault of each command from a seeded generator and counts commands."""

    def __init__(self, settings: FaultSettings):
        self.settings = settings
        self.commands = 0
        self.disconnected = False
        self._rng = np.random.default_rng(settings.seed)

    def next_fault(self, instrument: str | None = None) -> Fault:
        """The fault for the next command (counted) to ``instrument``."""
        self.commands += 1
        if not self.disconnected and self.commands == self.settings.disconnect_at:
            self.disconnected = True
            return Fault.DISCONNECT
        draw = self._rng.random()
        if self.settings.instruments is not None and instrument not in self.settings.instruments:
            return Fault.NONE
        if draw < self.settings.drop_rate:
            return Fault.DROP
        if draw < self.settings.drop_rate + self.settings.garble_rate:
            return Fault.GARBLE
        return Fault.NONE

    def garble(self, reply: bytes) -> bytes:
        """``reply`` with some bytes replaced by line noise (>= 0x80), keeping its newline."""
        body = bytearray(reply.rstrip(b"\n")) or bytearray(b"?")
        hits = self._rng.integers(0, len(body), size=max(1, len(body) // 4))
        for index in hits:
            body[index] = int(self._rng.integers(0x80, 0x100))
        return bytes(body) + b"\n"
