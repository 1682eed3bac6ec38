"""Every boundary validates (issue 18, part 1): hostile numbers, output locations and damaged inputs
give one error line naming the option, key or file and what is accepted, exit status 2, and leave
the input files alone."""

import json
import os

import numpy as np
import pytest
from user_facing import SAMPLE_CAMPAIGN, run_cli

from workflow.damping.posterior import DampingPosterior, load_posterior, save_posterior
from workflow.models import materials
from workflow.models.plate import ORIGINAL_PLATE
from workflow.optimise.problem import DesignProblem, optimise_analytical


def _with_velocity(text: str, value: str, rows=None) -> str:
    """The sample log with the velocity of the data rows (or of the ``rows``-th ones) set to ``value``."""
    lines = text.splitlines(keepends=True)
    header = next(i for i, line in enumerate(lines) if line.startswith("frequency_hz"))
    column = lines[header].strip().split(",").index("velocity_m_s")
    for index in range(header + 1, len(lines)):
        if rows is None or index - header in rows:
            cells = lines[index].rstrip("\n").split(",")
            cells[column] = value
            lines[index] = ",".join(cells) + "\n"
    return "".join(lines)


@pytest.fixture
def inputs(tmp_path, monkeypatch):
    """A working folder with good and damaged input files; the test runs in it."""
    monkeypatch.chdir(tmp_path)
    text = SAMPLE_CAMPAIGN.read_text(encoding="utf-8")
    (tmp_path / "log.csv").write_text(text, encoding="utf-8")
    (tmp_path / "fast.csv").write_text(_with_velocity(text, "1e6", rows={5}), encoding="utf-8")
    (tmp_path / "zero.csv").write_text(_with_velocity(text, "0"), encoding="utf-8")
    (tmp_path / "tiny.csv").write_text(_with_velocity(text, "1e-12"), encoding="utf-8")
    lines = text.splitlines(keepends=True)
    (tmp_path / "long.csv").write_text("".join(lines[:-2] + ["9" * 1_000_000 + "\n"] + lines[-2:]), encoding="utf-8")
    (tmp_path / "file.txt").write_text("not a folder\n", encoding="utf-8")
    (tmp_path / "folder").mkdir()
    (tmp_path / "empty.npz").write_bytes(b"")
    posteriors = {"whole.npz": (150.0, 0.25), "negative_q0.npz": (-5.0, 0.25), "negative_alpha.npz": (150.0, -1e3),
                  "huge_alpha.npz": (150.0, 1e300)}
    for name, (q0, alpha) in posteriors.items():
        samples = np.column_stack([np.full(8, q0), np.full(8, alpha)])
        posterior = DampingPosterior("quadratic", {"q0": samples[:, 0], "alpha": samples[:, 1]})
        save_posterior(posterior, tmp_path / name, samples, ["q0", "alpha"])
    whole = (tmp_path / "whole.npz").read_bytes()
    (tmp_path / "truncated.npz").write_bytes(whole[: len(whole) // 2])
    (tmp_path / "hot.toml").write_text("[design]\nvoltage_v = 1e4\n", encoding="utf-8")
    (tmp_path / "inf.toml").write_text("[fem]\nwidth_max_mm = inf\n", encoding="utf-8")
    (tmp_path / "seed.toml").write_text("[campaign]\nseed = -1\n", encoding="utf-8")
    (tmp_path / "draws.toml").write_text("[damping]\nposterior_draws = 0\n", encoding="utf-8")
    return tmp_path


CASES = {
    # extreme numbers
    "voltage 1e300": ("optimize --hp-mm 1 --voltage 1e300 --json", ["--voltage", "1000 V"]),
    "q 1e300": ("optimize --hp-mm 1 --q 1e300 --json", ["--q", "100000"]),
    "q below 1": ("evaluate --lambda-mm 24 --hi-mm 2 --hp-mm 1 --q 0.5", ["--q", "1 to"]),
    "voltage nan": ("evaluate --lambda-mm 24 --hi-mm 2 --hp-mm 1 --voltage nan", ["--voltage"]),
    "maps voltage 1e4": ("maps --hp-mm 1 --voltage 1e4 --grid 5 --out maps", ["--voltage", "1000"]),
    "fem space mapping 1e4": (
        "optimize --model fem --method space-mapping --hp-mm 1 --voltage 1e4",
        ["--voltage", "1000"],
    ),
    "maps grid 1": ("maps --hp-mm 1 --grid 1 --out maps", ["--grid", "2 to 400"]),
    "maps grid huge": ("maps --hp-mm 1 --grid 100000000 --out maps", ["--grid", "2 to 400"]),
    "measure seed -1": ("measure campaign --simulate --seed -1 --out c.csv", ["--seed", "4294967295"]),
    "simulate seed 2^32": ("simulate --seed 4294967296", ["--seed", "0 to 4294967295"]),
    "fit seed -1": ("fit-damping log.csv --out fit --seed -1", ["--seed", "0 to 4294967295"]),
    "fit max steps 1e20": (
        "fit-damping log.csv --out fit --max-steps 100000000000000000000",
        ["--max-steps", "1000000"],
    ),
    "measure timeout -1": ("measure resonance --simulate --timeout -1 --out r.csv", ["--timeout", "3600 s"]),
    "measure baudrate 0": ("measure resonance --simulate --baudrate 0 --out r.csv", ["--baudrate", "50 to"]),
    "measure retries -1": ("measure resonance --simulate --retries -1 --out r.csv", ["--retries", "0 to 100"]),
    "bench limit inf": ("measure resonance --simulate --bench-limit inf --out r.csv", ["--bench-limit", "0.001 to 1000 V"]),
    # output locations
    "maps out file": ("maps --hp-mm 1 --grid 2 --out file.txt", ["--out file.txt", "not a folder"]),
    "maps out under file": ("maps --hp-mm 1 --grid 2 --out file.txt/sub", ["--out file.txt/sub"]),
    "maps out in proc": ("maps --hp-mm 1 --grid 2 --out /proc/tactile-maps", ["--out /proc/tactile-maps"]),
    "run out file": ("run --out file.txt", ["--out file.txt", "not a folder"]),
    "run out under file": ("run --out file.txt/sub", ["--out file.txt/sub"]),
    "run out in proc": ("run --out /proc/tactile-run", ["--out /proc/tactile-run"]),
    "fit out file": ("fit-damping log.csv --out file.txt", ["--out file.txt", "not a folder"]),
    "fit out in proc": ("fit-damping log.csv --out /proc/tactile-fit", ["--out /proc/tactile-fit"]),
    # damaged inputs
    "empty posterior": ("optimize --hp-mm 1 --damping empty.npz", ["empty.npz", "truncated"]),
    "truncated posterior": ("evaluate --lambda-mm 24 --hi-mm 2 --hp-mm 1 --damping truncated.npz", ["truncated.npz"]),
    "posterior q0 < 1": ("optimize --hp-mm 1 --damping negative_q0.npz", ["negative_q0.npz", "q0", "1 to 100000"]),
    "posterior alpha < 0": (
        "optimize --hp-mm 1 --damping negative_alpha.npz",
        ["negative_alpha.npz", "alpha", "0 to 1e+12"],
    ),
    "posterior alpha 1e300": (
        "evaluate --lambda-mm 24 --hi-mm 2 --hp-mm 1 --damping huge_alpha.npz",
        ["huge_alpha.npz", "alpha"],
    ),
    "config is a folder": ("run --config folder --print-config", ["folder: is a folder"]),
    "config voltage 1e4": ("run --config hot.toml --print-config", ["hot.toml", "design.voltage_v", "1000"]),
    "config inf": ("run --config inf.toml --print-config", ["inf.toml", "fem.width_max_mm", "finite"]),
    "config seed -1": ("run --config seed.toml --print-config", ["seed.toml", "campaign.seed", "4294967295"]),
    "config no draws": ("run --config draws.toml --print-config", ["draws.toml", "damping.posterior_draws", "1 to 10000"]),
    "log 1e6 m/s": ("fit-damping fast.csv --out fit", ["fast.csv, line", "0 to 10 m/s"]),
    "log all zero": ("fit-damping zero.csv --out fit", ["zero.csv, line", "1e-06 m/s"]),
    "log tiny": ("fit-damping tiny.csv --out fit", ["tiny.csv, line", "1e-06 m/s"]),
    "log long line": ("fit-damping long.csv --out fit", ["long.csv, line", "10000"]),
}


@pytest.mark.parametrize("argv, expected", CASES.values(), ids=CASES.keys())
def test_one_error_line_exit_2_and_inputs_unchanged(inputs, capsys, argv, expected):
    before = {path: path.read_bytes() for path in inputs.iterdir() if path.is_file()}
    status, _, err = run_cli(capsys, *argv.split())
    assert status == 2, err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err and "internal error" not in err
    for text in expected:
        assert text in err
    assert {path: path.read_bytes() for path in inputs.iterdir() if path.is_file()} == before
    assert not any((inputs / name).exists() for name in ("fit", "maps", "r.csv", "c.csv"))


def test_the_undamaged_posterior_loads(inputs):
    posterior = load_posterior(inputs / "whole.npz")
    assert posterior.law_name == "quadratic" and posterior.median_law().q0 == 150.0


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_out_under_a_read_only_folder_is_refused(inputs, capsys):
    locked = inputs / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        status, _, err = run_cli(capsys, "maps", "--hp-mm", "1", "--grid", "2", "--out", locked / "maps")
    finally:
        locked.chmod(0o755)
    assert status == 2 and len(err.strip().splitlines()) == 1
    assert f"--out {locked / 'maps'}" in err and "Permission denied" in err


@pytest.mark.parametrize("argv", [["optimize", "--hp-mm", "1", "--voltage", "1000", "--q", "1e5", "--json"],
                                  ["optimize", "--hp-mm", "0.5", "--voltage", "0.001", "--q", "1", "--json"]])
def test_the_ends_of_the_ranges_are_accepted(capsys, argv):
    status, out, err = run_cli(capsys, *argv)
    assert status == 0, err
    record = json.loads(out.strip().splitlines()[-1])
    assert record["f_r_khz"] == pytest.approx(25.0, rel=1e-6) and record["constraint_active"]


def test_the_optimum_geometry_does_not_depend_on_q_times_voltage():
    """The beam deflection is proportional to Q V: the optimum plate is the same at 1e5 x 1000 V as at
    the design point (the optimiser once stopped on round-off there)."""

    def optimum(q, voltage):
        problem = DesignProblem(ceramic_thickness=1e-3, width=ORIGINAL_PLATE.width, voltage=voltage,
                                min_resonator_thickness=materials.PRACTICAL_MIN_RESONATOR_THICKNESS)
        return optimise_analytical(problem, q)

    design = optimum(materials.PLATE_Q, materials.DESIGN_VOLTAGE)
    extreme = optimum(1e5, 1000.0)
    assert extreme.plate.wavelength == pytest.approx(design.plate.wavelength, rel=1e-5)
    assert extreme.plate.resonator_thickness == pytest.approx(design.plate.resonator_thickness, rel=1e-5)
    scale = 1e5 * 1000.0 / (materials.PLATE_Q * materials.DESIGN_VOLTAGE)
    assert extreme.deflection == pytest.approx(design.deflection * scale, rel=1e-5)


def test_help_states_the_ranges(capsys):
    status, out, _ = run_cli(capsys, "optimize", "--help")
    assert status == 0
    text = " ".join(out.split())
    assert "0.001 to 1000 V" in text and "1 to 100000" in text


@pytest.mark.slow
def test_fem_space_mapping_at_the_top_of_the_voltage_range_finds_the_design_voltage_geometry(capsys, tmp_path, monkeypatch):
    """The issue's ``optimize --model fem --method space-mapping --hp-mm 1 --voltage 1e4`` is refused by the
    range; at its top, 1000 V, the search runs and the plate is the one found at 15 V (the FEM is linear:
    the deflection scales with V). About 20 s with a cold FEM cache."""
    monkeypatch.setenv("TACTILE_CACHE", str(tmp_path / "cache"))
    records = {}
    for voltage in ("15", "1000"):
        status, out, err = run_cli(capsys, "optimize", "--model", "fem", "--method", "space-mapping", "--hp-mm", "1",
                                   "--voltage", voltage, "--json")
        assert status == 0, err
        records[voltage] = json.loads(out.strip().splitlines()[-1])
    low, high = records["15"], records["1000"]
    assert high["lambda_mm"] == pytest.approx(low["lambda_mm"], abs=1e-3)
    assert high["h_i_mm"] == pytest.approx(low["h_i_mm"], abs=1e-3)
    assert high["w_dyn_um"] == pytest.approx(low["w_dyn_um"] * 1000 / 15, rel=1e-3)
