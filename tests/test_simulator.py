"""The bench simulator: SCPI forms, the safety limit in the instrument, the physics, faults, transports."""

import json
import subprocess

import numpy as np
import pytest
import serial
from user_facing import TACTILE

from instruments.simulator import (
    Bench,
    FaultSettings,
    bench_url,
    default_bench_settings,
    register_bench,
    register_url_handler,
)
from instruments.simulator.generator import GeneratorDevice
from instruments.simulator.physics import DEFAULT_LOW_VELOCITY_Q, plate_response, working_point_velocity
from workflow.models import analytical
from workflow.models.materials import DESIGN_VOLTAGE, PLATE_Q
from workflow.models.plate import ORIGINAL_PLATE


def open_bench(**changes):
    register_url_handler()
    bench = Bench(default_bench_settings(**changes))
    name = register_bench(bench)
    ports = [serial.serial_for_url(bench_url(name, i), timeout=1) for i in ("generator", "vibrometer")]
    return bench, *ports


@pytest.mark.parametrize(
    "line",
    ["FREQ 31000", "freq 31000", ":FREQ 31000", "SOUR1:FREQ 31000", ":SOURce1:FREQuency 31000",
     "SOURCE:FREQUENCY:CW 3.1E+04", "frequency 31000.000000"],
)
def test_generator_accepts_short_long_case_and_prefix_forms(line):
    generator = GeneratorDevice(peak_voltage_limit=5.0)
    assert generator.handle_line(line) is None
    assert generator.state.frequency == 31000.0
    assert generator.handle_line("SYST:ERR?") == '+0,"No error"'


def test_generator_program_lines_with_semicolons_and_unknown_headers():
    generator = GeneratorDevice(peak_voltage_limit=5.0)
    assert generator.handle_line("VOLT:UNIT VPP;:VOLT 2;:OUTP1 ON;*IDN?;:VOLT?").endswith(";+2.00000000000000E+00")
    assert generator.state.output
    generator.handle_line("VOLT:UNIT VRMS")
    assert float(generator.handle_line("VOLT?")) == pytest.approx(2 / (2 * np.sqrt(2)))
    generator.handle_line("SOUR2:FREQ 10")
    generator.handle_line("BLAH 3")
    assert generator.handle_line("SYST:ERR?").startswith("-114")
    assert generator.handle_line("SYST:ERR?").startswith("-113")


@pytest.mark.parametrize("line, error", [
    ("*RST?", "-113"), ("*CLS?", "-113"), ("*IDN", "-113"), ("SYST:ERR", "-113"),
    ("*RST 1", "-108"), ("FREQ? 1000", "-108"), ("FREQ", "-109"),
])
def test_a_header_in_a_form_it_does_not_have_is_an_error_and_changes_nothing(line, error):
    """As a 33500: a query form of a command that has none (``*RST?``) is an undefined header, not a reset."""
    generator = GeneratorDevice(peak_voltage_limit=5.0)
    generator.handle_line("FREQ 31000;:VOLT 2;:OUTP ON")
    before = generator.state
    assert generator.handle_line(line) is None
    assert generator.state == before
    assert generator.handle_line("SYST:ERR?").startswith(error + ",")
    assert generator.handle_line("SYST:ERR?") == '+0,"No error"'


def test_simulated_generator_refuses_beyond_its_limit_and_keeps_the_previous_output():
    generator = GeneratorDevice(peak_voltage_limit=1.5)  # 30 V across the ceramics through a gain of 20
    generator.handle_line("OUTP:LOAD INF")  # High Z: the stated levels are the terminal levels
    generator.handle_line("VOLT 2.0")
    generator.handle_line("VOLT 3.2")
    assert generator.state.amplitude_vpp == 2.0
    assert generator.handle_line("SYST:ERR?") == '-222,"Data out of range"'
    generator.handle_line("VOLT:OFFS 0.6")  # 1.0 + 0.6 > 1.5
    assert generator.state.offset == 0.0
    generator.handle_line("VOLT:UNIT VRMS;:VOLT 1.1")  # 3.1 Vpp
    assert generator.state.amplitude_vpp == 2.0
    assert generator.handle_line("SYST:ERR?").startswith("-222")


