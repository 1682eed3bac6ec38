"""A small SCPI parser: mnemonic headers in short or long form, optional nodes, numeric suffixes.

A header pattern reads like the 33500 manual: ``[SOURce#:]VOLTage[:AMPLitude]`` —
capitals are the short form, brackets mark optional nodes, ``#`` a numeric suffix.
Matching is case-insensitive and accepts a leading ``:``.  A program line may hold
several commands separated by ``;``; a command after ``;`` without a leading ``:``
continues in the subsystem of the previous one (IEEE 488.2).
"""

import re

_NODE = re.compile(r"(\[?):?([A-Za-z*]+)(#?)\]?")


def _mnemonic(long_form: str) -> str:
    short = "".join(c for c in long_form if not c.islower())
    alternatives = sorted({short, long_form.upper()}, key=len, reverse=True)
    return "(?:" + "|".join(map(re.escape, alternatives)) + ")"


def header_regex(pattern: str) -> re.Pattern:
    """Compile a header ``pattern`` (e.g. ``[SOURce#:]FREQuency``) into a regex.

    The regex matches ``":" + header`` (with the query mark, if any) and captures the
    numeric suffixes (empty when absent) and the query mark.
    """
    regex = ""
    for optional, word, suffix in _NODE.findall(pattern):
        node = ":" + _mnemonic(word) + (r"(\d*)" if suffix else "")
        regex += f"(?:{node})?" if optional else node
    return re.compile(regex + r"(\?)?", re.IGNORECASE)


def split_program(line: str) -> list[tuple[str, str]]:
    """Split a program line into (header with leading ':', argument text) pairs.

    Resolves the ``;`` rule: a header without a leading ``:`` after a ``;`` lives in the
    subsystem (all but the last node) of the previous header.
    """
    commands, subsystem = [], ""
    for command in (part.strip() for part in line.split(";")):
        if not command:
            continue
        header, _, argument = command.partition(" ")
        if header.startswith("*"):
            commands.append((header, argument.strip()))
            continue
        full = header if header.startswith(":") else f"{subsystem}:{header}"
        commands.append((full, argument.strip()))
        subsystem = full.rstrip("?").rsplit(":", 1)[0]
    return commands
