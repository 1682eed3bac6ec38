"""The command line: JSON contract and one-line errors (docs/cli.md)."""

import json
import subprocess
import sys

import pytest

from workflow.cli import main


def run_cli(capsys, *argv):
    try:
        status = main(list(argv))
    except SystemExit as exit_:
        status = exit_.code
    out, err = capsys.readouterr()
    return status, out, err


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
        (["evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--b-mm", "200"], "width"),
    ],
)
def test_bad_input_gives_one_error_line_and_a_non_zero_exit(capsys, argv, words):
    status, out, err = run_cli(capsys, *argv)
    assert status != 0
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert words in lines[0]
    assert "Traceback" not in err


def test_console_script_error_has_no_traceback():
    result = subprocess.run(
        [sys.executable, "-m", "workflow", "evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "0.7"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
