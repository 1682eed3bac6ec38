"""Instrument errors: each is a :class:`TactileError`, shown as one line by the CLI."""

from workflow.errors import TactileError


class InstrumentError(TactileError):
    """An instrument refused a command or reported an error."""


class CommunicationError(InstrumentError):
    """One exchange failed in a way a retry may fix (no reply, garbled reply)."""


class ReplyTimeout(CommunicationError):
    """No complete reply line before the port's timeout."""


class GarbledReply(CommunicationError):
    """A reply that is not a valid line of the protocol."""


class ConnectionLost(InstrumentError):
    """The serial port itself failed (unplugged, closed): retrying the exchange cannot help."""


class SafetyLimitError(InstrumentError):
    """A drive amplitude above the safety limit was asked for; nothing was sent."""
