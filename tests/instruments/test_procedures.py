"""Procedures and logs: campaigns through the simulator, safety, faults, resume, the CLI."""

import csv
import subprocess
import time
from pathlib import Path

import pytest
import serial
from user_facing import TACTILE
from paths import CHECKOUT

from instruments.drivers.errors import ConnectionLost, InstrumentError, SafetyLimitError
from instruments.procedures.logwriter import LogWriter, read_log
from instruments.procedures.simulated import reopened_station, simulate_campaign, simulated_station
from instruments.procedures.sweeps import (
    CampaignPlan,
    ResonancePlan,
    VoltageSweepPlan,
    q_campaign,
    resonance_search,
    voltage_sweep,
)
from instruments.simulator import FaultSettings, default_bench_settings
from workflow import logformat
from workflow.cli import main
from workflow.damping.logs import read_log as read_for_fit
from workflow.errors import InputFileError

ROOT = CHECKOUT
PLAN = CampaignPlan(32126.0, span=1200.0, points_per_sweep=21, voltages=(2.5, 7.5, 15.0))


def keys(path):
    rows = read_log(Path(path)).rows
    return [(r[logformat.SWEEP], r[logformat.FREQUENCY], r[logformat.DRIVE_VOLTAGE]) for r in rows]


def test_simulate_campaign_is_fast_complete_and_readable_by_the_fit(tmp_path):
    start = time.perf_counter()
    result = simulate_campaign(tmp_path / "c.csv", seed=3)
    elapsed = time.perf_counter() - start
    assert elapsed < 5
    assert result.planned == result.measured == 6 * 51
    log = read_for_fit(result.path)
    assert log.n_sweeps == 6 and len(log.velocity) == 306
    metadata = read_log(result.path).metadata
    assert metadata["simulated"] == "yes" and metadata["simulator_law"] == "quadratic"
    assert metadata["simulator_seed"] == "3" and metadata["format_version"] == "1"
    peaks = [s["peak_velocity_m_s"] for s in result.summary["sweeps"]]
    assert peaks == sorted(peaks) and 0.2 < peaks[-1] < 0.235  # ~0.216 m/s at 15 V


def test_alternating_sweeps_run_odd_sweeps_downward_and_a_log_resumes_only_with_its_own_setting(tmp_path):
    """--alternate: odd sweeps run downward (a drift then shows against Q, docs/damping.md); the default plan runs every
    sweep upward and writes no plan_alternate (the logs made before the option resume with it).  A log made one way is
    refused by the other with the way to resume it, untouched, and resumes with its own."""
    alternating = CampaignPlan(32126.0, span=600.0, points_per_sweep=5, voltages=(5.0, 10.0, 15.0), alternate=True)
    for sweep, upward in ((0, True), (1, False), (2, True)):
        frequency = [p.frequency for p in alternating.points() if p.sweep == sweep]
        assert frequency == sorted(frequency, reverse=not upward)
    default = CampaignPlan(32126.0, span=600.0, points_per_sweep=5, voltages=(5.0, 10.0, 15.0))
    assert [p.frequency for p in default.points() if p.sweep == 1] == sorted(p.frequency for p in default.points() if p.sweep == 1)
    station, _ = simulated_station(default_bench_settings(seed=1), settle_time=0.0)
    path = tmp_path / "alternating.csv"
    q_campaign(station, path, alternating, fsync=False)
    assert read_log(path).metadata["plan_alternate"] == "True"
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:-3]))  # cut short
    missing = 15 - len(read_log(path).rows)
    before = path.read_bytes()
    with pytest.raises(InputFileError, match="resumes with the --alternate setting it was made with"):
        q_campaign(station, path, default, fsync=False)
    assert path.read_bytes() == before
    assert missing > 0 and q_campaign(station, path, alternating, fsync=False).measured == missing
    one_way = tmp_path / "one_way.csv"
    q_campaign(station, one_way, default, fsync=False)
    with pytest.raises(InputFileError, match="resumes with the --alternate setting it was made with"):
        q_campaign(station, one_way, alternating, fsync=False)