def test_the_simulated_load_setting_doubles_the_terminal_voltage_at_50_ohm():
    """As a 33500: levels are stated into the load setting (50 ohm after *RST); an amplifier's
    high-impedance input sees (R + 50) / R times them, and the limit holds on what it sees."""
    generator = GeneratorDevice(peak_voltage_limit=1.5)
    assert float(generator.handle_line("OUTP:LOAD?")) == 50.0
    generator.handle_line("VOLT 1.4")  # 2.8 Vpp at the terminals: peak 1.4 V
    assert generator.state.terminal_amplitude_vpp == pytest.approx(2.8)
    generator.handle_line("VOLT 2.0")  # peak 2 V at the terminals: refused
    assert generator.state.amplitude_vpp == 1.4 and generator.handle_line("SYST:ERR?").startswith("-222")
    generator.handle_line("OUTP:LOAD 25")  # x3: refused, the output keeps its load
    assert generator.state.load == 50.0 and generator.handle_line("SYST:ERR?").startswith("-222")
    generator.handle_line("OUTP:LOAD INF")
    assert float(generator.handle_line("OUTP:LOAD?")) > 1e37 and generator.state.terminal_amplitude_vpp == 1.4
    generator.handle_line("*RST")
    assert generator.state.load == 50.0


def test_default_law_gives_q54_at_the_working_point_and_more_at_low_velocity():
    response = plate_response()
    assert response.resonance_frequency == pytest.approx(float(analytical.resonance_frequency(ORIGINAL_PLATE)))
    v_work = working_point_velocity()
    assert 0.2 < v_work < 0.23
    velocity, phase = response.velocity(response.resonance_frequency, DESIGN_VOLTAGE)
    assert velocity == pytest.approx(v_work, rel=1e-8)  # self-consistent at resonance
    assert response.law.quality_factor(velocity) == pytest.approx(PLATE_Q, rel=1e-6)
    assert phase == pytest.approx(0.0, abs=1e-6)
    assert response.law.quality_factor(0.01) > 140


def test_resonance_curve_peak_and_half_power_bandwidth_at_low_drive():
    response = plate_response()
    f_r = response.resonance_frequency
    frequency = np.linspace(f_r - 800, f_r + 800, 16001)
    velocity, _ = response.velocity(frequency, 0.01)  # v ~ 1e-4 m/s: Q = Q0
    assert frequency[np.argmax(velocity)] == pytest.approx(f_r, abs=0.2)
    above = frequency[velocity >= velocity.max() / np.sqrt(2)]
    assert f_r / (above[-1] - above[0]) == pytest.approx(DEFAULT_LOW_VELOCITY_Q, rel=0.01)
    # at 15 V the curve is flattened: its apparent Q is at most the working-point Q
    velocity_15, _ = response.velocity(frequency, DESIGN_VOLTAGE)
    above = frequency[velocity_15 >= velocity_15.max() / np.sqrt(2)]
    assert f_r / (above[-1] - above[0]) < PLATE_Q + 1


def test_simulated_instruments_measure_the_model_with_drift_and_noise():
    bench, generator, vibrometer = open_bench(relative_noise=0.0, floor_fraction=0.0, phase_noise=0.0)
    f_r = bench.settings.response.resonance_frequency
    generator.write(f"OUTP:LOAD INF;:FREQ {f_r};:VOLT 3;:OUTP 1\nSet,VeloDec,1,Range,50mm/s/V\n".encode())
    vibrometer.write(b"Set,VeloDec,1,Range,50mm/s/V\n")
    assert vibrometer.readline() == b"50mm/s/V\n"
    vibrometer.write(b"Get,LockIn,0,Velocity\n")
    amplitude, phase, status = vibrometer.readline().decode().strip().split(",")
    expected, _ = bench.settings.response.velocity(f_r, 15.0, bench.time)
    assert float(amplitude) == pytest.approx(expected, rel=1e-6) and status == "OK"
    assert bench.time == bench.settings.measurement_time
    assert bench.settings.response.resonance_at(100.0) < f_r  # the plate warms: f_r drifts down


