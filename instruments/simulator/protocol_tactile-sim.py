"""pyserial looks up the ``tactile-sim://`` scheme under this module name (see :mod:`.urlhandler`)."""

from instruments.simulator.urlhandler import SimulatedSerial as Serial  # noqa: F401