def test_simulate_campaign_is_deterministic(tmp_path):
    a = simulate_campaign(tmp_path / "a.csv", voltages=(5.0,), points_per_sweep=11, seed=1)
    b = simulate_campaign(tmp_path / "b.csv", voltages=(5.0,), points_per_sweep=11, seed=1)
    assert a.path.read_text() == b.path.read_text()


def test_resonance_search_finds_the_simulated_resonance_and_low_drive_q(tmp_path):
    station, bench = simulated_station(default_bench_settings(), settle_time=0.0)
    result = resonance_search(station, tmp_path / "r.csv", ResonancePlan(voltage=0.5), fsync=False)
    f_r = bench.settings.response.resonance_at(bench.time)
    assert result.summary["resonance_frequency_hz"] == pytest.approx(f_r, abs=10)
    assert result.summary["q_estimate"] == pytest.approx(bench.settings.response.law.q0, rel=0.1)
    assert bench.ceramic_voltage() == 0.0  # output off at the end


def test_voltage_sweep_deflection_grows_sublinearly(tmp_path):
    station, bench = simulated_station(default_bench_settings(), settle_time=0.0)
    f_r = bench.settings.response.resonance_frequency
    result = voltage_sweep(station, tmp_path / "v.csv", VoltageSweepPlan(f_r, (1.0, 15.0)), fsync=False)
    w1, w15 = result.summary["deflection_um"]
    assert w15 == pytest.approx(1.07, rel=0.05)  # Q = 54 at 15 V: the beam model's deflection
    assert w15 / w1 < 15 / 1.5  # Q falls with velocity


def test_procedure_refuses_a_plan_above_the_limit_before_touching_anything(tmp_path):
    station, bench = simulated_station(default_bench_settings(), voltage_limit=12.0)
    with pytest.raises(SafetyLimitError, match="safety limit 12 V"):
        q_campaign(station, tmp_path / "c.csv", PLAN)
    assert not (tmp_path / "c.csv").exists() and bench.faults.commands == 0


def test_instrument_limit_holds_when_the_software_limit_is_set_too_high(tmp_path):
    settings = default_bench_settings(ceramic_voltage_limit=10.0)
    station, bench = simulated_station(settings, voltage_limit=20.0, settle_time=0.0)
    with pytest.raises(InstrumentError, match=r"-222,Data out of range after setting 15 V"):
        q_campaign(station, tmp_path / "c.csv", PLAN, fsync=False)
    assert bench.generator.state.amplitude_vpp * bench.amplifier.gain / 2 <= 10.0
    assert keys(tmp_path / "c.csv")  # the sweeps below the limit were logged


def test_campaign_survives_dropped_and_garbled_replies(tmp_path):
    faults = FaultSettings(drop_rate=0.05, garble_rate=0.05, seed=2)
    station, bench = simulated_station(default_bench_settings(faults=faults), settle_time=0.0, retries=5)
    result = q_campaign(station, tmp_path / "c.csv", PLAN, fsync=False)
    assert result.measured == result.planned == 63
    assert sorted(keys(tmp_path / "c.csv")) == sorted(set(keys(tmp_path / "c.csv")))
    assert bench.faults.commands > 63 * 3


def test_retries_are_bounded_with_a_clear_error(tmp_path):
    faults = FaultSettings(drop_rate=0.95, seed=1)
    station, _ = simulated_station(default_bench_settings(faults=faults), settle_time=0.0, retries=2)
    with pytest.raises(InstrumentError, match="giving up after 3 attempts"):
        q_campaign(station, tmp_path / "c.csv", PLAN, fsync=False)


def test_disconnect_mid_campaign_then_resume_gives_every_row_once(tmp_path):
    path = tmp_path / "c.csv"
    settings = default_bench_settings(faults=FaultSettings(disconnect_at=120))
    station, bench = simulated_station(settings, settle_time=0.0)
    with pytest.raises(ConnectionLost, match="disconnected"):
        q_campaign(station, path, PLAN, fsync=False)
    partial = keys(path)
    assert 0 < len(partial) < 63
    with open(path, "a") as file:  # a crash in the middle of a row
        file.write("32126.3,15,0.2")
    # reconnect to the same bench (the fault fired once) and resume
    again = reopened_station(station, bench)
    result = q_campaign(again, path, PLAN, fsync=False)
    assert result.resumed == len(partial) and result.truncated_bytes == len("32126.3,15,0.2")
    final = keys(path)
    assert len(final) == len(set(final)) == 63
    assert final[: len(partial)] == partial
    assert len(read_for_fit(path).velocity) == 63


