"""Log integrity (issue 19, items 3, 4, 5, 7): one writer per log, foreign files untouched,
refused settings never logged, bounded plan sizes."""

import os
import subprocess
import threading

import pytest
from user_facing import TACTILE

from instruments.drivers.errors import InstrumentError
from instruments.procedures.logwriter import LogWriter, read_log
from instruments.procedures.simulated import simulated_station
from instruments.procedures.sweeps import CampaignPlan, PlannedPoint, VoltageSweepPlan, _measure_points, q_campaign
from instruments.simulator import default_bench_settings
from workflow import logformat
from workflow.cli import main
from workflow.errors import InputFileError, TactileError
from workflow.pipeline.config import default_config, merge

SMALL = CampaignPlan(32126.0, span=600.0, points_per_sweep=7, voltages=(2.5, 5.0))


def run_cli(capsys, *argv):
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def row_keys(path):
    rows = read_log(path).rows
    return [(r[logformat.SWEEP], r[logformat.FREQUENCY], r[logformat.DRIVE_VOLTAGE]) for r in rows]


# item 3: one writer per log

def test_a_second_procedure_on_a_log_in_use_fails_at_once_and_the_first_completes(tmp_path):
    path = tmp_path / "c.csv"
    started, release = threading.Event(), threading.Event()

    def held_sleep(seconds):
        started.set()
        release.wait(10)
        bench.sleep(seconds)  # the lock-in settles in bench time

    station, bench = simulated_station(default_bench_settings(), settle_time=0.001, sleep=held_sleep)
    outcome = {}
    first = threading.Thread(target=lambda: outcome.setdefault("first", q_campaign(station, path, SMALL, fsync=False)))
    first.start()
    assert started.wait(10)
    other, _ = simulated_station(default_bench_settings(), settle_time=0.0)
    try:
        with pytest.raises(InputFileError, match=rf"{path}: in use by another tactile process \(pid {os.getpid()}\)"):
            q_campaign(other, path, SMALL, fsync=False)
    finally:
        release.set()
        first.join(20)
    assert outcome["first"].measured == 14
    keys = row_keys(path)
    assert len(keys) == 14 and len(set(keys)) == 14
    assert not (tmp_path / "c.csv.lock").exists()


def test_cli_refuses_a_log_held_by_another_process_naming_it(tmp_path):
    path = tmp_path / "c.csv"
    with LogWriter(path, {"procedure": "campaign"}):
        result = subprocess.run([*TACTILE, "measure", "campaign", "--simulate",
                                 "--points", "5", "--voltages", "5", "--out", str(path)],
                                capture_output=True, text=True, timeout=120)
        assert (tmp_path / "c.csv.lock").read_text().strip() == str(os.getpid())
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and f"pid {os.getpid()}" in result.stderr and str(path) in result.stderr
    assert not (tmp_path / "c-resonance.csv").exists()


def test_a_stale_lock_file_from_a_dead_process_is_taken_over(tmp_path):
    path = tmp_path / "c.csv"
    (tmp_path / "c.csv.lock").write_text("999999999\n")
    station, _ = simulated_station(default_bench_settings(), settle_time=0.0)
    assert q_campaign(station, path, SMALL, fsync=False).measured == 14
    assert not (tmp_path / "c.csv.lock").exists()


# item 4: a file the command did not create is never overwritten

FOREIGN = {
    "no trailing newline": b"frequency_hz,drive_voltage_v,velocity_m_s",
    "only comment lines": b"# my notes\n# do not delete\n",
    "binary": bytes(range(256)) * 4,
    "someone else's csv": b"a,b,c\n1,2,3\n",
}


@pytest.mark.parametrize("restart", [False, True])
@pytest.mark.parametrize("name", list(FOREIGN))
def test_a_file_this_tool_did_not_write_is_left_untouched(tmp_path, capsys, name, restart):
    path = tmp_path / "x.csv"
    path.write_bytes(FOREIGN[name])
    argv = ["measure", "voltage-sweep", "--simulate", "--voltages", "1,2", "--frequency-hz", "32000", "--out", str(path)]
    code, _, err = run_cli(capsys, *argv, *(["--restart"] if restart else []))
    assert code == 2 and err.count("\n") == 1 and "not a log tactile wrote" in err and str(path) in err
    assert path.read_bytes() == FOREIGN[name]


