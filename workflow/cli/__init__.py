"""The ``tactile`` command line (docs/cli.md).

Each command lives in its own module with ``register(subparsers)`` that adds its parser
and sets ``handler``.  A handler returns a JSON-able dict (printed on the last line of
stdout with ``--json``) or ``None``.  Errors a user can act on are :class:`TactileError`
(or argparse usage errors): one line on stderr, exit status 2, no traceback.  Any other
exception is a bug: one line naming it and pointing to ``tactile --debug``, exit status 3;
with ``--debug`` the traceback is shown.  Exit statuses: :data:`EXIT_CODES`.
"""

import argparse
import importlib
import sys

from workflow.cli.options import Stopped
from workflow.errors import TactileError
from workflow.execution.memory import keep_freed_memory
from workflow.serialise import json_line

COMMANDS = ("evaluate", "optimize", "maps", "fit_damping", "calibrate", "simulate", "measure", "render", "run")
"""Modules of :mod:`workflow.cli`, one per command, in the order ``--help`` lists them."""

EXIT_USAGE = 2
EXIT_INTERNAL = 3
EXIT_HANGUP = 129
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141
EXIT_TERMINATED = 143
EXIT_CODES = {
    0: "success",
    EXIT_USAGE: "a usage error or an error the user can act on (bad option, input file, geometry, instrument)",
    EXIT_INTERNAL: "an unexpected internal error (a bug; rerun with --debug for the traceback)",
    EXIT_HANGUP: "stopped by SIGHUP (128 + 1)",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C, SIGINT: 128 + 2)",
    EXIT_BROKEN_PIPE: "the reader of stdout went away (e.g. | head)",
    EXIT_TERMINATED: "stopped by SIGTERM (128 + 15)",
}
"""Exit status -> meaning (docs/cli.md lists the same)."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors that name the command."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser(commands=COMMANDS) -> argparse.ArgumentParser:
    """The parser of ``commands`` (modules of :data:`COMMANDS`; all of them by default, for ``--help``)."""
    parser = _Parser(
        prog="tactile",
        description="Design ultrasonic tactile plates: beam and FEM models, NLopt optimisation, "
        "bench instruments and a Bayesian fit of the damping Q(v).",
    )
    from workflow import __version__

    parser.add_argument("--version", action="version", version=f"tactile {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of an unexpected error")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    subparsers.required = True
    for name in commands:
        try:
            module = importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as error:
            if error.name == f"{__name__}.{name}":
                continue
            raise
        module.register(subparsers)
    return parser


def _named_command(argv) -> tuple:
    """The command module ``argv`` names, alone, so that a command imports only what it needs (``tactile
    measure`` does not load the Bayesian fit's libraries: 0.8 s instead of 2.3 s per start); every command when
    ``argv`` names none of them (``--help``, a typo: argparse then lists them all)."""
    words = [word for word in argv if not word.startswith("-")]
    name = words[0].replace("-", "_") if words else None
    return (name,) if name in COMMANDS else COMMANDS


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_named_command(argv))
    args = parser.parse_args(argv)
    keep_freed_memory()  # the FEM's large arrays reused instead of fresh pages (workflow/execution/memory.py)
    try:
        result = args.handler(args)
    except TactileError as error:
        print(f"tactile {args.command.replace('_', '-')}: error: {error}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print(f"tactile {args.command.replace('_', '-')}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Stopped as stop:
        outcome = f"; {stop.outcome}" if stop.outcome else ""
        print(f"tactile {args.command.replace('_', '-')}: stopped by {stop.name}{outcome}", file=sys.stderr)
        return stop.exit_status
    except BrokenPipeError:
        return _closed_stdout()
    except Exception as error:
        if args.debug:
            raise
        return _internal_error(args, error)
    try:
        if getattr(args, "json", False) and result is not None:
            print(json_line(result))
        sys.stdout.flush()
    except BrokenPipeError:
        return _closed_stdout()
    return 0


def _internal_error(args, error: Exception) -> int:
    """One line for an unexpected exception (a bug), with the way to see its traceback."""
    command = args.command.replace("_", "-")
    message = " ".join(str(error).split()) or "no message"
    print(
        f"tactile {command}: internal error: {type(error).__name__}: {message[:300]} "
        f"(a bug: rerun as 'tactile --debug {command} ...' to see the traceback, and report it)",
        file=sys.stderr,
    )
    return EXIT_INTERNAL


def _closed_stdout() -> int:
    """The reader of stdout went away (e.g. ``| head``): stop quietly, as command-line tools do."""
    import os

    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return EXIT_BROKEN_PIPE
