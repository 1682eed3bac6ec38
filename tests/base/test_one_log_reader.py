"""One reader and one writer of the interferometer log format (issue 28, item 4).

``workflow/logformat.py`` holds the one reader (:class:`~workflow.logformat.LogReader`, with its views
``read_metadata`` and ``column_names``; the fit's ``read_table`` and the resume's ``read_log`` read through it) and
the text of a log (``head_text``, ``rows_text``), which ``instruments/procedures/logwriter.py::LogWriter``, the one
writer of log files, writes.  This test scans every module of ``workflow/`` and ``instruments/`` (their syntax
trees) for the shapes a second parser or writer of the format takes, and allows them in the reader alone, and in
the files listed in :data:`EXCEPTIONS` (which read or write files of another format) for the reasons given.
"""

import ast
import re

import pytest
from paths import CHECKOUT

ROOT = CHECKOUT
READER = "workflow/logformat.py"
"""The one module that parses (and composes) the text of a log."""
EXCEPTIONS = {
    "workflow/inputfiles.py": ({"log bytes"}, "defines MAX_LOG_BYTES, the cap of every log read"),
    "workflow/pipeline/texture_files.py": (
        {"csv", "comment test"},
        "the user's texture tables (--profile, --friction-curve, --trace): a header and '#' comments but no "
        "metadata, every message naming the option; not logs"),
    "workflow/pipeline/rendering.py": (
        {"csv"},
        "drive.csv of 'tactile render': the rendered drive as a table (time_s, wanted_um, drive_v, ...), no "
        "metadata, read by nothing in tactile; not a log"),
    "workflow/pipeline/runner.py": (
        {"log bytes"},
        "hashes each log's bytes (within MAX_LOG_BYTES) into the run cache's key; parses nothing"),
}
"""File -> (the rules it may break, why)."""

STRING_METHODS = {"startswith", "endswith", "lstrip", "strip", "removeprefix", "partition", "split", "find", "index"}
RE_FUNCTIONS = {"match", "search", "fullmatch", "compile", "findall", "finditer", "sub", "split"}
HASH_PATTERN = re.compile(r"\^?(\\s[*+?])?#")
"""A regular expression for a line that starts with '#' (``^#``, ``^\\s*#``)."""
FORMAT_NAMES = {"METADATA_PREFIX", "metadata_entry", "metadata_line"}
METADATA_LINE = re.compile(r"^#\s*(\w+|\{\})\s*:")
"""The start of a ``# key: value`` line, written out or composed (the key a placeholder '{}')."""


def _is_hash(node) -> bool:
    """A string constant starting with '#' (or a tuple holding one)."""
    if isinstance(node, ast.Tuple):
        return any(_is_hash(item) for item in node.elts)
    return isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("#")


def _name(node) -> str | None:
    return getattr(node, "id", getattr(node, "attr", None))


def _text(node: ast.JoinedStr) -> str:
    """An f-string's text, a placeholder as '{}' (METADATA_PREFIX's as '# ')."""
    return "".join(str(part.value) if isinstance(part, ast.Constant) else
                   "# " if _name(part.value) == "METADATA_PREFIX" else "{}" for part in node.values)


