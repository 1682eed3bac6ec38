"""Drivers against recorded exchanges: a replay port checks every line sent and plays the replies."""

import struct

import pytest
from ports import ReplayPort

from instruments.drivers.errors import (
    ConnectionLost,
    GarbledReply,
    InstrumentError,
    ReplyTimeout,
    SafetyLimitError,
)
from instruments.drivers.generator import FunctionGenerator
from instruments.drivers.lockin import (
    LockIn,
    LockInReading,
    capture_delay,
    capture_interval,
    capture_time_constant,
    parse_binary_block,
    settle_time,
)
from instruments.drivers.vibrometer import Vibrometer, format_delay, format_range, parse_delay, parse_range


def test_constructors_do_no_io():
    port = ReplayPort([])
    FunctionGenerator(port, max_peak_voltage=1.0)
    Vibrometer(port)
    LockIn(port)
    assert port.done()


def test_generator_settings_and_queries_replay():
    port = ReplayPort([
        ("*IDN?", b"Agilent Technologies,33521A,MY123,3.0\n"),
        ("FREQ 32126.5", None),
        ("FREQ?", b"+3.21265000000000E+04\n"),
        ("VOLT:OFFS?", b"+0.00000000000000E+00\n"),
        ("OUTP:LOAD?", b"+9.90000000000000E+37\n"),
        ("VOLT:UNIT VPP;:VOLT 2.5", None),
        ("VOLT:UNIT VPP;:VOLT?", b"+2.50000000000000E+00\n"),  # switching on checks the limit first
        ("VOLT:OFFS?", b"+0.00000000000000E+00\n"),
        ("OUTP:LOAD?", b"+9.90000000000000E+37\n"),
        ("OUTP 1", None),
        ("OUTP?", b"1\n"),
        ("SYST:ERR?", b'+0,"No error"\n'),
    ])
    generator = FunctionGenerator(port, max_peak_voltage=3.0)
    assert generator.identity.startswith("Agilent")
    generator.frequency = 32126.5
    assert generator.frequency == 32126.5
    generator.amplitude_vpp = 2.5
    generator.output = True
    assert generator.output is True
    generator.check_errors("test")
    assert port.done()


def test_generator_error_queue_is_reported_as_one_error():
    port = ReplayPort([("SYST:ERR?", b'-222,"Data out of range"\n'), ("SYST:ERR?", b'+0,"No error"\n')])
    with pytest.raises(InstrumentError, match="-222,Data out of range"):
        FunctionGenerator(port, 3.0).check_errors("setting 40 V")


def test_generator_driver_refuses_above_its_limit_without_sending_the_amplitude():
    # only the offset query goes out; the amplitude command never does
    port = ReplayPort([("VOLT:OFFS?", b"+0.00000000000000E+00\n"), ("OUTP:LOAD?", b"+9.90000000000000E+37\n"),])
    generator = FunctionGenerator(port, max_peak_voltage=3.0)
    with pytest.raises(SafetyLimitError, match="exceeds the limit 3 V"):
        generator.amplitude_vpp = 6.2
    assert port.done()


def test_generator_driver_counts_the_load_setting():
    """At the 50 ohm load setting the amplifier's high-impedance input sees twice the stated level:
    4 Vpp (2 V peak, 4 V at the terminals) is refused under a 3 V limit, 2.5 Vpp is accepted."""
    port = ReplayPort([
        ("VOLT:OFFS?", b"+0.00000000000000E+00\n"),
        ("OUTP:LOAD?", b"+5.00000000000000E+01\n"),
        ("VOLT:OFFS?", b"+0.00000000000000E+00\n"),
        ("OUTP:LOAD?", b"+5.00000000000000E+01\n"),
        ("VOLT:UNIT VPP;:VOLT 2.5", None),
    ])
    generator = FunctionGenerator(port, max_peak_voltage=3.0)
    with pytest.raises(SafetyLimitError, match="x2 into the amplifier"):
        generator.amplitude_vpp = 4.0
    generator.amplitude_vpp = 2.5
    assert port.done()
    with pytest.raises(SafetyLimitError, match="refusing"):
        FunctionGenerator(ReplayPort([]), 3.0).write("OUTP:LOAD 50")  # the load goes through load_ohm


def test_generator_driver_refuses_an_offset_that_pushes_the_peak_over_the_limit():
    port = ReplayPort([("VOLT:UNIT VPP;:VOLT?", b"+5.00000000000000E+00\n"), ("OUTP:LOAD?", b"+9.90000000000000E+37\n"),])
    with pytest.raises(SafetyLimitError):
        FunctionGenerator(port, max_peak_voltage=3.0).offset = 0.6
    assert port.done()


def test_timeout_and_garbled_replies_are_distinct_retryable_errors():
    generator = FunctionGenerator(ReplayPort([("FREQ?", None)]), 3.0)
    with pytest.raises(ReplyTimeout, match="no reply to 'FREQ\\?'"):
        generator.frequency
    generator = FunctionGenerator(ReplayPort([("FREQ?", b"+3.2\xf1E+04\n")]), 3.0)
    with pytest.raises(GarbledReply):
        generator.frequency
    generator = FunctionGenerator(ReplayPort([("FREQ?", b"hello\n")]), 3.0)
    with pytest.raises(GarbledReply, match="unexpected reply 'hello'"):
        generator.frequency