def test_resume_with_another_plan_is_refused(tmp_path):
    path = tmp_path / "c.csv"
    simulate_campaign(path, voltages=(5.0,), points_per_sweep=5)
    with pytest.raises(InputFileError, match="cannot resume"):
        simulate_campaign(path, voltages=(5.0, 10.0), points_per_sweep=5, restart=False)
    text = path.read_text()
    simulate_campaign(path, voltages=(5.0,), points_per_sweep=5, restart=False)
    assert path.read_text() == text  # nothing left to measure, nothing changed


@pytest.mark.parametrize("cut", [b"# format_ver", "# plate: λ".encode()[:-1], b"\x00" * 32],
                         ids=["ascii", "inside-a-character", "nul-padded"])
def test_log_writer_restarts_a_log_cut_inside_its_header(tmp_path, cut):
    path = tmp_path / "c.csv"
    path.write_bytes(b"# tactile interferometer log\n" + cut)
    with LogWriter(path, {"procedure": "campaign"}) as log:
        log.append({logformat.FREQUENCY: 1.0, logformat.DRIVE_VOLTAGE: 2.0, logformat.VELOCITY: 0.1})
    rows = list(csv.reader(line for line in path.read_text().splitlines() if not line.startswith("#")))
    assert rows == [list(logformat.COLUMNS), ["1", "2", "0.1", "", "", ""]]


@pytest.mark.parametrize("cut", [b"32126.3,15,0.2", b"32126.3,15,0." + b"\x00" * 4000, b"\x00" * 512],
                         ids=["mid-row", "nul-padded-row", "nul-padding"])
def test_a_log_cut_by_a_power_loss_resumes_with_every_complete_row(tmp_path, cut):
    """A power loss may leave the last block of a file padded with NUL bytes: that unterminated tail is a write cut
    short like any other (kept, reported, the point measured again), not a binary file."""
    path = tmp_path / "c.csv"
    simulate_campaign(path, voltages=(5.0,), points_per_sweep=5)
    complete = path.read_bytes()
    written = keys(path)
    rows = [line for line in complete.splitlines(keepends=True) if not line.startswith(b"#")]
    path.write_bytes(complete[: complete.index(rows[-2])] + cut)  # the last two rows lost, the file cut in the next
    assert len(read_for_fit(path).velocity) == len(written) - 2  # the fit reads the complete rows, with a warning
    result = simulate_campaign(path, voltages=(5.0,), points_per_sweep=5, restart=False)
    assert result.resumed == len(written) - 2 and result.truncated_bytes == len(cut)
    assert keys(path) == written


def run_cli(capsys, *argv):
    try:
        code = main(list(argv))
    except SystemExit as exit:  # argparse usage errors
        code = exit.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_measure_simulated_campaign_and_resume(tmp_path, capsys):
    out = tmp_path / "c.csv"
    args = ["measure", "campaign", "--simulate", "--points", "9", "--voltages", "5,10", "--out", str(out), "--json"]
    code, stdout, _ = run_cli(capsys, *args)
    assert code == 0 and '"measured": 18' in stdout.splitlines()[-1]
    assert (tmp_path / "c-resonance.csv").exists()
    code, stdout, _ = run_cli(capsys, *args)
    assert code == 0 and '"measured": 0' in stdout.splitlines()[-1] and '"resumed": 18' in stdout


