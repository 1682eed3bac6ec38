"""The bench simulator: SCPI forms, the safety limit in the instrument, the physics, faults, transports."""

import json
import subprocess
import threading
import time

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
from instruments.drivers.lockin import OVERLOAD_INPUT, OVERLOAD_OUTPUT, OVERLOAD_UNLOCKED, settle_time
from instruments.simulator.bench import INSTRUMENTS
from instruments.simulator.generator import GeneratorDevice
from instruments.simulator.vibrometer import DECODER_DELAY
from instruments.simulator.physics import DEFAULT_LOW_VELOCITY_Q, plate_response, working_point_velocity
from workflow.models import analytical
from workflow.models.materials import DESIGN_VOLTAGE, PLATE_Q
from workflow.models.plate import ORIGINAL_PLATE


def open_bench(**changes):
    register_url_handler()
    bench = Bench(default_bench_settings(**changes))
    name = register_bench(bench)
    ports = [serial.serial_for_url(bench_url(name, i), timeout=1) for i in INSTRUMENTS]
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


def ask(port, line: str) -> str:
    port.write(line.encode() + b"\n")
    return port.readline().decode().strip()


def test_the_lockin_reads_the_decoder_output_once_settled_and_not_before():
    """The chain: velocity at the spot -> decoder (velocity / range, delayed) -> lock-in R [V rms] and theta; a reading
    right after a step is not settled, one after the settling time of its time constant and slope is."""
    bench, generator, vibrometer, lockin = open_bench(relative_noise=0.0, floor_fraction=0.0, phase_noise=0.0,
                                                     heating=False)
    f_r = bench.settings.response.resonance_frequency
    vibrometer.write(b"Set,VeloDec,1,Range,500mm/s/V\n")
    assert ask(vibrometer, "Get,VeloDec,1,Range") == "500mm/s/V"
    lockin.write(b"RSRC 1;RTRG 1;OFLT 9;OFSL 3;IRNG 0;SCAL 0\n")  # 30 ms, 24 dB/oct
    generator.write(f"OUTP:LOAD INF;:FREQ {f_r};:VOLT 3;:OUTP 1\n".encode())
    early = float(ask(lockin, "OUTP? 2"))
    velocity, phase = bench.settings.response.velocity(f_r, 15.0, bench.time)
    expected = velocity / 0.5 / np.sqrt(2)
    assert early < 0.01 * expected  # the filter has barely moved
    bench.sleep(settle_time(0.03, 4) - 0.05)
    assert abs(float(ask(lockin, "OUTP? 2")) / expected - 1) > 2e-3  # still settling
    bench.sleep(0.05)
    magnitude, theta = (float(x) for x in ask(lockin, "SNAP? 2,3").split(","))
    assert magnitude == pytest.approx(expected, rel=2e-3)
    assert theta == pytest.approx(float(phase) - 360 * f_r * DECODER_DELAY, abs=0.2)
    assert ask(lockin, "CUROVLDSTAT?") == "0"


def test_overloads_are_reported_not_clipped_silently():
    """A decoder range too small drives the lock-in's input past its range: CUROVLDSTAT? bit 4 (and LIAS?, latched);
    R is what the clipped input gives, below the truth.  R past the sensitivity sets the output bits."""
    bench, generator, vibrometer, lockin = open_bench(relative_noise=0.0, floor_fraction=0.0, phase_noise=0.0)
    lockin.write(b"RSRC 1;OFLT 9;OFSL 3;SCAL 0\n")
    generator.write(f"OUTP:LOAD INF;:FREQ {bench.settings.response.resonance_frequency};:VOLT 3;:OUTP 1\n".encode())
    vibrometer.write(b"Set,VeloDec,1,Range,100mm/s/V\n")  # 0.216 m/s -> 2.2 V at the input: over its 1 V range
    bench.sleep(1.0)
    assert int(ask(lockin, "CUROVLDSTAT?")) & OVERLOAD_INPUT
    truth = bench.steady()[1] / 0.1 / np.sqrt(2)
    assert float(ask(lockin, "OUTP? 2")) < 0.6 * abs(truth)  # the clipped sine's fundamental: far from the truth
    vibrometer.write(b"Set,VeloDec,1,Range,500mm/s/V\n")
    bench.sleep(1.0)
    assert int(ask(lockin, "CUROVLDSTAT?")) == 0 and int(ask(lockin, "LIAS?")) & OVERLOAD_INPUT  # latched until read
    assert int(ask(lockin, "LIAS?")) == 0
    lockin.write(b"SCAL 6\n")  # 10 mV full scale, R ~ 0.3 V
    assert int(ask(lockin, "CUROVLDSTAT?")) & OVERLOAD_OUTPUT
    generator.write(b"BURS:STAT ON\n")  # a bursting generator's sync is no reference
    assert int(ask(lockin, "CUROVLDSTAT?")) & OVERLOAD_UNLOCKED


def test_the_lockin_refuses_what_it_does_not_know_in_its_status_register():
    bench, _, _, lockin = open_bench()
    lockin.write(b"OFLT 99;BOGUS 3\n")
    assert ask(lockin, "*ESR?") == str(1 << 4)  # execution error; the line stops at the bad command
    lockin.write(b"BOGUS 3\n")
    assert ask(lockin, "*ESR?") == str(1 << 5) and ask(lockin, "*ESR?") == "0"
    assert ask(lockin, "OFLT?") == "10"  # after power-on: 100 ms, untouched


