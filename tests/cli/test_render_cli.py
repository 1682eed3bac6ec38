"""``tactile render`` and ``tactile measure render`` on the command line: outputs, and one clear line per bad texture."""

import json

import numpy as np
import pytest

from workflow.cli import main
from workflow.damping.posterior import DampingPosterior, save_posterior
from workflow.rendering import synthesis


@pytest.fixture(autouse=True)
def short_search(monkeypatch):
    """Three grating periods for the smallest-period search: enough for the command's plumbing."""
    monkeypatch.setattr(synthesis, "SEARCH_POINTS", 3)


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_render_on_the_embedded_defaults_writes_the_drive_for_the_generator(tmp_path, capsys):
    assert main(["render", "--out", str(tmp_path), "--json"]) == 0
    result = _json(capsys)
    assert result["texture_kind"] == "grating" and result["texture_period_mm"] == 2
    assert result["error"] < result["plain_error"] and result["peak_drive_v"] <= 30.0
    assert result["model"]["law"] == "constant" and result["points"] <= 512
    for key in ("table", "figure", "summary", "precompensated_arb", "precompensated_scpi", "plain_arb"):
        assert (tmp_path / result["files"][key].split("/")[-1]).is_file()
    script = (tmp_path / "precompensated.scpi").read_text().splitlines()
    assert script[0] == "OUTP 0" and "AM:INT:FUNC ARB" in script and script[-1] == "OUTP 1"
    table = np.genfromtxt(tmp_path / "drive.csv", delimiter=",", names=True)
    assert len(table) == result["points"] and np.all(table["drive_v"] <= 30.0)


def test_render_with_a_fitted_posterior_uses_its_law_and_measured_plate(tmp_path, capsys):
    fit = tmp_path / "fit"
    fit.mkdir()
    samples = 40
    posterior = DampingPosterior("quadratic", {"q0": np.full(samples, 140.0), "alpha": np.full(samples, 0.3)})
    save_posterior(posterior, fit / "posterior.npz", np.zeros((samples, 2)), ["q0", "alpha"])
    parameters = {"gain": {"median": 1.3e-9}, "f_r_0": {"median": 32050.0}, "kappa": {"median": 0.08}}
    (fit / "fit.json").write_text(json.dumps({"parameters": parameters}))
    assert main(["render", "--damping", str(fit), "--period-mm", "4", "--speed-mm-s", "50", "--points", "64", "--out",
                 str(tmp_path / "out"), "--json"]) == 0
    model = _json(capsys)["model"]
    assert model["law"] == "quadratic" and model["law_parameters"] == {"q0": 140.0, "alpha": pytest.approx(0.3)}
    assert (model["resonance_frequency_hz"], model["gain_m_v"], model["softening_s2_m2"]) == (32050.0, 1.3e-9, 0.08)
    assert "posterior-median" in model["source"] and "fit's measured plate" in model["source"]


def _write(path, text: str) -> str:
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("arguments, message", [
    (["--period-mm", "-2"], "argument --period-mm: expected a positive number"),
    (["--levels-um", "0.3,9"], "the texture asks for 9 µm, above the"),
    (["--levels-um", "1,0.5"], "--levels-um needs 0 <= LOW < HIGH"),
    (["--friction-curve", "{empty}", "--levels-friction", "1,0.6"], "empty (expected a header row amplitude_um,friction"),
    (["--friction-curve", "{wavy}", "--levels-friction", "1,0.6"], "line 4: the friction ratio must be strictly monotonic"),
    (["--levels-friction", "1,0.6"], "--levels-friction needs --friction-curve"),
    (["--trace", "{backwards}"], "line 4: the finger trace goes backwards in time"),
    (["--profile", "{no_amplitude}"], "no column amplitude_um"),
    (["--profile", "{bad_value}"], "line 3: amplitude_um = 'x' is not a finite number"),
])
def test_a_bad_texture_is_one_clear_error_line(arguments, message, tmp_path, capsys):
    files = {
        "empty": _write(tmp_path / "empty.csv", "# nothing here\n"),
        "wavy": _write(tmp_path / "wavy.csv", "amplitude_um,friction\n0,1\n0.5,0.7\n1.0,0.8\n"),
        "backwards": _write(tmp_path / "trace.csv", "time_s,position_mm\n0,0\n0.01,1\n0.005,2\n"),
        "no_amplitude": _write(tmp_path / "profile.csv", "position_mm,height\n0,1\n1,2\n"),
        "bad_value": _write(tmp_path / "profile2.csv", "position_mm,amplitude_um\n0,1\n1,x\n"),
    }
    arguments = [files[a[1:-1]] if a.startswith("{") else a for a in arguments]
    with pytest.raises(SystemExit) if arguments[:1] == ["--period-mm"] else _returns(2) as status:
        status.value = main(["render", "--out", str(tmp_path / "out"), *arguments])
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err
    assert not (tmp_path / "out" / "render.json").exists()


class _returns:
    """Context manager recording a command's exit status (``value``) and checking it on exit."""

    def __init__(self, expected: int):
        self.expected, self.value = expected, None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        assert exc[0] is None and self.value == self.expected
        return False


def test_measure_render_on_the_simulator_plays_both_drives_and_compares(tmp_path, capsys):
    out = tmp_path / "render.csv"
    assert main(["measure", "render", "--simulate", "--out", str(out), "--frequency-hz", "32126", "--settle-s", "0.1",
                 "--json"]) == 0
    result = _json(capsys)
    assert result["procedure"] == "render" and result["measured"] == 512
    assert set(result["comparison"]) == {"plain", "precompensated"}
    assert result["comparison"]["precompensated"]["error"] < result["comparison"]["plain"]["error"]
    assert (tmp_path / "render.png").is_file()
    assert main(["measure", "render", "--simulate", "--out", str(out), "--frequency-hz", "32126", "--settle-s", "0.1",
                 "--json"]) == 0
    assert _json(capsys)["resumed"] == 512  # a rerun resumes the complete log


def test_a_friction_profile_under_a_recorded_trace_renders(tmp_path, capsys):
    curve = _write(tmp_path / "curve.csv", "# measured on our plate\namplitude_um,friction\n0,1\n0.5,0.8\n1.0,0.6\n1.5,0.5\n")
    profile = _write(tmp_path / "profile.csv", "position_mm,friction,note\n0,0.9,a\n5,0.55,b\n10,0.9,c\n")
    trace = _write(tmp_path / "trace.csv", "time_s,position_mm\n0,0\n0.05,6\n0.1,10\n")
    assert main(["render", "--profile", profile, "--friction-curve", curve, "--trace", trace, "--points", "64",
                 "--out", str(tmp_path / "out"), "--json"]) == 0
    result = _json(capsys)
    assert result["texture_kind"] == "profile" and result["texture_finger"] == "trace"
    assert result["loop_s"] == pytest.approx(0.1) and result["texture_speed_mm_s"] == pytest.approx(100)
    low, high = result["texture_levels_um"]
    assert 0.2 < low < 0.3 and 1.2 < high < 1.3  # friction 0.9 and 0.55 through the curve
