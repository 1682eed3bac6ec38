"""The simulator never stalls: bounded input lines and output queues, each port served on its own.

Each test has a hard timeout, so a simulator that blocks fails fast instead of hanging the suite.
"""

import threading
import time

import pytest
import serial

from instruments.simulator import Bench, bench_url, default_bench_settings, register_bench, register_url_handler
from instruments.simulator.ptyserver import open_ptys, serve

IDN = b"Agilent Technologies,33521A,TACTILE-SIM,1.0-sim\n"
READOUT = b"SNAP? 2,3;CUROVLDSTAT?\n"
REPLY_BOUND = 1.0
"""Longest wait for a reply on a port whose client reads [s]."""


@pytest.fixture
def pty_ports():
    """A bench served on pseudo-terminals by :func:`serve` in a thread; the client ports."""
    bench = Bench(default_bench_settings())
    ptys = open_ptys()
    stop = threading.Event()
    server = threading.Thread(target=serve, args=(bench, ptys), kwargs={"poll": 0.05, "should_stop": stop.is_set},
                              daemon=True)
    server.start()
    ports = {name: serial.Serial(pair.path, timeout=REPLY_BOUND, write_timeout=5) for name, pair in ptys.items()}
    yield ports
    stop.set()
    for port in ports.values():
        port.close()
    server.join(timeout=2)
    if not server.is_alive():  # a stalled server still holds its fds
        for pair in ptys.values():
            pair.close()


def timed_readout(lockin) -> float:
    """Seconds a lock-in reading takes to come back complete."""
    start = time.monotonic()
    lockin.write(READOUT)
    reply = lockin.readline()
    assert reply.endswith(b";0\n") and reply.count(b",") == 1, reply
    return time.monotonic() - start


def drain(port) -> bytes:
    """Everything ``port`` receives until it is quiet for 0.3 s."""
    port.timeout = 0.3
    received = b""
    while chunk := port.read(1 << 16):
        received += chunk
    port.timeout = REPLY_BOUND
    return received


@pytest.mark.timeout(20)
def test_a_client_sending_3000_queries_without_reading_neither_deadlocks_nor_delays_the_other_port(pty_ports):
    generator, lockin = pty_ports["generator"], pty_ports["lockin"]
    generator.write(b"*IDN?\n" * 3000)
    generator.flush()
    assert timed_readout(lockin) < REPLY_BOUND
    replies = drain(generator).splitlines(keepends=True)
    assert 0 < len(replies) < 3000 and set(replies) == {IDN}  # the overflow dropped whole replies
    generator.write(b"SYST:ERR?\n")
    assert generator.readline() == b'-430,"Query DEADLOCKED"\n'
    generator.write(b"*CLS;*IDN?\n")
    assert generator.readline() == IDN


@pytest.mark.timeout(20)
def test_a_stuck_client_on_the_generator_does_not_delay_the_lockin(pty_ports):
    generator, lockin = pty_ports["generator"], pty_ports["lockin"]
    stop = threading.Event()

    def flood():  # writes queries and never reads
        while not stop.is_set():
            generator.write(b"*IDN?;*IDN?;*IDN?\n" * 50)

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    try:
        time.sleep(0.5)
        delays = [timed_readout(lockin) for _ in range(10)]
        assert flooder.is_alive()  # its writes never block for long (write_timeout would end it)
    finally:
        stop.set()
        flooder.join(timeout=6)
    assert max(delays) < REPLY_BOUND / 2


@pytest.mark.timeout(20)
def test_a_16_mb_line_is_discarded_in_linear_time_and_reported(pty_ports):
    generator, vibrometer = pty_ports["generator"], pty_ports["vibrometer"]
    start = time.monotonic()
    generator.write(b"A" * (16 << 20))
    vibrometer.write(b"X" * 5000 + b"\n")
    generator.write(b"\n*IDN?\n")
    assert generator.readline() == IDN
    assert time.monotonic() - start < 5  # was 26 s: the line was re-scanned at every read
    query = time.monotonic()
    generator.write(b"SYST:ERR?\n")
    assert generator.readline() == b'-363,"Input buffer overrun"\n'
    generator.write(b"SYST:ERR?\n")
    assert generator.readline() == b'+0,"No error"\n'
    assert time.monotonic() - query < REPLY_BOUND
    assert vibrometer.readline() == b"Error,3,Input buffer overrun\n"


def url_ports():
    register_url_handler()
    name = register_bench(Bench(default_bench_settings()))
    return [serial.serial_for_url(bench_url(name, i), timeout=1) for i in ("generator", "vibrometer")]


def test_line_length_bound_on_the_url_handler_counts_bytes_across_writes():
    generator, vibrometer = url_ports()
    accepted = b"*OPC?;" * 682 + b"*OPC"  # 4096 bytes, the size of the input buffer
    over_long = accepted + b"?"
    generator.write(over_long[:3000])
    generator.write(over_long[3000:] + b"\n")
    generator.write(accepted + b"\n")
    assert generator.readline() == b"1;" * 681 + b"1\n"  # the 4097-byte line never ran
    generator.write(b"SYST:ERR?\n")
    assert generator.readline() == b'-363,"Input buffer overrun"\n'
    vibrometer.write(b"Get," * 1100 + b"\nGetDevInfo,VeloDec,1,Name\n")
    assert vibrometer.readline() == b"Error,3,Input buffer overrun\n"
    assert vibrometer.readline() == b"VD-09\n"


@pytest.mark.timeout(20)
def test_url_handler_output_queue_is_bounded_and_keeps_whole_replies():
    generator, vibrometer = url_ports()
    for _ in range(2000):
        generator.write(b"*IDN?\n")
        vibrometer.write(b"GetDevInfo,VeloDec,1,Name\n")
    assert 0 < generator.in_waiting <= 4096 and 0 < vibrometer.in_waiting <= 4096
    assert set(generator.read(generator.in_waiting).splitlines(keepends=True)) == {IDN}
    assert set(vibrometer.read(vibrometer.in_waiting).splitlines()) == {b"VD-09"}
    generator.write(b"SYST:ERR?\n")
    assert generator.readline() == b'-430,"Query DEADLOCKED"\n'


@pytest.mark.timeout(20)
def test_url_handler_skips_a_16_mb_line_written_in_4_kb_pieces_in_linear_time():
    generator, _ = url_ports()
    start = time.monotonic()
    for _ in range(4096):
        generator.write(b"A" * 4096)
    generator.write(b"\n*IDN?\n")
    assert generator.readline() == IDN
    assert time.monotonic() - start < 5
    generator.write(b"SYST:ERR?;:SYST:ERR?\n")
    assert generator.readline() == b'-363,"Input buffer overrun";+0,"No error"\n'