def test_the_plate_warms_with_the_power_it_dissipates_and_its_resonance_falls():
    bench, generator, _, _ = open_bench(drift_rate=0.0)
    thermal = bench.settings.response.thermal
    f_r = bench.settings.response.resonance_frequency
    generator.write(f"OUTP:LOAD INF;:FREQ {f_r};:VOLT 3;:OUTP 1\n".encode())
    velocity, _ = bench.steady()
    power = thermal.dissipated_power(f_r, velocity, bench.settings.response.law.quality_factor(velocity))
    assert 4.0 < power < 4.7  # ~4.4 W at the working point
    bench.sleep(thermal.time_constant)
    generator.write(b"*OPC?\n")
    rise = bench.heating()
    assert 0.55 * power / thermal.conductance < rise < 0.65 * power / thermal.conductance  # 1 - 1/e, the drive detunes
    assert bench.resonance() == pytest.approx(f_r * (1 + thermal.frequency_coefficient * rise))
    assert bench.temperature() == pytest.approx(22.0 + rise)
    generator.write(b"OUTP 0\n")
    bench.sleep(5 * thermal.time_constant)
    generator.write(b"*OPC?\n")
    assert bench.heating() < 0.01 * rise  # cools to the ambient with the output off


def idn_replies(generator, count):
    replies = []
    for _ in range(count):
        generator.write(b"*IDN?\n")
        replies.append(generator.read_until(b"\n"))
    return replies


def test_faults_are_seeded_and_disconnect_once():
    faults = FaultSettings(drop_rate=0.3, garble_rate=0.3, disconnect_at=50, seed=4)
    bench, generator, _, _ = open_bench(faults=faults)
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

    bench, port, _, _ = open_bench()
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
        assert set(ports) == {"generator", "vibrometer", "lockin"}
        how_to_stop = process.stderr.readline()
        assert "Ctrl-C" in how_to_stop and f"kill {process.pid}" in how_to_stop and ports["generator"] in how_to_stop
        generator = serial.Serial(ports["generator"], timeout=5)
        vibrometer = serial.Serial(ports["vibrometer"], timeout=5)
        generator.write(b"*IDN?\n")
        assert b"33521A" in generator.readline()
        generator.write(b"FREQ 32126\nVOLT 40\nSYST:ERR?\n")  # 200 V: refused
        assert generator.readline().startswith(b"-222")
        generator.write(b"OUTP:LOAD INF\nVOLT 3\nOUTP ON\n")
        vibrometer.write(b"Set,VeloDec,1,Range,500mm/s/V\nGet,VeloDec,1,Range\n")
        assert vibrometer.readline() == b"500mm/s/V\n"
        lockin = serial.Serial(ports["lockin"], timeout=5)
        lockin.write(b"RSRC 1;OFLT 6;OFSL 3\n")  # 1 ms: settled well within a second of wall clock
        time.sleep(0.2)
        lockin.write(b"SNAP? 2,3\n")
        magnitude, _ = (float(x) for x in lockin.readline().split(b","))
        assert 0.19 < magnitude * np.sqrt(2) * 0.5 < 0.24
        lockin.close()
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


def test_pymeasure_sr860_client_drives_the_simulated_lockin_unchanged_over_a_pty():
    """PyMeasure's own ``SR860`` class on a pseudo-terminal served by the simulator (as a user's script would)."""
    pytest.importorskip("pymeasure")
    from pymeasure.adapters import SerialAdapter
    from pymeasure.instruments.srs import SR860

    from instruments.simulator.ptyserver import open_ptys, serve

    bench = Bench(default_bench_settings(relative_noise=0.0, floor_fraction=0.0, phase_noise=0.0))
    ptys, stop = open_ptys(), threading.Event()
    server = threading.Thread(target=serve, args=(bench, ptys), kwargs={"poll": 0.02, "should_stop": stop.is_set},
                              daemon=True)
    server.start()
    try:
        ports = {name: serial.Serial(pair.path, timeout=5) for name, pair in ptys.items()}
        client = SR860(SerialAdapter(ports["lockin"], write_termination="\n", read_termination="\n"))
        assert client.ask("*IDN?").startswith("Stanford_Research_Systems,SR860,")
        client.reference_source = "EXT"
        client.time_constant = 1e-3
        client.filter_slope = 3
        client.sensitivity = 1.0
        client.input_range = "1V"
        assert (client.reference_source, client.time_constant, client.sensitivity) == ("EXT", 1e-3, 1.0)
        f_r = bench.settings.response.resonance_frequency
        ports["generator"].write(f"OUTP:LOAD INF;:FREQ {f_r};:VOLT 3;:OUTP 1\n".encode())
        ports["vibrometer"].write(b"Set,VeloDec,1,Range,500mm/s/V\n")
        time.sleep(0.1)  # 10 ms settles a 1 ms, 24 dB/oct filter: the bench follows the wall clock
        velocity, phase = bench.settings.response.velocity(f_r, 15.0, bench.time)
        expected = float(velocity) / 0.5 / np.sqrt(2)
        assert client.magnitude == pytest.approx(expected, rel=0.01)
        assert client.frequency == pytest.approx(f_r)
        magnitude, theta = client.snap("R", "THeta")
        assert magnitude == pytest.approx(expected, rel=0.01)
        assert theta == pytest.approx(float(phase) - 360 * f_r * DECODER_DELAY, abs=1.0)
        assert client.x ** 2 + client.y ** 2 == pytest.approx(expected ** 2, rel=0.02)
        for port in ports.values():
            port.close()
    finally:
        stop.set()
        server.join(timeout=5)
        for pair in ptys.values():
            pair.close()
