"""``tactile evaluate --model fem``: JSON contract, human output and refusal of bad geometry."""

import json
import re

import pytest
from user_facing import assert_readable, run_cli


def test_fem_evaluate_json_lists_the_modes(capsys):
    status, out, _ = run_cli(capsys, "evaluate", "--model", "fem", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--b-mm", "55",
                          "--accuracy", "0.01", "--json")
    assert status == 0
    record = json.loads(out.strip().splitlines()[-1])
    for key in ("lambda_mm", "h_i_mm", "h_p_mm", "b_mm", "q", "voltage_v", "w_dyn_um", "f_r_khz", "modes"):
        assert key in record
    assert len(record["modes"]) == 6
    best = max(record["modes"], key=lambda mode: mode["w_um"])
    assert best["f_khz"] == pytest.approx(record["f_r_khz"]) and best["w_um"] == pytest.approx(record["w_dyn_um"])
    assert 29.0 < record["f_r_khz"] < 33.0
    assert 0 <= best["transverse"] < 0.1


def test_fem_evaluate_marks_the_working_mode(capsys):
    """The human mode list marks one mode, the one whose deflection and frequency are reported."""
    status, out, _ = run_cli(capsys, "evaluate", "--model", "fem", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--b-mm", "55",
                              "--accuracy", "0.01")
    assert status == 0
    assert_readable(out)
    first, accuracy, *modes = out.strip().splitlines()
    assert accuracy.startswith("  FEM accuracy: f_r ") and "target 1 % met" in accuracy
    reported = re.search(r"w_dyn ([\d.]+) µm at f_r ([\d.]+) kHz", first).groups()[::-1]
    marked = [line for line in modes if "working mode" in line]
    assert len(modes) == 6 and len(marked) == 1
    assert re.search(r"mode +([\d.]+) kHz: ([\d.]+) µm", marked[0]).groups() == reported


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "0.7"], "commercial"),
        (["--lambda-mm", "50", "--hi-mm", "2", "--hp-mm", "1"], "wavelength"),
        (["--lambda-mm", "24", "--hi-mm", "5", "--hp-mm", "1"], "resonator thickness"),
        (["--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--b-mm", "10"], "--b-mm: 10 is outside the accepted range 30 to 100 mm"),
        (["--lambda-mm", "-24", "--hi-mm", "2", "--hp-mm", "1"], "positive"),
    ],
)
def test_fem_evaluate_refuses_bad_geometry_in_one_line(capsys, flags, message):
    status, out, err = run_cli(capsys, "evaluate", "--model", "fem", *flags, "--json")
    assert status == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and message in err and "Traceback" not in err
