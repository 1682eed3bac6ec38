"""pyserial looks up the ``tactile-sim://`` scheme under this module name (see :mod:`.urlhandler`)."""

from .urlhandler import SimulatedSerial as Serial  # noqa: F401
