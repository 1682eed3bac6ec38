"""Drivers against recorded exchanges: a replay port checks every line sent and plays the replies."""

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
from instruments.drivers.vibrometer import VelocityReading, Vibrometer, format_range, parse_range


def test_constructors_do_no_io():
    port = ReplayPort([])
    FunctionGenerator(port, max_peak_voltage=1.0)
    Vibrometer(port)
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
    port = ReplayPort([
        ("GetDevInfo,Controller,0,Name", b"OFV-5000\n"),
        ("GetDevInfo,VeloDec,1,Ranges", b"5mm/s/V;1mm/s/V;25mm/s/V\n"),
        ("Set,VeloDec,1,Range,25mm/s/V", b"25mm/s/V\n"),
        ("Get,VeloDec,1,Range", b"25mm/s/V\n"),
        ("Get,LockIn,0,Velocity", b"1.234500E-01,-12.500,OK\n"),
        ("Get,LockIn,0,Velocity", b"2.500000E-01,+3.000,OVER\n"),
    ])
    vibrometer = Vibrometer(port)
    assert vibrometer.controller == "OFV-5000"
    assert vibrometer.ranges == [0.001, 0.005, 0.025]
    vibrometer.decoder_range = 0.025
    assert vibrometer.decoder_range == pytest.approx(0.025)
    assert vibrometer.read_velocity() == VelocityReading(0.12345, -12.5, False)
    assert vibrometer.read_velocity().over_range
    assert port.done()


def test_vibrometer_error_reply_and_wrong_acknowledge():
    with pytest.raises(InstrumentError, match="Error,1,Unknown command"):
        Vibrometer(ReplayPort([("Get,VeloDec,1,Range", b"Error,1,Unknown command\n")])).decoder_range
    with pytest.raises(GarbledReply, match="acknowledged"):
        Vibrometer(ReplayPort([("Set,VeloDec,1,Range,5mm/s/V", b"25mm/s/V\n")])).decoder_range = 0.005


def test_range_text_round_trip():
    for value in (0.001, 0.025, 0.1):
        assert parse_range(format_range(value)) == pytest.approx(value)
    with pytest.raises(ValueError):
        parse_range("25 V")
