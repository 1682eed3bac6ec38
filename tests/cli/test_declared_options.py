"""Options declared by the configuration's keys (issue 28, item 1): one declaration gives a design command's option
and the run's key its type, range, choices, default and help."""

import argparse

import pytest

from workflow.cli import main
from workflow.cli.options import (
    RUN_OVERRIDES,
    add_build_options,
    add_drive_options,
    add_fem_options,
    add_hi_min_option,
    add_width_option,
    key_option,
)
from workflow.errors import InputFileError
from workflow.inputfiles import tomllib
from workflow.pipeline.config import default_config, merge
from workflow.pipeline.sections import key

SHARED = [("design.q", "--q"), ("design.voltage_v", "--voltage"), ("design.glue_um", "--glue-um"),
          ("design.ceramic", "--ceramic"), ("design.resonator", "--resonator"), ("fem.piezo", "--piezo"),
          ("design.width_mm", "--b-mm"), ("design.hi_min_mm", "--hi-min-mm")]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    add_drive_options(parser)
    add_fem_options(parser)
    add_width_option(parser)
    add_hi_min_option(parser)
    return parser


@pytest.mark.parametrize("path, flag", SHARED)
def test_an_option_and_its_key_share_default_range_and_help(path, flag, capsys):
    declared = key(path)
    args = _parser().parse_args([])
    assert getattr(args, flag[2:].replace("-", "_")) == declared.default
    bad = "no-such-record" if declared.kind is str else str(declared.limits[1] * 2 + 1)
    with pytest.raises(SystemExit):
        _parser().parse_args([flag, bad])
    assert flag in capsys.readouterr().err
    with pytest.raises(InputFileError, match=declared.path):
        merge(default_config(), {declared.section: {declared.name: bad if declared.kind is str else float(bad)}})
    helped = next(a.help for a in _parser()._actions if flag in a.option_strings)
    assert helped.startswith(declared.declared.help.replace("%", "%%"))


def test_the_run_overrides_its_keys_from_the_options_of_the_same_names(capsys):
    given = {"design.glue_um": ("20", 20.0), "fem.piezo": ("coupled", "coupled"),
             "design.ceramic": ("PZT-5H", "PZT-5H"), "design.resonator": ("C17200", "C17200"), "damping.mixed_plates": ("warn", "warn"),
             "fem.accuracy": ("0.01", 0.01)}
    assert set(given) == set(RUN_OVERRIDES)
    argv = [word for path, (text, _) in given.items() for word in ("--" + RUN_OVERRIDES[path].replace("_", "-"), text)]
    assert main(["run", *argv, "--print-config"]) in (0, None)
    printed = tomllib.loads(capsys.readouterr().out)
    for path, (_, value) in given.items():
        section, name = path.split(".")
        assert printed[section][name] == value, path


def test_an_override_option_keeps_the_configurations_value_when_not_given():
    parser = argparse.ArgumentParser()
    add_build_options(parser, overrides=True)
    key_option(parser, "damping.mixed_plates", overrides=True)
    args = parser.parse_args([])
    assert args.glue_um is None and args.ceramic is None and args.mixed_plates is None
