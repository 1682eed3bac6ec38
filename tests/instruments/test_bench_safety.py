"""Bench safety (issue 19, items 1 and 2): the output is off after every kind of exit, and the
generator driver's limit holds whatever state the instrument was left in."""

import json
import math
import random
import signal
import subprocess
import time
from dataclasses import replace

import pytest
import serial
from ports import DevicePort
from user_facing import TACTILE

from instruments.drivers.errors import SafetyLimitError
from instruments.drivers.generator import LOWEST_AMPLITUDE_VPP, FunctionGenerator
from instruments.procedures.sweeps import Station
from instruments.simulator.generator import FUNCTIONS, GeneratorDevice, GeneratorState
from workflow.cli import main

DRIVER_LIMIT = 3.0
"""The driver's limit in these tests [V peak at the generator output]."""
DEVICE_LIMIT = 9.0
"""The simulated generator's own limit, well above the driver's, so that only the driver stands in the way [V]."""


# --- item 1: output off on every exit, through the pseudo-terminals -------------------------------

@pytest.fixture
def pty_bench():
    """The simulator serving on pseudo-terminals: {"generator": path, "vibrometer": path}."""
    process = subprocess.Popen(TACTILE + ["simulate", "--pty"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield json.loads(process.stdout.readline())
    finally:
        process.terminate()
        process.wait(timeout=10)


def ask(port: str, *commands: str) -> list[str]:
    """Send ``commands`` to the generator on ``port``; the replies of those ending in ``?``."""
    with serial.Serial(port, timeout=5) as link:
        replies = []
        for command in commands:
            link.write(command.encode() + b"\n")
            if command.endswith("?"):
                replies.append(link.readline().decode().strip())
        return replies


def logged_velocities(path) -> list[float]:
    """The velocity column of a log being written [m/s] (complete rows only)."""
    from workflow.damping.logs import read_logs

    lines = path.read_text().splitlines(keepends=True)
    complete = path.with_name("complete-" + path.name)
    complete.write_text("".join(line for line in lines if line.endswith("\n")))
    return [float(v) for v in read_logs([complete]).velocity]


def assert_safe_state(port: str) -> None:
    output, unit, amplitude, offset = ask(port, "OUTP?", "VOLT:UNIT?", "VOLT?", "VOLT:OFFS?")
    assert output == "0"
    assert unit == "VPP" and float(amplitude) == pytest.approx(LOWEST_AMPLITUDE_VPP)
    assert float(offset) == 0.0


def campaign(ports: dict, out, *extra: str) -> list[str]:
    return TACTILE + ["measure", "campaign", "--generator", ports["generator"], "--vibrometer", ports["vibrometer"],
                      "--lockin", ports["lockin"], "--center-hz", "31000", "--time-constant", "0.001", "--out", str(out), *extra]


def data_rows(path) -> int:
    if not path.exists():
        return 0
    return sum(1 for line in path.read_text().splitlines() if line and not line.startswith("#")) - 1


@pytest.mark.parametrize("signum", [signal.SIGTERM,
                                    pytest.param(signal.SIGHUP, marks=pytest.mark.slow),  # one handler for the three:
                                    pytest.param(signal.SIGINT, marks=pytest.mark.slow)],  # SIGTERM by default
                         ids=lambda s: signal.Signals(s).name)
def test_a_stop_signal_mid_campaign_leaves_the_output_off_at_the_lowest_amplitude(pty_bench, tmp_path, signum):
    out = tmp_path / "c.csv"
    process = subprocess.Popen(campaign(pty_bench, out, "--points", "200"), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while data_rows(out) < 2 and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert process.poll() is None, process.stderr.read()
    # driving the plate when the signal comes: the logged points moved it.  (Not asked over the
    # generator's port: a second client on the pty would take the campaign's replies, and it its.)
    assert max(logged_velocities(out)) > 0
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=30)
    name = signal.Signals(signum).name
    assert process.returncode == 128 + signum
    assert stderr.strip().splitlines()[-1] == f"tactile measure: stopped by {name}; generator output off (OUTP 0, lowest amplitude)"
    assert_safe_state(pty_bench["generator"])
    assert data_rows(out) >= 2  # the rows measured before the signal are kept for a resume


def test_a_normal_end_leaves_the_output_off_at_the_lowest_amplitude(pty_bench, tmp_path):
    done = subprocess.run(campaign(pty_bench, tmp_path / "c.csv", "--points", "3", "--voltages", "2.5,5"),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert_safe_state(pty_bench["generator"])


def test_an_instrument_error_leaves_the_output_off_at_the_lowest_amplitude(pty_bench, tmp_path):
    # the generator was left on by someone; the lock-in does not speak its protocol (a loopback)
    ask(pty_bench["generator"], "VOLT 1", "OUTP 1")
    ports = {**pty_bench, "lockin": "loop://"}
    done = subprocess.run(campaign(ports, tmp_path / "c.csv", "--retries", "0", "--timeout", "0.2"),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "error" in done.stderr
    assert_safe_state(pty_bench["generator"])


def test_a_refused_voltage_leaves_an_instrument_left_on_switched_off(pty_bench, tmp_path):
    ask(pty_bench["generator"], "VOLT 1", "OUTP 1")
    done = subprocess.run(campaign(pty_bench, tmp_path / "c.csv", "--voltages", "40"),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "safety limit 30 V" in done.stderr
    assert_safe_state(pty_bench["generator"])


# --- item 2: the driver's limit from the instrument's real state ----------------------------------

def generator_left_in(**state) -> tuple[FunctionGenerator, GeneratorDevice]:
    """A driver on a simulated generator left in ``state`` (High Z load unless given)."""
    device = GeneratorDevice(DEVICE_LIMIT)
    device.state = GeneratorState(**{"load": math.inf, **state})
    return FunctionGenerator(DevicePort(device), max_peak_voltage=DRIVER_LIMIT), device


def test_offset_check_reads_the_amplitude_in_vpp_when_the_instrument_is_left_in_vrms():
    device = GeneratorDevice(DEVICE_LIMIT)
    for line in ("OUTP:LOAD INF", "VOLT:UNIT VRMS", "VOLT 2"):
        device.handle_line(line)
    generator = FunctionGenerator(DevicePort(device), max_peak_voltage=3.0)
    with pytest.raises(SafetyLimitError, match="output peak 3.328"):
        generator.offset = 0.5
    assert device.state.offset == 0.0 and device.state.peak_voltage < 3.0
    assert generator.amplitude_vpp == pytest.approx(5.657, abs=1e-3)
    assert device.errors == []


def test_raw_level_commands_cannot_go_around_the_properties():
    generator, device = generator_left_in(amplitude_vpp=1.0)
    for command in ("VOLT 8", "VOLT:UNIT VPP;:VOLT 8", "SOUR1:VOLT:OFFS 4", "VOLT:UNIT VRMS;OFFS 4", "APPL:SIN 1000,8,0",
                    "VOLT:HIGH 5", "FREQ 1000\nVOLT 8", "volt:ampl 8"):
        for send in (generator.set, generator.write, generator.query):
            with pytest.raises(SafetyLimitError, match="levels are set through"):
                send(command)
    assert device.state.amplitude_vpp == 1.0 and device.state.offset == 0.0 and device.errors == []
    generator.set("FREQ 31000")
    generator.set("VOLT:UNIT VRMS")  # renames the amplitude, changes nothing at the output
    assert device.state.frequency == 31000 and device.state.unit == "VRMS"


@pytest.mark.parametrize("function", FUNCTIONS)
@pytest.mark.parametrize("sign", [1, -1], ids=["positive offset", "negative offset"])
@pytest.mark.parametrize("unit", ["VPP", "VRMS"])
def test_no_sequence_of_driver_commands_exceeds_the_limit(unit, sign, function):
    """Random settings through the driver, the unit switched behind its back before each: the true peak stays within the limit."""
    generator, device = generator_left_in(function=function, unit=unit, amplitude_vpp=2.0, offset=sign * 0.5)
    rng = random.Random(f"{unit}{sign}{function}")
    accepted = refused = 0
    loads_seen = set()
    for _ in range(150):
        # the front panel, or another program, changes the unit and the load setting (within the limit)
        device.state = replace(device.state, unit=rng.choice(["VPP", "VRMS"]))
        other_load = replace(device.state, load=rng.choice([math.inf, 50.0, 1000.0]))
        if other_load.peak_voltage <= DRIVER_LIMIT:
            device.state = other_load
        true_vpp = device.state.amplitude_vpp
        assert generator.amplitude_vpp == pytest.approx(true_vpp)
        loads_seen.add(device.state.load)
        action = rng.choice(["amplitude", "offset", "function", "raw"])
        try:
            if action == "amplitude":
                generator.amplitude_vpp = rng.uniform(0.01, 9.0)
            elif action == "offset":
                generator.offset = sign * rng.uniform(0.0, 4.0)
            elif action == "function":
                generator.function = rng.choice(FUNCTIONS)
            else:
                generator.set(f"VOLT {rng.uniform(0.01, 9.0):.3f}")
            accepted += 1
        except SafetyLimitError:
            refused += 1
        assert device.state.peak_voltage <= DRIVER_LIMIT + 1e-9
        assert device.errors == []  # the simulator's own limit was never needed
    assert accepted > 20 and refused > 20  # both sides of the limit were exercised
    assert loads_seen >= {math.inf, 50.0}  # the limit was decided under more than one load setting
    assert generator.amplitude_unit in ("VPP", "VRMS")


def test_the_driver_accepts_settings_up_to_the_limit_in_either_unit():
    for unit in ("VPP", "VRMS"):
        generator, device = generator_left_in(unit=unit, amplitude_vpp=2.0)
        generator.offset = -(DRIVER_LIMIT - 1.0)
        generator.amplitude_vpp = 2.0
        assert device.state.peak_voltage == pytest.approx(DRIVER_LIMIT)
        assert device.state.unit == "VPP"


def test_the_simulator_has_no_dbm_unit_to_test():
    device = GeneratorDevice(DEVICE_LIMIT)
    device.handle_line("VOLT:UNIT DBM")
    assert device.state.unit == "VPP" and device.errors[0].startswith("-224")


@pytest.mark.parametrize("limit", [float("inf"), float("nan"), 0.0, -1.0])
def test_a_limit_that_is_not_a_finite_positive_number_is_refused(limit):
    with pytest.raises(ValueError, match="finite number of volts > 0"):
        FunctionGenerator(DevicePort(GeneratorDevice(DEVICE_LIMIT)), max_peak_voltage=limit)
    with pytest.raises(ValueError, match="finite number of volts > 0"):
        Station(None, None, None, None, voltage_limit=limit)


def _exit_status(argv) -> int:
    """``tactile ARGV``'s exit status, in process (argparse exits on a bad option)."""
    try:
        return main(argv)
    except SystemExit as exit_:
        return exit_.code


@pytest.mark.parametrize("text", ["inf", "nan", "0", "-5", "1e6"])
def test_max_voltage_inf_nan_or_not_positive_is_one_line_naming_the_option(text, tmp_path, capsys):
    status = _exit_status(["measure", "resonance", "--simulate", "--max-voltage", text, "--out", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.strip().splitlines()) == 1
    assert f"argument --max-voltage: {text} is outside the accepted range 0.001 to 1000 V" in err
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("text", ["inf", "nan", "0", "0.01"])
def test_an_amplifier_gain_that_would_zero_or_void_the_generator_limit_is_refused(text, tmp_path, capsys):
    status = _exit_status(["measure", "resonance", "--simulate", "--amplifier-gain", text, "--out", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err
    assert status == 2 and f"argument --amplifier-gain: {text} is outside the accepted range 0.1 to 1000" in err
    assert len(err.strip().splitlines()) == 1


def test_the_limit_cannot_be_raised_on_an_open_driver():
    generator, _ = generator_left_in()
    with pytest.raises(AttributeError):
        generator.max_peak_voltage = float("inf")
