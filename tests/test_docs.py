"""The documentation users read is in the repository, and it stays consistent with the code.

Nothing a user reads points to the team's specification file (which users never see): not
the README, not docs/, not any ``--help``, not a docstring or comment.  Every relative
markdown link resolves, anchors included; docs/cli.md names every option of every command;
docs/model.md and docs/log-format.md state the values the code uses.
"""

import argparse
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