def test_a_failing_port_is_a_lost_connection():
    class DeadPort(ReplayPort):
        def write(self, data):
            raise OSError("device unplugged")

    with pytest.raises(ConnectionLost, match="device unplugged"):
        FunctionGenerator(DeadPort([]), 3.0).output = False


def test_vibrometer_replay():
    """OFV-5000 conventions: a Set is read back with its Get (acknowledge off: no reply to the Set)."""
    port = ReplayPort([
        ("GetDevInfo,Controller,0,Name", b"OFV-5000\n"),
        ("GetDevInfo,VeloDec,1,Range", b"5mm/s/V;1mm/s/V;25mm/s/V\n"),
        ("Set,Interface,0,Acknowledge,Off", None),
        ("Get,Interface,0,Acknowledge", b"Off\n"),
        ("Set,VeloDec,1,Range,25mm/s/V", None),
        ("Get,VeloDec,1,Range", b"25mm/s/V\n"),
        ("Get,VeloDec,1,SignalDelay", b"8.16us\n"),
    ])
    vibrometer = Vibrometer(port)
    assert vibrometer.controller == "OFV-5000"
    assert vibrometer.ranges == [0.001, 0.005, 0.025]
    vibrometer.acknowledge_off()
    vibrometer.decoder_range = 0.025
    assert vibrometer.signal_delay == pytest.approx(8.16e-6)
    assert port.done()


def test_vibrometer_error_reply_and_an_ignored_setting():
    with pytest.raises(InstrumentError, match="Error,1,Unknown command"):
        Vibrometer(ReplayPort([("Get,VeloDec,1,Range", b"Error,1,Unknown command\n")])).decoder_range
    port = ReplayPort([("Set,VeloDec,1,Range,5mm/s/V", None), ("Get,VeloDec,1,Range", b"25mm/s/V\n")])
    with pytest.raises(InstrumentError, match="kept Range at '25mm/s/V'"):
        Vibrometer(port).decoder_range = 0.005


def test_lockin_replay_settings_by_index_and_one_line_readings():
    port = ReplayPort([
        ("RSRC 1", None), ("OFLT 9", None), ("OFLT?", b"9\n"), ("SCAL 3", None), ("OFSL 3", None),
        ("SNAP? 2,3;CUROVLDSTAT?", b"1.2345e-01,-12.5;16\n"),
        ("*ESR?", b"16\n"),
    ])
    lockin = LockIn(port)
    lockin.reference_source = "EXT"
    lockin.time_constant = 0.03
    assert lockin.time_constant == pytest.approx(0.03)
    lockin.sensitivity = 0.1
    lockin.filter_poles = 4
    assert lockin.read() == LockInReading(0.12345, -12.5, 16)
    with pytest.raises(InstrumentError, match="execution error"):
        lockin.check_status("setting the time constant")
    assert port.done()


@pytest.mark.parametrize("reply, error", [
    (b"1.2e-01;0\n", GarbledReply),           # no theta
    (b"-1.2e-01,3.0;0\n", GarbledReply),      # a negative R
    (b"1.2e-01,3.0\n", GarbledReply),         # no status
    (b"1.2e-01,3\xff.0;0\n", GarbledReply),   # line noise
    (None, ReplyTimeout),
])
def test_bad_lockin_replies_are_retryable_errors(reply, error):
    with pytest.raises(error):
        LockIn(ReplayPort([("SNAP? 2,3;CUROVLDSTAT?", reply)])).read()


def test_binary_blocks_and_the_capture_ladder():
    values = (0.5, -1.25, 3.0e-3, 7.0)
    body = struct.pack("<4f", *values)
    assert parse_binary_block(b"#216" + body) == pytest.approx(values)
    for bad in (b"#217" + body, b"16" + body, b"#0" + body, b"#215" + body[:15]):
        with pytest.raises(ValueError):
            parse_binary_block(bad)
    port = ReplayPort([("CAPTUREGET? 0, 1", b"#216" + body + b"\n")])
    assert LockIn(port).capture_block(0, 1) == pytest.approx(values)
    assert capture_interval(50e-6) == pytest.approx(51.2e-6) and capture_interval(40e-6) == pytest.approx(51.2e-6)
    assert capture_interval(50e-6, at_least=True) == pytest.approx(51.2e-6)
    assert capture_interval(52e-6, at_least=True) == pytest.approx(102.4e-6)
    assert capture_time_constant(51.2e-6) == pytest.approx(10e-6) and capture_delay(51.2e-6) == pytest.approx(40e-6)


@pytest.mark.parametrize("poles, constants", [(1, 6.908), (2, 9.233), (4, 13.062)])
def test_settling_of_cascaded_filters(poles, constants):
    """exp(-x) sum_{j<n} x^j / j! = 1e-3 at the tabulated x."""
    assert settle_time(0.1, poles) == pytest.approx(0.1 * constants, rel=1e-3)


def test_delay_text_round_trip():
    assert parse_delay("8.16us") == pytest.approx(8.16e-6) and parse_delay("8.16 us") == pytest.approx(8.16e-6)
    assert format_delay(1.5e-6) == "1.5us"


def test_range_text_round_trip():
    for value in (0.001, 0.025, 0.1):
        assert parse_range(format_range(value)) == pytest.approx(value)
    with pytest.raises(ValueError):
        parse_range("25 V")
