"""The defaults the README and docs/cli.md state for each option are the ones the command line has.

The command-line options take their defaults from the declarations (``workflow.pipeline.sections``, the domain's
constants); the option tables of docs/cli.md and README's command table are written for people, with links and
caveats, so they are checked here instead of generated: every default stated as a number, a word or "off"/"none"/
"required" must be the option's.  Defaults stated as prose ("local cores", "81 (beam), 12 (FEM)") are not compared;
the test asserts that most are.
"""

import argparse
import math
import re

import pytest
from test_docs import PARSERS, ROOT

DOCS = ROOT / "docs" / "cli.md"
README = ROOT / "README.md"
OPTION = re.compile(r"`(--[a-z][a-z0-9-]*)")


def _actions(command: str) -> dict:
    """Option string -> the argparse actions of that option in ``command`` and its subcommands (a subcommand's own
    default may differ: ``tactile measure resonance --voltage`` and ``campaign --voltage``)."""
    actions = {}
    for name, parser in PARSERS.items():
        if name == command or name.startswith(command + " "):
            for action in parser._actions:
                for option in action.option_strings:
                    actions.setdefault(option, []).append(action)
    return actions


def _number(text: str):
    """'100 000' -> 100000.0, '0.002' -> 0.002; None when the text is not one number."""
    try:
        return float(text.replace(" ", "").replace("\u202f", ""))
    except ValueError:
        return None


def agrees(stated: str, actions) -> bool | None:
    """Whether ``stated`` is the default of one of ``actions`` (the same option in a command's subcommands); None when
    ``stated`` is prose, or the option's default is computed when the command runs (argparse's default None)."""
    verdicts = [_agrees(stated, action) for action in actions]
    return None if all(v is None for v in verdicts) else any(verdicts)


def _agrees(stated: str, action: argparse.Action) -> bool | None:
    stated = stated.strip().strip("`").strip()
    default = action.default
    if stated == "required":
        return bool(action.required)
    if action.required:
        return False
    if stated in ("off", "on"):
        flag = isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction))
        return flag and bool(default) == (stated == "on")
    if stated == "none":
        return default is None
    if default is None:
        return None  # computed when the command runs (e.g. from the procedures or the texture given)
    values = [_number(v) for v in re.split(r",\s*|\s+", stated)] if re.fullmatch(r"[\d.]+([,\s]+[\d.]+)+", stated) else []
    if values and isinstance(default, (tuple, list)):
        return len(values) == len(default) and all(math.isclose(v, float(d), rel_tol=1e-9) for v, d in zip(values, default))
    number = _number(stated)
    if number is not None:
        if isinstance(default, (tuple, list, bool)):
            return False
        try:
            return math.isclose(float(default), number, rel_tol=1e-9, abs_tol=1e-12)
        except (TypeError, ValueError):
            return False
    if re.fullmatch(r"[A-Za-z][\w.-]*", stated) and isinstance(default, str):
        return default == stated
    return None


def _docs_rows():
    """(command, options, default cell) of every option table row of docs/cli.md under a command's section."""
    text = DOCS.read_text(encoding="utf-8")
    for part in re.split(r"^## ", text, flags=re.MULTILINE)[1:]:
        heading = re.match(r"`(tactile [a-z-]+)`", part)
        if heading is None:
            continue
        for line in part.splitlines():
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))] if line.startswith("| `--") else []
            if len(cells) >= 3 and cells[1]:
                yield heading.group(1), OPTION.findall(cells[0]), cells[1]


def _readme_rows():
    """(command, option, stated default) of README's command table: "`--opt X` (default, remarks)"."""
    for line in README.read_text(encoding="utf-8").splitlines():
        match = re.match(r"\| `(tactile [a-z-]+(?: [a-z-]+)?)` \| (.*) \| .* \|$", line)
        if match is None:
            continue
        command = match.group(1) if match.group(1) in PARSERS else " ".join(match.group(1).split()[:2])
        for option, stated in re.findall(r"`(--[a-z][a-z0-9-]*)[^`]*` \(([^()]*)", match.group(2)):
            yield command, option, re.split(r"[;:]|,\s", stated)[0]


def _checks():
    """(where, command, option, stated) for every stated default."""
    for command, options, cell in _docs_rows():
        values = [v.strip() for v in cell.split(", ")] if len(options) > 1 else [cell]
        if len(values) != len(options):
            values = [cell] * len(options)
        for option, stated in zip(options, values):
            yield "docs/cli.md", command, option, stated
    for command, option, stated in _readme_rows():
        yield "README.md", command, option, stated


CHECKS = list(_checks())


def test_enough_stated_defaults_are_compared():
    """The readable defaults are most of them (a parser change that made this test vacuous fails here)."""
    compared = [c for c in CHECKS if c[2] in _actions(c[1]) and agrees(c[3], _actions(c[1])[c[2]]) is not None]
    assert len(compared) >= 100, len(compared)


@pytest.mark.parametrize("where, command, option, stated", CHECKS, ids=[f"{c[0]}:{c[1]}:{c[2]}" for c in CHECKS])
def test_stated_default_is_the_options(where, command, option, stated):
    actions = _actions(command)
    if option not in actions:
        pytest.skip(f"{option} belongs to another command's table row")
    verdict = agrees(stated, actions[option])
    if verdict is None:
        pytest.skip(f"prose default {stated!r}")
    assert verdict, f"{where} states {command} {option} default {stated!r}; the option's is {actions[option].default!r}"
