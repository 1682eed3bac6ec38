"""Exceptions the command line turns into one clear error line (no traceback)."""


class TactileError(Exception):
    """Base class: an error a user can act on; its message is shown as is."""


class GeometryError(TactileError, ValueError):
    """A plate geometry that is non-physical or outside the design space."""


class InfeasibleError(TactileError):
    """An optimisation problem with no feasible point."""


class InputFileError(TactileError, ValueError):
    """A malformed input file (log, configuration, posterior)."""
