"""Exceptions the command line turns into one clear error line (no traceback)."""


def one_line(message) -> str:
    """``message`` with every control or line-breaking character escaped (``\\n`` -> ``\\\\n``, NEL -> ``\\\\x85``): an
    error stays one line whatever a file name or a value quoted in it holds."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(message))


class TactileError(Exception):
    """Base class: an error a user can act on; its message is shown as is, on one line (:func:`one_line`)."""

    def __str__(self) -> str:
        return one_line(super().__str__())


class GeometryError(TactileError, ValueError):
    """A plate geometry that is non-physical or outside the design space."""


class InfeasibleError(TactileError):
    """An optimisation problem with no feasible point."""


class InputFileError(TactileError, ValueError):
    """A malformed input file (log, configuration, posterior)."""
