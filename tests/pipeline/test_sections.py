"""The configuration declared once (issue 28, item 1): the sections' dataclasses give the defaults, the reader's
checks and the docs' table of keys."""

import dataclasses
from pathlib import Path

import pytest

from workflow.errors import InputFileError
from workflow.pipeline import sections
from workflow.pipeline.config import default_config, merge
from workflow.pipeline.sections import SECTIONS, TABLE_END, TABLE_START, keys, markdown_table

CLI_DOC = Path(__file__).resolve().parents[2] / "docs" / "cli.md"

ALL_KEYS = [key for section in SECTIONS for key in keys(section)]


def test_the_docs_table_of_keys_is_the_declarations():
    text = CLI_DOC.read_text(encoding="utf-8")
    documented = text[text.index(TABLE_START) + len(TABLE_START):text.index(TABLE_END)].strip()
    assert documented == markdown_table(), (
        "docs/cli.md's table of configuration keys differs from workflow/pipeline/sections.py: "
        "write it again with `python -m workflow.pipeline.sections --write docs/cli.md`")


def test_the_defaults_are_the_declared_ones_and_pass_their_own_checks():
    config = default_config()
    assert list(config) == list(SECTIONS)
    for section, cls in SECTIONS.items():
        instance = cls()
        assert list(config[section]) == [f.name for f in dataclasses.fields(cls)]
        for name, value in config[section].items():
            declared = getattr(instance, name)
            assert value == (list(declared) if isinstance(declared, tuple) else declared)
    assert merge(default_config(), default_config()) == default_config()


@pytest.mark.parametrize("key", ALL_KEYS, ids=lambda k: k.path)
def test_every_key_declares_what_it_is(key):
    assert key.declared.help.strip(), f"{key.path}: no help text"
    if (key.item or key.kind) in (int, float):
        assert key.declared.unit, f"{key.path}: a number needs its unit ('-' when it has none)"
    if key.limits is not None:
        low, high = key.limits
        values = key.default if key.item else [key.default]
        assert all(low <= v <= high for v in values), f"{key.path}: its default is outside its own range"
    if key.declared.choices is not None:
        values = key.default if key.item else [key.default]
        assert all(v in key.declared.choices for v in values)


RANGED = [key for key in ALL_KEYS if key.limits is not None]


@pytest.mark.parametrize("key", RANGED, ids=lambda k: k.path)
def test_a_value_beyond_the_declared_range_is_refused_naming_the_key(key):
    low, high = key.limits
    beyond = (high + 1 if isinstance(high, int) else high * 2 + 1.0) if high >= 0 else high + 1
    value = [beyond] if key.item else beyond
    with pytest.raises(InputFileError, match=rf"run\.toml: '{key.path}(\[0\])?'"):
        merge(default_config(), {key.section: {key.name: value}}, source="run.toml")


@pytest.mark.parametrize("key", [k for k in ALL_KEYS if k.declared.not_empty], ids=lambda k: k.path)
def test_an_empty_list_is_refused_where_one_is_needed(key):
    with pytest.raises(InputFileError, match=rf"'{key.path}' is empty"):
        merge(default_config(), {key.section: {key.name: []}}, source="run.toml")


@pytest.mark.parametrize("key", [k for k in ALL_KEYS if k.declared.choices is not None], ids=lambda k: k.path)
def test_a_value_outside_the_declared_choices_is_refused(key):
    odd = "no-such-law" if (key.item or key.kind) is str else 0.123
    with pytest.raises(InputFileError, match=rf"'{key.path}' holds"):
        merge(default_config(), {key.section: {key.name: [odd] if key.item else odd}}, source="run.toml")


def test_a_key_declared_in_one_place_is_read_checked_and_documented(monkeypatch):
    """Adding a setting touches one place: a new field of a section is a default, a checked key and a table row."""

    @dataclasses.dataclass(frozen=True)
    class Maps(sections.MapsSection):
        contour_levels: int = sections.setting(12, unit="-", help="contour levels per map", limits=(2, 50))

    monkeypatch.setitem(SECTIONS, "maps", Maps)
    assert default_config()["maps"]["contour_levels"] == 12
    assert merge(default_config(), {"maps": {"contour_levels": 20}})["maps"]["contour_levels"] == 20
    with pytest.raises(InputFileError, match="'maps.contour_levels' = 51 is outside the accepted range 2 to 50"):
        merge(default_config(), {"maps": {"contour_levels": 51}})
    with pytest.raises(InputFileError, match="'maps.contour_levels' must be an integer"):
        merge(default_config(), {"maps": {"contour_levels": "many"}})
    assert "| `[maps] contour_levels` | integer | `12` | - | 2 to 50 | contour levels per map |" in markdown_table()


def test_print_config_says_what_each_key_is_and_reads_back(capsys):
    from workflow.cli import main
    from workflow.inputfiles import tomllib
    from workflow.pipeline.config import to_toml

    config = merge(default_config(), {"campaign": {"logs": ["run #1.csv"]}})
    text = to_toml(config, comments=True)
    assert tomllib.loads(text) == config
    assert "width_mm = 49.0                          # [mm] plate width b\n" in text
    assert main(["run", "--print-config"]) in (0, None)
    printed = capsys.readouterr().out
    assert tomllib.loads(printed) == default_config() and "# [kHz] lowest resonance frequency" in printed