def test_cli_measure_logs_under_an_ignored_measurements_folder_by_default(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, stdout, _ = run_cli(capsys, "measure", "voltage-sweep", "--simulate", "--voltages", "1,2")
    assert code == 0
    assert (tmp_path / "measurements" / "voltage-sweep.csv").is_file()
    assert (tmp_path / "measurements" / "voltage-sweep-resonance.csv").is_file()
    assert "log: measurements/voltage-sweep.csv" in stdout and not (tmp_path / "data").exists()
    if (ROOT / ".git").exists():
        ignored = subprocess.run(["git", "check-ignore", "-q", "measurements/voltage-sweep.csv"], cwd=ROOT)
        assert ignored.returncode == 0


def test_cli_safety_limit_refuses_with_one_line(tmp_path, capsys):
    code, _, err = run_cli(capsys, "measure", "voltage-sweep", "--simulate", "--frequency-hz", "32126",
                           "--voltages", "10,35", "--out", str(tmp_path / "v.csv"))
    assert code == 2 and err.count("\n") == 1 and "safety limit 30 V" in err
    code, _, err = run_cli(capsys, "measure", "voltage-sweep", "--simulate", "--frequency-hz", "32126",
                           "--voltages", "35", "--max-voltage", "40", "--out", str(tmp_path / "w.csv"))
    assert code == 2 and "-222" in err and err.count("\n") == 1


def test_cli_bad_port_and_garbled_replies_are_one_line_errors(tmp_path, capsys):
    code, _, err = run_cli(capsys, "measure", "resonance", "--generator", "/dev/nonexistent-tty",
                           "--vibrometer", "/dev/nonexistent-tty2", "--lockin", "/dev/nonexistent-tty3",
                           "--out", str(tmp_path / "r.csv"))
    assert code == 2 and err.startswith("tactile measure: error: cannot open --generator /dev/nonexistent-tty")
    code, _, err = run_cli(capsys, "measure", "resonance", "--generator", "/dev/nonexistent-tty",
                           "--vibrometer", "/dev/nonexistent-tty2", "--out", str(tmp_path / "r.csv"))
    assert code == 2 and "need --generator PORT, --vibrometer PORT and --lockin PORT" in err
    code, _, err = run_cli(capsys, "measure", "resonance", "--simulate", "--garble-rate", "0.9", "--retries", "1",
                           "--out", str(tmp_path / "g.csv"))
    assert code == 2 and "garbled" in err and err.count("\n") == 1
    code, _, err = run_cli(capsys, "measure", "campaign", "--simulate", "--voltages", "5,x")
    assert code == 2 and "comma-separated" in err


def test_shipped_sample_campaign_regenerates_identically(tmp_path):
    shipped = ROOT / "data" / "sample_campaign.csv"
    out = tmp_path / "sample_campaign.csv"
    subprocess.run([*TACTILE, "measure",
                    "campaign", "--simulate", "--seed", "0", "--restart", "--out", str(out)],
                   check=True, capture_output=True, cwd=tmp_path)
    assert out.read_text() == shipped.read_text()
    logged = read_log(shipped)
    metadata, rows = logged.metadata, logged.rows
    assert metadata["simulated"] == "yes" and len(rows) == 306


@pytest.mark.hardware
def test_real_generator_identifies():
    """Opt-in (``pytest -m hardware``): a real 33500-series generator on $TACTILE_GENERATOR_PORT."""
    import os

    from instruments.drivers.generator import FunctionGenerator

    port = os.environ.get("TACTILE_GENERATOR_PORT")
    if not port:
        pytest.skip("set TACTILE_GENERATOR_PORT to a real 33500-series generator")
    assert FunctionGenerator(serial.Serial(port, timeout=2), 0.5).identity


@pytest.mark.parametrize(
    "argv, message",
    [
        (["campaign", "--points", "2"], "--points must be at least 3"),
        (["resonance", "--start-hz", "40000", "--stop-hz", "30000"], "must be below --stop-hz"),
        (["voltage-sweep", "--frequency-hz", "-3"], "--frequency-hz must be positive"),
        (["campaign", "--max-voltage", "0"], "argument --max-voltage: 0 is outside the accepted range 0.001 to 1000 V"),
        (["campaign", "--drop-rate", "1.5"], "bad fault flag"),
        (["campaign", "--generator", "/dev/ttyUSB0"], "not both"),
    ],
)
def test_cli_bad_plan_flags(tmp_path, capsys, argv, message):
    code, _, err = run_cli(capsys, "measure", *argv, "--simulate", "--out", str(tmp_path / "x.csv"))
    assert code == 2 and message in err and err.count("\n") == 1
    assert not (tmp_path / "x.csv").exists()
