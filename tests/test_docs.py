"""The documentation users read is in the repository, and it stays consistent with the code.

Nothing a user reads points to the team's specification file (which users never see): not
the README, not docs/, not any ``--help``, not a docstring or comment.  Every relative
markdown link resolves, anchors included; docs/cli.md names every option of every command;
docs/model.md and docs/log-format.md state the values the code uses.
"""

import argparse
import math
import re
import unicodedata
from pathlib import Path

import pytest
from user_facing import HIDDEN_REFERENCE

from workflow import logformat
from workflow.cli import build_parser
from workflow.damping.logs import read_log
from workflow.models import materials
from workflow.units import MM

ROOT = Path(__file__).resolve().parents[1]
MARKDOWN = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SOURCES = sorted(
    path
    for folder in ("workflow", "instruments", "bench", "tests")
    for path in (ROOT / folder).rglob("*")
    if path.suffix in {".py", ".toml", ".md"}
)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)
INLINE_CODE = re.compile(r"`[^`\n]*`")


def _parsers(parser: argparse.ArgumentParser, name: str = "tactile"):
    """(command line, parser) for ``parser`` and every subcommand below it, depth first."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub_parser in action.choices.items():
                yield from _parsers(sub_parser, f"{name} {sub_name}")


PARSERS = dict(_parsers(build_parser()))


def _prose(text: str) -> str:
    """Markdown without fenced code blocks and inline code (where brackets are not links)."""
    return INLINE_CODE.sub("", FENCE.sub("", text))


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = INLINE_CODE.sub(lambda m: m.group(0)[1:-1], heading.strip()).lower()
    kept = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return kept.replace(" ", "-")


def _anchors(path: Path) -> set:
    """Anchors of the headings of a markdown file (duplicates numbered as GitHub does)."""
    anchors, seen = set(), {}
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        match = re.match(r"#{1,6}\s+(.*)", line)
        if match:
            slug = _slug(match.group(1))
            count = seen.get(slug, 0)
            seen[slug] = count + 1
            anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_markdown_does_not_point_to_the_hidden_specification(path):
    hits = [n for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if HIDDEN_REFERENCE.search(line)]
    assert not hits, f"{path.relative_to(ROOT)} lines {hits}: point to a file under docs/ instead"


def test_sources_do_not_point_to_the_hidden_specification():
    hits = [
        f"{path.relative_to(ROOT)}:{n}"
        for path in SOURCES
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if HIDDEN_REFERENCE.search(line)
    ]
    assert not hits, f"docstrings/comments/strings should cite docs/ instead: {hits}"


@pytest.mark.parametrize("command", PARSERS, ids=str)
def test_help_does_not_point_to_the_hidden_specification(command):
    text = PARSERS[command].format_help()
    assert not HIDDEN_REFERENCE.search(text), f"'{command} --help' points to the specification:\n{text}"


def test_every_command_and_subcommand_is_walked():
    commands = set(PARSERS)
    assert {"tactile evaluate", "tactile fit-damping", "tactile run", "tactile measure campaign"} <= commands
    assert len(commands) >= 11


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path):
    broken = []
    for target in LINK.findall(_prose(path.read_text(encoding="utf-8"))):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):
            continue  # http:, https:, mailto: ...
        file_part, _, anchor = target.partition("#")
        linked = (path.parent / file_part).resolve() if file_part else path
        if not linked.exists() or ROOT not in (linked, *linked.parents):
            broken.append(target)
        elif anchor and linked.suffix == ".md" and anchor not in _anchors(linked):
            broken.append(target)
    assert not broken, f"{path.relative_to(ROOT)}: links to nothing: {broken}"


def test_the_slug_follows_github():
    assert _slug("The beam model (Bernoulli–Euler)") == "the-beam-model-bernoullieuler"
    assert _slug("`tactile optimize`") == "tactile-optimize"
    assert _slug("Design with Q(v) and the calibration") == "design-with-qv-and-the-calibration"


def _cli_sections() -> dict:
    """Command (e.g. "tactile maps") -> the text of its "## `tactile maps`" section in docs/cli.md."""
    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    parts = re.split(r"^## `(tactile [a-z-]+)`\s*$", text, flags=re.MULTILINE)
    return dict(zip(parts[1::2], parts[2::2]))


@pytest.mark.parametrize("command", sorted({" ".join(c.split()[:2]) for c in PARSERS if c != "tactile"}))
def test_cli_reference_names_every_option(command):
    sections = _cli_sections()
    assert command in sections, f"docs/cli.md has no section for {command}"
    shared = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8").split("## `tactile")[0]
    missing = sorted(
        option
        for name, parser in PARSERS.items()
        if name == command or name.startswith(command + " ")
        for action in parser._actions
        for option in action.option_strings
        if option.startswith("--") and option not in ("--help", "--version")
        and not re.search(re.escape(option) + r"(?![\w-])", sections[command] + shared)
    )
    assert not missing, f"docs/cli.md does not document {command} {missing}"


def test_model_reference_states_table_1_as_the_code_has_it():
    text = (ROOT / "docs" / "model.md").read_text(encoding="utf-8")
    cube, pzt = materials.COPPER_BERYLLIUM, materials.PZT
    expected = [
        f"{cube.youngs_modulus / 1e9:g} GPa",
        f"{cube.density:g} kg/m³",
        f"{cube.poisson_ratio:g}",
        f"{pzt.youngs_modulus / 1e9:g} GPa",
        f"{pzt.d31 * 1e12:g} pm/V".replace("-", "−"),
        f"{pzt.e31:g} C/m²".replace("-", "−"),
        f"{pzt.density:g} kg/m³",
        f"{pzt.poisson_ratio:g}",
        f"| {pzt.mechanical_q:g} |",
        "{:g} – {:g} mm".format(*(x / MM for x in materials.WAVELENGTH_RANGE)),
        "{:g} – {:g} mm".format(*(x / MM for x in materials.RESONATOR_THICKNESS_RANGE)),
        "{:g} – {:g} mm".format(*(x / MM for x in materials.WIDTH_RANGE)),
        f"| {materials.CERAMIC_GAP / MM:.1f} mm |",
        f"| {materials.N_CERAMICS} |",
        ", ".join(f"{t / MM:.1f}" for t in materials.CERAMIC_THICKNESSES[:-1])
        + f" or {materials.CERAMIC_THICKNESSES[-1] / MM:.1f} mm",
        f"practical minimum {materials.PRACTICAL_MIN_RESONATOR_THICKNESS / MM:g} mm",
        f"| {materials.MIN_FREQUENCY / 1e3:g} kHz |",
        f"| {materials.DESIGN_VOLTAGE:g} V |",
        f"| {materials.TARGET_DEFLECTION * 1e6:g} µm |",
        f"| {materials.PLATE_Q:g} |",
    ]
    missing = [value for value in expected if value not in text]
    assert not missing, f"docs/model.md does not state {missing}"


def test_log_format_reference_names_every_column_and_its_example_reads(tmp_path):
    text = (ROOT / "docs" / "log-format.md").read_text(encoding="utf-8")
    missing = [column for column in logformat.COLUMNS if f"| `{column}` |" not in text]
    assert not missing, f"docs/log-format.md has no row for {missing}"
    example = re.search(r"^```csv\n(.*?)^```", text, re.MULTILINE | re.DOTALL).group(1)
    path = tmp_path / "example.csv"
    path.write_text(example, encoding="utf-8")
    log = read_log(path)
    assert log.n_sweeps == 2 and log.warnings == ()
    assert list(log.sweep_voltages()) == [2.5, 5.0]


# The defaults the README and docs/cli.md state for each option are the command line's.
# The command-line options take their defaults from the declarations (``workflow.pipeline.sections``, the domain's
# constants); the option tables of docs/cli.md and README's command table are written for people, with links and
# caveats, so they are checked here instead of generated: every default stated as a number, a word or "off"/"none"/
# "required" must be the option's.  Defaults stated as prose ("local cores", "81 (beam), 12 (FEM)") are not compared;
# the test asserts that most are.

CLI_REFERENCE = ROOT / "docs" / "cli.md"
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
    """(command, options, default cell) of every option table row of docs/cli.md: under a command's section that
    command, elsewhere (the options several commands share) ``tactile``, every command."""
    text = CLI_REFERENCE.read_text(encoding="utf-8")
    for part in re.split(r"^## ", text, flags=re.MULTILINE)[1:]:
        heading = re.match(r"`(tactile [a-z-]+)`", part)
        command = "tactile" if heading is None else heading.group(1)
        for line in part.splitlines():
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))] if line.startswith("| `--") else []
            if len(cells) >= 3 and cells[1]:
                yield command, OPTION.findall(cells[0]), cells[1]


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
    assert option in actions, f"{where} documents {option} for {command}, which has no such option"
    verdict = agrees(stated, actions[option])
    if verdict is None:
        pytest.skip(f"prose default {stated!r}")
    assert verdict, f"{where} states {command} {option} default {stated!r}; the option's is {actions[option].default!r}"
