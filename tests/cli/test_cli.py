"""The command line: JSON contract, one-line errors (docs/cli.md), readable human output."""

import argparse
import json
import re
import subprocess
import sys

import pytest
from user_facing import TACTILE, assert_readable, run_cli
from paths import README

from workflow.cli import build_parser, main


def test_evaluate_json_has_the_contract_keys(capsys):
    status, out, _ = run_cli(capsys, "evaluate", "--model", "analytical", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--json")
    assert status == 0
    record = json.loads(out.strip().splitlines()[-1])
    for key in ("lambda_mm", "h_i_mm", "h_p_mm", "b_mm", "q", "voltage_v", "w_dyn_um", "f_r_khz"):
        assert key in record
    assert record["w_dyn_um"] == pytest.approx(1.070, rel=5e-3)


def test_optimize_json_has_the_contract_keys(capsys):
    status, out, _ = run_cli(capsys, "optimize", "--model", "analytical", "--hp-mm", "1", "--json")
    assert status == 0
    record = json.loads(out.strip().splitlines()[-1])
    for key in ("lambda_mm", "h_i_mm", "h_p_mm", "w_dyn_um", "f_r_khz", "coarse_evaluations"):
        assert key in record
    assert record["f_r_khz"] >= 25.0 * (1 - 1e-6)


def test_optimize_without_hp_reports_every_ceramic(capsys):
    status, out, _ = run_cli(capsys, "optimize", "--json")
    assert status == 0
    optima = json.loads(out.strip().splitlines()[-1])["optima"]
    assert [o["h_p_mm"] for o in optima] == [0.5, 1.0, 2.0]


@pytest.mark.parametrize(
    "argv, words",
    [
        (["evaluate", "--lambda-mm", "-24", "--hi-mm", "2", "--hp-mm", "1"], "--lambda-mm"),
        (["evaluate", "--lambda-mm", "24", "--hi-mm", "9", "--hp-mm", "1"], "resonator thickness"),
        (["evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "0.7"], "commercial"),
        (["evaluate", "--lambda-mm", "abc", "--hi-mm", "2", "--hp-mm", "1"], "expected a number"),
        (["evaluate", "--lambda-mm", "nan", "--hi-mm", "2", "--hp-mm", "1"], "finite"),
        (["evaluate", "--hi-mm", "2", "--hp-mm", "1"], "--lambda-mm"),
        (["optimize", "--hp-mm", "3"], "commercial"),
        (["optimize", "--hp-mm", "1", "--hi-min-mm", "5"], "--hi-min-mm"),
        (["optimize", "--model", "comsol"], "--model"),
        (["evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--b-mm", "200"], "--b-mm: 200 is outside the accepted range 30 to 100 mm"),
    ],
)
def test_bad_input_gives_one_error_line_and_a_non_zero_exit(capsys, argv, words):
    status, out, err = run_cli(capsys, *argv)
    assert status != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert words in lines[0]
    assert "Traceback" not in err


@pytest.mark.parametrize("name", ["two\nlines.csv", "next\x85line.csv", "sep\u2028arator.csv"])
def test_a_file_name_that_breaks_lines_is_named_in_one_error_line(capsys, tmp_path, name):
    """A file name may hold any character but / and NUL: the error line escapes those that would end it."""
    status, _, err = run_cli(capsys, "fit-damping", str(tmp_path / name), "--out", str(tmp_path / "out"))
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert repr(name)[1:-1] in err


def test_console_script_error_has_no_traceback():
    result = subprocess.run(
        [*TACTILE, "evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "0.7"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


def test_an_unexpected_error_is_one_line_pointing_to_debug(capsys, monkeypatch):
    """A bug inside a command: one line, exit 3, no traceback; --debug shows the traceback."""
    from workflow.models import analytical

    def broken(*args, **kwargs):
        raise ZeroDivisionError("division by zero\n  somewhere deep")

    monkeypatch.setattr(analytical, "dynamic_deflection", broken)
    argv = ["evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1"]
    assert main(argv) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "internal error: ZeroDivisionError: division by zero somewhere deep" in err and "tactile --debug evaluate" in err
    with pytest.raises(ZeroDivisionError):
        main(["--debug", *argv])


def test_the_fem_optimum_uses_space_mapping_by_default():
    args = build_parser().parse_args(["optimize", "--model", "fem"])
    assert args.method == "space-mapping"


@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1"],
        ["optimize"],
        ["simulate"],
        ["measure", "campaign", "--simulate", "--points", "9", "--voltages", "5,10"],
        ["measure", "voltage-sweep", "--simulate", "--voltages", "1,2,3"],
        ["measure", "resonance", "--simulate"],
    ],
    ids=lambda argv: " ".join(argv[:2]),
)
def test_human_output_is_readable(capsys, tmp_path, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    status, out, err = run_cli(capsys, *argv)
    assert status == 0, err
    assert out.strip()
    assert_readable(out)


def test_the_checker_catches_what_it_must():
    for bad in ("Q(v) law: QuadraticLoss(q0=150.0, alpha=0.25)", "voltage_v: [1.0, 2.0]", "sweeps: {'sweep': 0}",
                "f_r 32125.44342976582 Hz", "w_dyn 1.07 um"):
        with pytest.raises(AssertionError):
            assert_readable(bad)
    assert_readable("Q(v): quadratic law, Q0 150, alpha 0.254 s^2/m^2; log: /tmp/x[1]/a.csv; 32125.4 Hz, 1.07 µm")


def test_evaluate_warns_above_the_bench_limit_and_still_computes(capsys):
    base = ["evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--json", "--voltage"]
    for voltage in ("15", "30"):
        status, _, err = run_cli(capsys, *base, voltage)
        assert status == 0 and err == ""
    status, out, err = run_cli(capsys, *base, "40")
    assert status == 0
    assert json.loads(out.strip().splitlines()[-1])["voltage_v"] == 40.0
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "warning" in lines[0] and "30 V" in lines[0] and "refuse" in lines[0]


def _commands(parser, prefix=""):
    """(command name, its parser) for every command and measure procedure."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                nested = list(_commands(sub, f"{prefix}{name} "))
                yield from nested or [(f"{prefix}{name}", sub)]


def _shown(default) -> str:
    if isinstance(default, tuple):
        return ",".join(f"{v:g}" for v in default)
    return f"{default:g}" if isinstance(default, (int, float)) else str(default)




def test_the_readme_examples_of_the_beam_model_print_what_the_readme_shows(capsys):
    """The quick examples (beam model, no files needed) reproduce exactly; the FEM and fit ones were pasted from runs."""
    block = re.search(r"```console\n(.*?)```", README.read_text(encoding="utf-8"), re.S).group(1)
    examples = re.findall(r"^\$ tactile (.+)\n((?:[^$].*\n)*)", block, re.M)
    quick = [(command, shown) for command, shown in examples if "fem" not in command and "fit" not in command]
    assert len(quick) >= 2
    for command, shown in quick:
        status, out, err = run_cli(capsys, *command.split())
        assert status == 0, err
        assert out == shown, command


def test_the_readme_table_shows_every_option_with_its_default():
    readme = README.read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `tactile ([^`]+)`[^|]*\| (.+?) \| [^|]+ \|$", readme, re.M))
    for command, parser in _commands(build_parser()):
        row = rows[command] + (rows["measure …"] if command.startswith("measure ") else "")
        segments = {segment.split()[0].strip("`"): segment for segment in re.split(r"--(?=[a-z])", row)[1:]}
        for action in parser._actions:
            option = next((o[2:] for o in action.option_strings if o.startswith("--")), None)
            if option in (None, "help"):
                continue
            assert option in segments, f"{command}: --{option} missing from the README table"
            if action.default not in (None, False):
                shown = _shown(action.default)
                abridged = re.sub(r"^([^,]+,[^,]+),.*,([^,]+)$", r"\1,…,\2", shown)
                assert shown in segments[option] or abridged in segments[option], f"{command} --{option} {shown}"


def test_a_command_loads_only_its_own_module_and_help_lists_them_all(capsys):
    """``tactile measure`` starts without the fit's and the calibration's libraries (each bench test and each user
    pays the start); ``tactile --help`` and a misspelt command still see every command."""
    probe = ("import sys; from workflow.cli import main\n"
             "try: main(['measure', 'campaign', '--help'])\n"
             "except SystemExit: pass\n"
             "print(sorted(m for m in ('arviz', 'emcee', 'workflow.cli.fit_damping', 'workflow.cli.run') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout + done.stderr
    for argv in (["--help"], ["fit-dampin"]):
        status, out, err = run_cli(capsys, *argv)
        assert all(command in out + err for command in ("fit-damping", "measure", "run", "calibrate")), (status, argv)