def test_over_range_is_reported_not_clipped_silently():
    bench, generator, vibrometer = open_bench()
    generator.write(f"OUTP:LOAD INF;:FREQ {bench.settings.response.resonance_frequency};:VOLT 3;:OUTP 1\n".encode())
    vibrometer.write(b"Set,VeloDec,1,Range,1mm/s/V\nGet,LockIn,0,Velocity\n")
    vibrometer.readline()
    amplitude, _, status = vibrometer.readline().decode().strip().split(",")
    assert status == "OVER" and float(amplitude) == pytest.approx(0.01)


def idn_replies(generator, count):
    replies = []
    for _ in range(count):
        generator.write(b"*IDN?\n")
        replies.append(generator.read_until(b"\n"))
    return replies


def test_faults_are_seeded_and_disconnect_once():
    faults = FaultSettings(drop_rate=0.3, garble_rate=0.3, disconnect_at=50, seed=4)
    bench, generator, _ = open_bench(faults=faults)
    replies = idn_replies(generator, 49)
    assert replies == idn_replies(open_bench(faults=faults)[1], 49)
    assert b"" in replies and any(not set(r.strip()) <= set(range(32, 127)) for r in replies)
    with pytest.raises(serial.SerialException, match="disconnected"):
        generator.write(b"*IDN?\n")
    with pytest.raises(serial.SerialException):
        generator.read(1)
    again = serial.serial_for_url(generator.port, timeout=1)  # reconnect: the fault fired once
    for _ in range(20):
        again.write(b"*CLS\n")
    assert bench.faults.commands == 70


def test_pymeasure_agilent33500_client_drives_the_simulator_unchanged():
    pymeasure = pytest.importorskip("pymeasure")
    from pymeasure.adapters import SerialAdapter
    from pymeasure.instruments.agilent import Agilent33500

    bench, port, _ = open_bench()
    client = Agilent33500(SerialAdapter(port, write_termination="\n", read_termination="\n"))
    assert "33521A" in client.id
    client.shape = "SIN"
    client.frequency = 32100.25
    client.amplitude_unit = "VPP"
    client.amplitude = 2.0
    client.offset = 0.0
    client.output = True
    assert (client.shape, client.frequency, client.amplitude, client.output) == ("SIN", 32100.25, 2.0, True)
    client.ch_1.frequency = 32000
    client.ch_1.output = False
    assert client.ch_1.frequency == 32000 and client.ch_1.output is False
    assert client.check_errors() == []
    client.amplitude = 8.0  # 40 V across the ceramics: over the bench's 30 V limit
    assert client.amplitude == 2.0
    assert bench.ceramic_voltage() == 0.0  # output was off; the refused value never applied
    errors = client.check_errors()
    assert errors and int(errors[0][0]) == -222
    assert pymeasure.__version__


def test_pty_server_end_to_end():
    process = subprocess.Popen(
        [*TACTILE, "simulate", "--pty"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        ports = json.loads(process.stdout.readline())
        assert set(ports) == {"generator", "vibrometer"}
        how_to_stop = process.stderr.readline()
        assert "Ctrl-C" in how_to_stop and f"kill {process.pid}" in how_to_stop and ports["generator"] in how_to_stop
        generator = serial.Serial(ports["generator"], timeout=5)
        vibrometer = serial.Serial(ports["vibrometer"], timeout=5)
        generator.write(b"*IDN?\n")
        assert b"33521A" in generator.readline()
        generator.write(b"FREQ 32126\nVOLT 40\nSYST:ERR?\n")  # 200 V: refused
        assert generator.readline().startswith(b"-222")
        generator.write(b"OUTP:LOAD INF\nVOLT 3\nOUTP ON\n")
        vibrometer.write(b"Set,VeloDec,1,Range,50mm/s/V\nGet,LockIn,0,Velocity\n")
        assert vibrometer.readline() == b"50mm/s/V\n"
        amplitude, _, status = vibrometer.readline().decode().strip().split(",")
        assert 0.19 < float(amplitude) < 0.24 and status == "OK"
        pymeasure = pytest.importorskip("pymeasure.instruments.agilent")
        from pymeasure.adapters import SerialAdapter

        client = pymeasure.Agilent33500(SerialAdapter(generator, write_termination="\n", read_termination="\n"))
        client.ch_1.frequency = 31500.5
        assert client.frequency == 31500.5 and client.output is True
        generator.close()
        vibrometer.close()
    finally:
        process.terminate()
        assert process.wait(timeout=10) == 0
