"""The interferometer-log reader: valid logs, tolerated problems and refused input."""

import os

import numpy as np
import pytest

from workflow.damping.logs import drop_short_sweeps, read_log, read_logs
from workflow.damping.synthetic import campaign_csv, simulate_campaign
from workflow.errors import InputFileError

HEADER = "frequency_hz,drive_voltage_v,velocity_m_s\n"


def write(tmp_path, text, name="log.csv"):
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return path


def test_round_trip_of_a_synthetic_campaign(tmp_path):
    log = simulate_campaign(points_per_sweep=11, seed=2)
    read = read_log(write(tmp_path, campaign_csv(log)))
    assert read.n_sweeps == log.n_sweeps
    assert np.allclose(read.frequency, log.frequency, rtol=1e-9)
    assert np.allclose(read.velocity, log.velocity, rtol=1e-7)
    assert read.warnings == ()


def test_sweeps_follow_voltage_changes_without_a_sweep_column(tmp_path):
    rows = "".join(f"{f},{v},0.1\n" for v in (5, 10, 5) for f in (31000, 31100))
    log = read_log(write(tmp_path, "# title\n# key: value\n" + HEADER + rows))
    assert list(log.sweep) == [0, 0, 1, 1, 2, 2]
    assert np.allclose(log.sweep_voltages(), [5, 10, 5])


def test_several_logs_get_distinct_sweeps(tmp_path):
    a = write(tmp_path, HEADER + "31000,5,0.1\n31100,5,0.1\n", "a.csv")
    b = write(tmp_path, HEADER + "31000,5,0.1\n", "b.csv")
    log = read_logs([a, b])
    assert list(log.sweep) == [0, 0, 1]
    assert log.sources == (str(a), str(b))


def test_dropouts_are_dropped_and_counted(tmp_path):
    text = HEADER + "31000,5,0.1\n31100,5,\n31200,5,nan\n31300,5,0.2\n"
    log = read_log(write(tmp_path, text))
    assert len(log.velocity) == 2
    assert len(log.warnings) == 1 and "dropped 2 row(s)" in log.warnings[0]


def test_an_incomplete_last_line_is_ignored_with_a_warning(tmp_path):
    log = read_log(write(tmp_path, HEADER + "31000,5,0.1\n31100,5,0.2\n31200,5"))
    assert len(log.velocity) == 2
    assert "line 4" in log.warnings[0] and "incomplete" in log.warnings[0]


def test_other_columns_and_crlf_are_accepted(tmp_path):
    text = "note,frequency_hz,velocity_m_s,drive_voltage_v,phase_deg\r\nx,31000,0.1,5,12\r\n"
    log = read_log(write(tmp_path, text))
    assert log.frequency[0] == 31000 and log.drive_voltage[0] == 5 and log.velocity[0] == 0.1


BAD = {
    "empty": ("", "empty file"),
    "header only": (HEADER, "header only"),
    "missing column": ("frequency_hz,drive_voltage_v\n31000,5\n", "missing required column 'velocity_m_s'"),
    "unknown unit": ("frequency_khz,drive_voltage_v,velocity_m_s\n31,5,0.1\n", "unknown unit"),
    "ambiguous": ("frequency_hz,frequency_hz,drive_voltage_v,velocity_m_s\n1,1,5,0.1\n", "ambiguous"),
    "non-numeric": (HEADER + "31000,5,0.1\n31100,five,0.1\n", "line 3: non-numeric value 'five'"),
    "negative frequency": (HEADER + "31000,5,0.1\n-31100,5,0.1\n", "line 3: frequency_hz = -31100"),
    "wrong field count": (HEADER + "31000,5,0.1,7\n", "line 2: expected 3 fields, got 4"),
    "missing frequency": (HEADER + ",5,0.1\n", "line 2: missing value in column 'frequency_hz'"),
    "binary": (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "binary"),
    "not utf-8": (HEADER.encode() + b"31000,5,0.1\n31100,5,0.\xe90\n", "line 3: not UTF-8"),
    "all dropouts": (HEADER + "31000,5,nan\n", "no data row has a velocity"),
}


@pytest.mark.parametrize("text, message", BAD.values(), ids=BAD.keys())
def test_bad_logs_raise_an_error_naming_the_file(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(InputFileError) as error:
        read_log(path)
    assert str(path) in str(error.value)
    assert message in str(error.value)


def test_a_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputFileError, match="cannot read"):
        read_log(tmp_path / "nope.csv")


def test_reading_never_modifies_the_file(tmp_path):
    path = write(tmp_path, HEADER + "31000,5,0.1\n31100,5,nan\n31200,5")
    before = (path.read_bytes(), os.stat(path).st_mtime_ns)
    read_log(path)
    assert (path.read_bytes(), os.stat(path).st_mtime_ns) == before


def test_short_sweeps_are_dropped_with_a_warning(tmp_path):
    rows = "".join(f"{31000 + 10 * i},5,0.1\n" for i in range(6)) + "31000,10,0.2\n31010,10,0.2\n"
    log = drop_short_sweeps(read_log(write(tmp_path, HEADER + rows)))
    assert log.n_sweeps == 1 and len(log.velocity) == 6
    assert "ignored 1 sweep(s)" in log.warnings[-1]
    with pytest.raises(InputFileError, match="no sweep has 5"):
        drop_short_sweeps(read_log(write(tmp_path, HEADER + "31000,5,0.1\n", "short.csv")))
