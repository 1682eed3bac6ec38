"""Exceptions the command line turns into one clear error line (no traceback)."""


class TactileError(Exception):
    """Base class: an error a user can act on; its message is shown as is."""


class GeometryError(TactileError, ValueError):
    """A plate geometry that is non-physical or outside the design space."""


class InfeasibleError(TactileError):
    """An optimisation problem with no feasible point."""


class InputFileError(TactileError, ValueError):
    """A malformed input file (log, configuration, posterior)."""


def shown(text: str) -> str:
    """``text`` as an error line may quote it: as is when printable (no control or line-breaking character: the
    message stays one line), else its ``repr`` (``'\\x85'``)."""
    return text if text.isprintable() else repr(text)


def one_line(message) -> str:
    """``message`` with every control or line-breaking character escaped (``\\n`` -> ``\\\\n``): the error line the
    command line prints stays one line whatever a file name or a value in it holds."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(message))