def log_text_handling(source: str) -> list[tuple[int, str]]:
    """(line, rule) of each place in ``source`` that handles log text itself:

    * ``csv``: the csv module imported (rows split or joined);
    * ``comment test``: a line tested or cut for ``#`` (``line.lstrip().startswith("#")``, ``line[0] == "#"``,
      ``re.match(r"^\\s*#", line)``);
    * ``metadata line``: a ``# key: value`` line composed (``f"# {key}: {value}"``) or written literally;
    * ``format internals``: the reader's own pieces used (``METADATA_PREFIX``, ``metadata_entry``, ``metadata_line``);
    * ``log bytes``: a log opened within its size cap (``MAX_LOG_BYTES``) to be read.
    """
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import) and any(alias.name == "csv" for alias in node.names):
            found.append((node.lineno, "csv"))
        elif isinstance(node, ast.ImportFrom) and node.module == "csv":
            found.append((node.lineno, "csv"))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in STRING_METHODS
              and any(_is_hash(arg) for arg in node.args)):
            found.append((node.lineno, "comment test"))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in RE_FUNCTIONS
              and _name(node.func.value) == "re" and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str) and HASH_PATTERN.match(node.args[0].value)):
            found.append((node.lineno, "comment test"))
        elif isinstance(node, ast.Compare) and any(_is_hash(side) for side in [node.left, *node.comparators]):
            found.append((node.lineno, "comment test"))
        elif isinstance(node, ast.JoinedStr) and METADATA_LINE.match(_text(node)):
            found.append((node.lineno, "metadata line"))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and METADATA_LINE.match(node.value):
            found.append((node.lineno, "metadata line"))
        elif _name(node) in FORMAT_NAMES:
            found.append((node.lineno, "format internals"))
        elif _name(node) == "MAX_LOG_BYTES":
            found.append((node.lineno, "log bytes"))
    return sorted(set(found))


SOURCES = sorted(path.relative_to(ROOT).as_posix() for folder in ("workflow", "instruments")
                 for path in (ROOT / folder).rglob("*.py"))


@pytest.mark.parametrize("name", [name for name in SOURCES if name != READER])
def test_no_module_but_the_reader_parses_or_composes_log_text(name):
    allowed, _ = EXCEPTIONS.get(name, (set(), ""))
    found = [f"{name}:{line}: {rule}" for line, rule in log_text_handling((ROOT / name).read_text(encoding="utf-8"))
             if rule not in allowed]
    assert not found, ("log text is parsed or composed in workflow/logformat.py only (LogReader, head_text, rows_text), "
                       "not at\n" + "\n".join(found))


def test_the_exceptions_are_files_that_exist_and_still_need_their_exception():
    for name, (rules, reason) in EXCEPTIONS.items():
        assert name in SOURCES and reason
        assert rules <= {rule for _, rule in log_text_handling((ROOT / name).read_text(encoding="utf-8"))}, name


SECOND_PARSERS = {
    "rows split by csv": ('import csv\n\ndef _fields(line):\n    return next(csv.reader([line]), [])\n', "csv"),
    "a metadata loop": ('def read(lines):\n    for line in lines:\n        if line.lstrip().startswith("#"):\n'
                        '            yield line[1:].partition(":")\n', "comment test"),
    "a first-character test": ('def comment(line):\n    return line[:1] == "#"\n', "comment test"),
    "a metadata line composed": ('def line(key, value):\n    return f"# {key}: {value}"\n', "metadata line"),
    "a regular expression": ('def entry(line):\n    return re.match(r"^\\s*#\\s*(\\w+):(.*)", line)\n', "comment test"),
    "the prefix and a key": ('HEAD = f"{logformat.METADATA_PREFIX}format_version: {logformat.FORMAT_VERSION}"\n',
                             "metadata line"),
    "a literal metadata line": ('HEAD = "# format_version: 1\\n"\n', "metadata line"),
    "the reader's pieces": ('def entry(line):\n    return logformat.metadata_entry(line)\n', "format internals"),
    "a log opened within its cap": ('def text(path):\n    return read_input(path, str(path), MAX_LOG_BYTES)\n',
                                    "log bytes"),
}
"""Shapes the former parsers and writers had (damping/logs.py, logformat.py, procedures/logwriter.py,
damping/synthetic.py), each with the rule that catches it."""


@pytest.mark.parametrize("source, rule", SECOND_PARSERS.values(), ids=SECOND_PARSERS.keys())
def test_the_scan_sees_a_second_parser(source, rule):
    """The rules are not vacuous: each shape is caught by its rule."""
    assert rule in {found for _, found in log_text_handling(source)}


def test_the_reader_itself_holds_what_the_scan_looks_for():
    rules = {rule for _, rule in log_text_handling((ROOT / READER).read_text(encoding="utf-8"))}
    assert {"csv", "comment test", "metadata line", "format internals", "log bytes"} <= rules