@pytest.mark.parametrize("target", ["/dev/full", "/dev/null", "fifo", "directory"])
def test_a_non_regular_output_is_refused_up_front(tmp_path, capsys, target):
    if target == "fifo":
        target = tmp_path / "f"
        os.mkfifo(target)
    elif target == "directory":
        target = tmp_path / "d"
        target.mkdir()
    if not os.path.exists(target):
        pytest.skip(f"{target} missing")
    code, _, err = run_cli(capsys, "measure", "campaign", "--simulate", "--out", str(target))
    assert code == 2 and err.count("\n") == 1 and "not a regular file" in err
    assert not os.path.exists(f"{target}.lock")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes read-only files")
def test_a_read_only_log_is_one_line_and_unchanged(tmp_path, capsys):
    path = tmp_path / "v.csv"
    argv = ["measure", "voltage-sweep", "--simulate", "--voltages", "1,2", "--frequency-hz", "32000", "--out", str(path)]
    assert run_cli(capsys, *argv)[0] == 0
    cut = path.read_bytes()[:-5]
    path.write_bytes(cut)
    path.chmod(0o444)
    code, _, err = run_cli(capsys, *argv)
    assert code == 2 and err.count("\n") == 1 and "not writable" in err
    assert path.read_bytes() == cut


# item 5: a refused setting is never logged as measured

def test_a_frequency_the_generator_refuses_stops_the_run_before_logging_it(tmp_path):
    """Points past the generator's 20 MHz (a fine sweep may cross the edge of a valid coarse plan)."""
    path = tmp_path / "r.csv"
    station, bench = simulated_station(default_bench_settings(), settle_time=0.0)
    station.prepare()
    points = [PlannedPoint(0, f, 1.0) for f in (19_999_900.0, 20_000_100.0, 20_000_300.0)]
    with LogWriter(path, {"procedure": "resonance"}, fsync=False) as log:
        with pytest.raises(InstrumentError, match=r"-222,Data out of range after setting 20000100 Hz; that point is not logged"):
            _measure_points(station, log, points, "resonance")
    assert row_keys(path) == [("0", "19999900", "1")]


def test_plans_outside_the_generator_frequency_range_are_refused_up_front(tmp_path, capsys):
    path = tmp_path / "c.csv"
    code, _, err = run_cli(capsys, "measure", "campaign", "--simulate", "--center-hz", "19999500", "--span-hz",
                           "2000", "--out", str(path))
    assert code == 2 and err.count("\n") == 1 and "20000500 Hz" in err and "20000000 Hz" in err
    assert not path.exists()


# item 7: unbounded sizes

@pytest.mark.parametrize(
    "argv, message",
    [
        (["campaign", "--points", "1000000000"], "--points 1000000000 exceeds the limit of 10000 points per sweep"),
        (["resonance", "--coarse-points", "1000000000"], "--coarse-points 1000000000 exceeds the limit"),
        (["resonance", "--fine-points", "20000"], "--fine-points 20000 exceeds the limit"),
        (["campaign", "--points", "9000", "--voltages", ",".join(["5"] * 30)], "270000 points exceed the limit of 100000"),
        (["voltage-sweep", "--frequency-hz", "32000", "--voltages", ",".join(["5"] * 200000)], "--voltages: 200000 points exceed the limit of 100000"),
    ],
)
def test_cli_refuses_oversized_plans_up_front(tmp_path, capsys, argv, message):
    code, _, err = run_cli(capsys, "measure", *argv, "--simulate", "--out", str(tmp_path / "x.csv"))
    assert code == 2 and message in err and err.count("\n") == 1
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize(
    "campaign, message",
    [
        ({"points_per_sweep": 1000000000}, "'campaign.points_per_sweep' = 1000000000 is outside the accepted range 3 to 10000"),
        ({"points_per_sweep": 2}, "'campaign.points_per_sweep' = 2 is outside the accepted range 3 to 10000"),
        ({"points_per_sweep": 9000, "voltages_v": [5.0] * 30}, "270000 points exceed the limit of 100000"),
    ],
)
def test_config_refuses_oversized_campaigns(campaign, message):
    with pytest.raises(InputFileError, match=message):
        merge(default_config(), {"campaign": campaign}, source="run.toml")


def test_plans_refuse_oversized_sizes_and_frequencies_from_python():
    with pytest.raises(TactileError, match="points_per_sweep 1000000000 exceeds the limit"):
        CampaignPlan(32e3, points_per_sweep=10**9)
    with pytest.raises(TactileError, match="30000000 Hz is outside the generator's range"):
        VoltageSweepPlan(30e6)
