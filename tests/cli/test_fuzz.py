"""Property-based (Hypothesis) tests of the parsers at the boundaries: the interferometer-log reader (sweeps,
ring-downs, scans), the calibration reader, the run configuration's sections, the resume of an edited log,
the simulator's SCPI and vibrometer command parsers, and the generator driver's limit.

Each property runs twice: under the default profile (40 examples per property, about two
seconds in all) and, marked ``slow``, under the ``long`` profile (thousands of examples):
``pytest -m slow tests/cli/test_fuzz.py``.  ``HYPOTHESIS_PROFILE=long pytest tests/cli/test_fuzz.py``
runs the default-suite tests with the long profile too.  Profiles are registered in
``tests/conftest.py``.
"""

import copy
import functools
import json
import math
import operator
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hostile import CORPUS
from ports import DevicePort

from instruments.drivers.errors import InstrumentError
from instruments.drivers.generator import FunctionGenerator
from instruments.procedures.logwriter import INCOMPLETE_ROW, read_log, row_key
from instruments.procedures.simulated import simulated_station
from instruments.procedures.sweeps import CampaignPlan, q_campaign
from instruments.simulator import default_bench_settings
from instruments.simulator.generator import FUNCTIONS, MAX_ERRORS, GeneratorDevice, GeneratorState
from instruments.simulator.scpi import split_program
from instruments.simulator.vibrometer import VibrometerDevice
from workflow import logformat
from workflow.damping.logs import MIN_PEAK_VELOCITY, read_logs
from workflow.errors import InputFileError, TactileError
from workflow.models.limits import LIMITS, plate_problem, point_problem
from workflow.pipeline.builtplate import read_scan
from workflow.pipeline.calibration_files import load_calibration
from workflow.pipeline.config import default_config, merge, to_toml

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

pytestmark = pytest.mark.timeout(300)  # a hang fails the test instead of stalling the suite


def fuzz(**strategies):
    """Test the property ``body(**examples)`` under the current profile, and under ``long`` when slow."""

    def decorate(body):
        @pytest.mark.parametrize("profile", [None, pytest.param("long", marks=pytest.mark.slow)])
        def test(profile):
            chosen = settings() if profile is None else settings.get_profile(profile)
            settings(chosen)(given(**strategies)(body))()

        test.__name__, test.__doc__ = body.__name__, body.__doc__
        return test

    return decorate


# --- the interferometer-log reader -----------------------------------------------------------------

ENCODINGS = ("utf-8", "utf-8-sig", "latin-1", "utf-16")
LINE_ENDS = ("\n", "\r\n", "\r")
SEPARATORS = (",", ";", "\t")
COLUMN_NAMES = logformat.COLUMNS + ("x_mm", "y_mm", "frequency_khz", "velocity_mm_s", "voltage", "note", "")

numbers = st.floats(allow_nan=True, allow_infinity=True).map(repr)
number_texts = st.one_of(
    numbers,
    st.sampled_from(["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e400", "-1e400", "1e-400", "0", "-0", "",
                     " ", "1_000", "0x10", "1,5", '"1"', '"', "1e308", "4.9e-324"]),
    st.integers(min_value=-(10**400), max_value=10**400).map(str),
    st.text(max_size=8),
)
cells = st.one_of(number_texts, st.sampled_from(COLUMN_NAMES))


@st.composite
def log_like_bytes(draw):
    """Text shaped like a log (comments, a header, rows of numbers), damaged at random, then encoded."""
    separator = draw(st.sampled_from(SEPARATORS))
    line_end = draw(st.sampled_from(LINE_ENDS))
    extra = draw(st.lists(st.sampled_from(COLUMN_NAMES), max_size=3))
    header = draw(st.permutations(list(logformat.REQUIRED_COLUMNS) + extra))
    lines = draw(st.lists(st.sampled_from(["# tactile interferometer log", "# format_version: 1", "", "#"]),
                          max_size=3))
    lines.append(separator.join(header))
    width = st.integers(min_value=max(0, len(header) - 1), max_value=len(header) + 1)
    for _ in range(draw(st.integers(min_value=0, max_value=8))):
        lines.append(separator.join(draw(st.lists(cells, min_size=draw(width), max_size=len(header) + 1))))
    if draw(st.booleans()):  # a very long line somewhere
        long_line = draw(st.sampled_from(["1", "a", "1,", ",", '"'])) * draw(st.integers(1000, 300_000))
        lines.insert(draw(st.integers(0, len(lines))), long_line)
    text = line_end.join(lines) + draw(st.sampled_from(["", line_end]))
    return text.encode(draw(st.sampled_from(ENCODINGS)), errors="replace")


log_inputs = st.one_of(st.binary(max_size=2000), log_like_bytes(), st.text(max_size=500).map(str.encode))


def read_or_refused(name: str, data: bytes, reader):
    """``reader(path)`` of a file ``name`` holding ``data``, or None when it raised one InputFileError line naming
    the file; the file's bytes are unchanged either way."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_bytes(data)
        try:
            return reader(path)
        except InputFileError as error:
            assert str(path) in str(error) and len(str(error).splitlines()) == 1, error
            return None
        finally:
            assert path.read_bytes() == data


def read_file_bytes(data: bytes):
    """read_logs on a file holding ``data``: (log or None, error or None); the file's bytes are unchanged."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "log.csv"
        path.write_bytes(data)
        try:
            return read_logs([path]), None
        except InputFileError as error:
            message = str(error)
            assert str(path) in message and len(message.splitlines()) == 1, message
            return None, error
        finally:
            assert path.read_bytes() == data


@fuzz(data=log_inputs)
def test_the_log_reader_returns_a_log_or_one_line_naming_the_file(data):
    """Any bytes: a log, or one InputFileError line naming the file; never another exception; the file unchanged."""
    log, _ = read_file_bytes(data)
    if log is not None:
        assert len(log.frequency) == len(log.drive_voltage) == len(log.velocity) == len(log.sweep) > 0
        assert np.all(log.frequency > 0) and np.all(log.drive_voltage >= 0) and np.all(log.velocity >= 0)


frequencies = st.floats(*LIMITS[logformat.FREQUENCY])
"""Frequencies a log may hold [Hz] (docs/log-format.md: the plausible range)."""
velocities = st.floats(min_value=1e-6, max_value=10.0)
"""Velocities a sweep may hold [m/s] (docs/log-format.md: 0 to 10 m/s, each sweep peaking at 1 um/s or more)."""


@st.composite
def valid_logs(draw):
    """A valid log: (its bytes, its rows as (frequency, voltage, velocity or None for a dropout, sweep id,
    other value), whether it has a sweep column, whether it ends with a newline)."""
    optional = draw(st.lists(st.sampled_from(logformat.OPTIONAL_COLUMNS + ("x_mm", "note")), unique=True))
    header = draw(st.permutations(list(logformat.REQUIRED_COLUMNS) + optional))
    quarter_volts = st.integers(0, 4000).map(lambda quarters: quarters / 4)  # distinct beyond the reader's tolerance
    voltages = draw(st.lists(quarter_volts, min_size=1, max_size=3, unique=True))
    rows = draw(st.lists(st.tuples(frequencies, st.sampled_from(voltages), st.one_of(velocities, st.none()),
                                   st.integers(-5, 5), st.floats(allow_nan=False, allow_infinity=False)),
                         min_size=1, max_size=20))
    values = {logformat.FREQUENCY: 0, logformat.DRIVE_VOLTAGE: 1, logformat.VELOCITY: 2, logformat.SWEEP: 3}
    line_end = draw(st.sampled_from(("\n", "\r\n")))
    lines = ["# tactile interferometer log", "# format_version: 1", ",".join(header)]
    for row in rows:
        fields = []
        for name in header:
            value = row[values[name]] if name in values else row[4]
            fields.append(draw(st.sampled_from(["", "nan"])) if value is None else repr(value))
        lines.append(",".join(fields))
        if draw(st.booleans()):
            lines.append(draw(st.sampled_from(["", "# a comment", "   "])))
    while lines[-1].strip() == "" or lines[-1].startswith("#"):
        lines.pop()
    final_newline = draw(st.booleans())
    text = line_end.join(lines) + (line_end if final_newline else "")
    bom = draw(st.sampled_from(["", "\ufeff"]))
    return (bom + text).encode(), rows, logformat.SWEEP in header, final_newline


@fuzz(case=valid_logs())
def test_valid_logs_read_back_with_the_values_written(case):
    """A log built from the format with random values reads back exactly: values, dropouts, sweeps (a complete
    last row is read whether or not a newline ends the file)."""
    data, rows, has_sweep, _ = case
    kept = [row for row in rows if row[2] is not None]
    log, error = read_file_bytes(data)
    if not kept:
        assert error is not None
        return
    assert error is None, error
    frequency, voltage, velocity, ids, _ = map(list, zip(*kept))
    assert list(log.frequency) == frequency and list(log.drive_voltage) == voltage and list(log.velocity) == velocity
    key = ids if has_sweep else voltage
    starts = [True] + [a != b for a, b in zip(key[1:], key[:-1])]
    assert list(log.sweep) == list(np.cumsum(starts) - 1)
    unmapped_point = logformat.X_POSITION in data.decode("utf-8-sig").splitlines()[2]  # no lambda_mm: one warning
    assert len(log.warnings) == (len(kept) < len(rows)) + unmapped_point


@fuzz(case=valid_logs(), line=st.integers(min_value=0), bad=st.sampled_from(["inf", "-1", "abc", "1e999", "-inf"]))
def test_a_bad_value_is_refused_naming_its_line(case, line, bad):
    """One non-finite, negative or non-numeric frequency in a valid log: one line naming the file and that line."""
    data, rows, _, _ = case
    lines = data.decode("utf-8-sig").split("\n")
    header_at = 2  # after the two metadata lines valid_logs writes
    header = lines[header_at].rstrip("\r").split(",")
    velocity = header.index(logformat.VELOCITY)
    complete = lines if data.endswith(b"\n") else lines[:-1]  # an incomplete last line is ignored
    data_lines = [i for i, text in enumerate(complete) if i > header_at and text.strip() and not text.startswith("#")
                  and text.rstrip("\r").split(",")[velocity] not in ("", "nan")]  # nor are dropouts checked
    assume(data_lines)
    target = data_lines[line % len(data_lines)]
    fields = lines[target].rstrip("\r").split(",")
    fields[header.index(logformat.FREQUENCY)] = bad
    lines[target] = ",".join(fields) + "\r" * lines[target].endswith("\r")
    _, error = read_file_bytes("\n".join(lines).encode())
    assert error is not None and f"line {target + 1}:" in str(error)


# --- the simulator's command parsers -------------------------------------------------------------

HEADER_PATTERNS = ("*IDN", "*RST", "*CLS", "*OPC", "SYSTem:ERRor[:NEXT]", "[SOURce#:]FUNCtion[:SHAPe]",
                   "[SOURce#:]FREQuency[:CW]", "[SOURce#:]VOLTage:UNIT", "[SOURce#:]VOLTage[:LEVel][:IMMediate]:OFFSet",
                   "[SOURce#:]VOLTage[:LEVel][:IMMediate][:AMPLitude]", "OUTPut#:LOAD", "OUTPut#[:STATe]",
                   "APPLy:SINusoid", "VOLTage:HIGH", "VOLTage:LOW")
"""The headers of docs/instruments.md, as the 33500 manual writes them, and a few it lacks."""


SUFFIXES = ("", "", "1", "2", "01", "0", "99999999999999999999")
QUERY_MARKS = ("", "", "?")


@st.composite
def scpi_headers(draw, patterns=HEADER_PATTERNS, suffixes=SUFFIXES, query_marks=QUERY_MARKS):
    """A header from ``patterns``: random short/long forms, case, optional nodes, suffixes, query mark."""
    pattern = draw(st.sampled_from(patterns))
    nodes = []
    for node in pattern.replace("[", " [").replace("]", "] ").replace(":", " ").split():
        if node.startswith("[") and not draw(st.booleans()):
            continue
        word = node.strip("[]")
        suffix = draw(st.sampled_from(suffixes)) if "#" in word else ""
        word = word.rstrip("#")
        form = word if draw(st.booleans()) else "".join(c for c in word if not c.islower())
        nodes.append(draw(st.sampled_from([form, form.upper(), form.lower()])) + suffix)
    header = ":".join(node for node in nodes if node)
    return draw(st.sampled_from(["", ":"])) + header + draw(st.sampled_from(query_marks))


scpi_arguments = st.one_of(number_texts, st.sampled_from(["INF", "MIN", "MAX", "DEF", "ON", "OFF", "VPP", "VRMS", "DBM",
                                                           "SIN", "SQUARE", "1000,8,0", "0", "1"]))
scpi_commands = st.tuples(scpi_headers(), st.sampled_from(["", " ", "  ", "\t", " ,"]), scpi_arguments).map("".join)
scpi_lines = st.one_of(
    st.lists(scpi_commands, min_size=1, max_size=4).flatmap(
        lambda commands: st.sampled_from([";", "; ", ";:"]).map(lambda separator: separator.join(commands))),
    st.text(max_size=200),
    st.text(st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=200),
    st.tuples(st.sampled_from(["VOLT ", "FREQ ", "", ";", ":"]), st.integers(1000, 100_000)).map(lambda t: t[0] * t[1]),
)
device_limits = st.floats(min_value=0.1, max_value=20.0)


@fuzz(lines=st.lists(scpi_lines, max_size=12), limit=device_limits)
def test_the_simulated_generator_never_raises_and_never_exceeds_its_limit(lines, limit):
    """Any sequence of lines: errors go to the error queue, replies are printable lines, the peak stays
    within the limit."""
    device = GeneratorDevice(limit)
    for line in lines:
        reply = device.handle_line(line)
        assert reply is None or (reply.isprintable() and reply.isascii()), reply
        assert device.state.peak_voltage <= limit + 1e-9, (line, device.state)
        assert len(device.errors) <= MAX_ERRORS


@fuzz(header=scpi_headers(HEADER_PATTERNS[4:12] + ("*IDN", "*OPC"), suffixes=("", "1"), query_marks=("?",)))
def test_every_form_of_a_documented_query_is_answered(header):
    """Short or long form, any case, optional nodes or not, channel 1 or none: a reply, no error."""
    device = GeneratorDevice(1.0)
    assert device.handle_line(header) and device.errors == [], header


@fuzz(line=scpi_lines)
def test_split_program_returns_header_and_argument_pairs(line):
    """Any line: (header, argument) pairs, headers non-empty and without ';'."""
    for header, argument in split_program(line):
        assert header and ";" not in header + argument


VIBROMETER_WORDS = ("Get", "GetDevInfo", "Set", "Controller", "VeloDec", "SensorHead", "Interface", "SignalLevel", "0",
                    "1", "Name", "Version", "Range", "SignalDelay", "Value", "Acknowledge", "On", "Off", "5mm/s/V",
                    "100MM/S/V", "3mm/s/V", "mm/s/V", "")
vibrometer_lines = st.one_of(
    st.lists(st.one_of(st.sampled_from(VIBROMETER_WORDS), st.text(max_size=6)), max_size=7).flatmap(
        lambda words: st.sampled_from([",", ", ", ";"]).map(lambda separator: separator.join(words))),
    st.text(max_size=200),
)


@fuzz(lines=st.lists(vibrometer_lines, max_size=12))
def test_the_simulated_vibrometer_answers_every_query_with_one_line(lines):
    """Any sequence of lines: one printable reply line to each that is no ``Set`` (an error reply for what it does not
    know); a ``Set`` answers only with acknowledge on, and only the value in effect; the range stays one of its own."""
    device = VibrometerDevice()
    for line in lines:
        acknowledge = device.acknowledge
        reply = device.handle_line(line)
        fields = [field.strip() for field in line.strip().split(",")]
        if fields[0] == "Set" and len(fields) == 5 and reply is None:
            continue
        if fields[0] == "Set" and len(fields) == 5 and not reply.startswith("Error,"):
            assert acknowledge or device.acknowledge, (line, reply)
        assert isinstance(reply, str) and reply and reply.isprintable() and reply.isascii(), reply
        assert device.decoder_range in device.ranges


LOCKIN_WORDS = ("*IDN?", "*RST", "*CLS", "*ESR?", "RSRC", "RSRC?", "OFLT", "OFLT?", "SCAL", "SCAL?", "IRNG", "OFSL",
                "FREQ", "FREQ?", "OUTP?", "SNAP?", "CUROVLDSTAT?", "LIAS?", "OAUX?", "CAPTURECFG", "CAPTURELEN",
                "CAPTURERATE", "CAPTURERATE?", "CAPTURESTART", "CAPTURESTOP", "CAPTURESTAT?", "CAPTUREGET?",
                "CAPTUREVAL?", "ONE", "TRIG", "IMM", "R", "THeta", "0", "2", "3", "21", "99", "-1", "1e9", "nan", "")
lockin_lines = st.one_of(
    st.lists(st.one_of(st.sampled_from(LOCKIN_WORDS), st.text(max_size=5)), max_size=5).map(
        lambda words: (words[0] + " " + ",".join(words[1:])) if words else ""),
    st.text(max_size=100),
)


@fuzz(lines=st.lists(lockin_lines, max_size=10), step=st.floats(min_value=0, max_value=10))
def test_the_simulated_lockin_answers_any_line_with_a_reply_or_a_status_bit(lines, step):
    """Any line: a printable ASCII reply, a binary block, or nothing (a refused command sets *ESR? bits); its state
    stays within the SR860's settings; nothing raises."""
    from instruments.simulator.bench import Bench

    bench = Bench(default_bench_settings())
    for line in lines:
        bench.sleep(step)
        reply = bench.lockin.handle_line(line)
        assert reply is None or (isinstance(reply, bytes) and reply.startswith(b"#")) or (
            isinstance(reply, str) and reply.isascii() and reply.isprintable()), reply
    state = bench.lockin.state
    assert 0 <= state["time_constant"] <= 21 and 0 <= state["sensitivity"] <= 27 and 0 <= state["slope"] <= 3


# --- the generator driver's limit over the simulated generator -----------------------------------

DRIVER_DEVICE_LIMIT = 1e6
"""The simulated generator's own limit, far above the driver's, so that only the driver stands in the way [V]."""
levels = st.floats(min_value=-20, max_value=20)
driver_calls = st.one_of(
    st.tuples(st.just("amplitude_vpp"), st.floats(min_value=1e-3, max_value=10)),
    st.tuples(st.just("offset"), levels),
    st.tuples(st.just("load_ohm"), st.sampled_from([math.inf, 1.0, 50.0, 1000.0, 10e3])),
    st.tuples(st.just("function"), st.sampled_from(FUNCTIONS)),
    st.tuples(st.just("frequency"), st.floats(min_value=1, max_value=1e6)),
    st.tuples(st.just("output"), st.booleans()),
    st.tuples(st.sampled_from(["reset", "clear", "switch_off", "check_errors"]), st.none()),
    st.tuples(st.sampled_from(["write", "set"]), scpi_lines),
    st.tuples(st.just("unit behind"), st.sampled_from(["VPP", "VRMS"])),
    st.tuples(st.just("load behind"), st.sampled_from([math.inf, 1.0, 50.0, 1000.0])),
)


def call(generator: FunctionGenerator, device: GeneratorDevice, name: str, value) -> None:
    """One driver call, or a change made behind the driver's back (only one keeping the peak within its limit)."""
    if name in ("unit behind", "load behind"):
        changed = replace(device.state, **{"unit" if name == "unit behind" else "load": value})
        if changed.peak_voltage <= generator.max_peak_voltage:
            device.state = changed
    elif name in ("reset", "clear", "switch_off"):
        getattr(generator, name)()
    elif name == "check_errors":
        generator.check_errors("fuzzing")
    elif name in ("write", "set"):
        getattr(generator, name)(value)
    else:
        setattr(generator, name, value)


def test_an_amplitude_at_the_limit_is_not_rounded_above_it():
    """Found by the property below: 1.732421875 Vpp into 50 ohm, checked against a 1.732421875 V limit, went out as
    '1.73242188' (9 digits rounded to nearest); levels are now rounded toward zero."""
    device = GeneratorDevice(DRIVER_DEVICE_LIMIT)
    device.state = GeneratorState(amplitude_vpp=1e-3, load=math.inf)
    generator = FunctionGenerator(DevicePort(device), max_peak_voltage=1.732421875)
    for name, value in [("load_ohm", 50.0), ("output", True), ("amplitude_vpp", 1.732421875), ("offset", 0.0)]:
        call(generator, device, name, value)
    assert device.state.output and device.state.peak_voltage <= 1.732421875


@fuzz(calls=st.lists(driver_calls, max_size=25), limit=st.floats(min_value=0.01, max_value=10.0))
def test_no_sequence_of_driver_calls_exceeds_the_drivers_limit(calls, limit):
    """Driver calls and raw commands in any order, unit and load changed behind its back: while the output
    is on, the true peak stays within the limit."""
    device = GeneratorDevice(DRIVER_DEVICE_LIMIT)
    device.state = GeneratorState(amplitude_vpp=1e-3, load=math.inf)
    generator = FunctionGenerator(DevicePort(device), max_peak_voltage=limit)
    for name, value in calls:
        try:
            call(generator, device, name, value)
        except InstrumentError:
            pass
        if device.state.output:
            assert device.state.peak_voltage <= limit * (1 + 1e-9), (name, value, device.state)


# --- calibration.json (--calibration) ------------------------------------------------------------

VALID_CALIBRATION = json.loads((CORPUS / "calibrations" / "valid.json").read_text(encoding="utf-8"))
"""A small calibration written by ``tactile calibrate`` on a coarse mesh (tests/data/hostile/README.md)."""
json_values = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**30), 10**30), st.floats(), st.text(max_size=12),
    st.sampled_from(["paper", "eigenstrain", "coupled", "uniform", "normal", "glue_um", "tactile-calibration"]),
    st.lists(st.floats(), max_size=4), st.dictionaries(st.text(max_size=6), st.floats(), max_size=2),
)


def _json_paths(data, prefix=()):
    """The path (keys and indices) of every value of a JSON tree, its root included."""
    yield prefix
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, list) else ()
    for key, value in items:
        yield from _json_paths(value, prefix + (key,))


CALIBRATION_PATHS = list(_json_paths(VALID_CALIBRATION))


@st.composite
def damaged_calibrations(draw) -> str:
    """A valid calibration with one to three values replaced by anything JSON holds, or deleted."""
    data = copy.deepcopy(VALID_CALIBRATION)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(CALIBRATION_PATHS))
        if not path:
            data = draw(json_values)
            continue
        try:
            parent = functools.reduce(operator.getitem, path[:-1], data)
            if draw(st.booleans()):
                del parent[path[-1]]
            else:
                parent[path[-1]] = draw(json_values)
        except (KeyError, IndexError, TypeError):  # an earlier change removed that place
            pass
    return json.dumps(data)


@pytest.mark.parametrize("name", ["\x85", "\u2028", "a\nb", "\x1c"])
def test_a_parameter_named_with_a_line_break_is_refused_in_one_line(name):
    """Found by the property below: a name holding a character that ends a line (NEL, LINE SEPARATOR, ...) was
    quoted as is in the error, which then printed as two lines."""
    data = copy.deepcopy(VALID_CALIBRATION)
    data["settings"]["parameters"][0]["name"] = name
    assert read_or_refused("calibration.json", json.dumps(data).encode(), load_calibration) is None


def test_a_surrogate_of_infinite_degree_is_refused_in_one_line():
    """Found by the property below (long profile): a surrogate's degree of 1e999 (JSON's Infinity) raised an
    OverflowError out of the reader instead of its one line."""
    data = copy.deepcopy(VALID_CALIBRATION)
    data["surrogates"][0]["log_frequency"]["degree"] = math.inf
    assert read_or_refused("calibration.json", json.dumps(data).encode(), load_calibration) is None


@fuzz(text=damaged_calibrations())
def test_the_calibration_reader_returns_a_checked_calibration_or_one_line_naming_the_file(text):
    """Any damage: a calibration whose priors are plausible, whose samples lie inside them and whose surrogates
    predict plausible resonances there, or one InputFileError line naming the file; the file unchanged."""
    calibration = read_or_refused("calibration.json", text.encode(), load_calibration)
    if calibration is None:
        return
    for k, parameter in enumerate(calibration.settings.parameters):
        parameter.check("fuzz")
        assert np.all((calibration.samples[:, k] >= parameter.low) & (calibration.samples[:, k] <= parameter.high))
    assert {"q", "voltage_v", "accuracy", "piezo"} <= set(calibration.fem)
    for surrogate in calibration.surrogates:
        low, high = LIMITS[logformat.FREQUENCY]
        assert np.all((surrogate.frequency(calibration.samples) >= low) & (surrogate.frequency(calibration.samples) <= high))


# --- ring-down and scan logs ---------------------------------------------------------------------

anything = st.one_of(number_texts, st.floats(-1e3, 1e3).map(repr), st.just(""))


@st.composite
def ringdown_logs(draw) -> bytes:
    """A ring-down log (docs/log-format.md): bursts of envelope samples, some values hostile, rows repeated or moved."""
    rows = []
    for burst in range(draw(st.integers(1, 3))):
        level, samples = draw(st.sampled_from([1.0, 5.0, 15.0])), draw(st.integers(1, 6))
        for k in range(samples):
            rows.append([str(burst), "1.000", repr(k * 5e-5), "32126", repr(level), repr(0.1 * 0.9**k), "22.5"])
    for _ in range(draw(st.integers(0, 4))):
        row, column = draw(st.integers(0, len(rows) - 1)), draw(st.integers(0, 6))
        action = draw(st.sampled_from(["value", "repeat", "move"]))
        if action == "value":
            rows[row][column] = draw(anything)
        elif action == "repeat":
            rows.insert(row, list(rows[row]))
        else:
            rows.insert(draw(st.integers(0, len(rows))), rows.pop(row))
    lines = ["# tactile interferometer log", ",".join(logformat.RINGDOWN_COLUMNS)] + [",".join(row) for row in rows]
    return ("\n".join(lines) + "\n").encode()


@fuzz(data=ringdown_logs())
def test_the_ringdown_reader_returns_plausible_decays_or_one_line_naming_the_file(data):
    """A ring-down log with hostile values, repeated or moved rows: decays whose samples lie in their plausible
    ranges at strictly increasing times within each burst, each burst above the velocity floor; or one line."""
    log, _ = read_file_bytes(data)
    if log is None:
        return
    decays = log.ringdown
    assert decays is not None and log.n_sweeps == 0
    for burst in range(decays.n_bursts):
        mine = decays.burst == burst
        assert np.all(np.diff(decays.decay_time[mine]) > 0) and decays.velocity[mine].max() >= MIN_PEAK_VELOCITY
    for column, values in ((logformat.DECAY_TIME, decays.decay_time), (logformat.VELOCITY, decays.velocity),
                           (logformat.FREQUENCY, decays.frequency), (logformat.DRIVE_VOLTAGE, decays.drive_voltage)):
        low, high = LIMITS[column]
        assert np.all((values >= low) & (values <= high)), column


lengths_mm = st.one_of(st.sampled_from(["20.56", "0.75", "1.0", "49", "1e-6", "1e6", "-1", "0", "nan", "abc", ""]),
                       st.floats(-1e3, 1e3).map(repr))


@st.composite
def scan_logs(draw) -> bytes:
    """A scan of a built plate (docs/log-format.md): its metadata and points, any of them hostile."""
    geometry = {"lambda_mm": "20.56", "h_i_mm": "0.75", "h_p_mm": "1.0", "b_mm": "49"}
    for key in draw(st.lists(st.sampled_from(sorted(geometry)), max_size=2, unique=True)):
        geometry[key] = draw(lengths_mm)
    lines = ["# tactile interferometer log"] + [f"# {key}: {value}" for key, value in geometry.items()]
    lines.append(",".join(logformat.SCAN_COLUMNS))
    for x, y in draw(st.lists(st.tuples(st.floats(-60, 60), st.floats(-30, 30)), min_size=1, max_size=6)):
        lines.append(f"23160,5,{draw(st.floats(0, 0.2))!r},0,1.000,{draw(st.floats(-180, 180))!r},{x!r},{y!r}")
    for _ in range(draw(st.integers(0, 2))):
        row = draw(st.integers(2 + len(geometry), len(lines) - 1))
        cells = lines[row].split(",")
        cells[draw(st.integers(0, len(cells) - 1))] = draw(anything)
        lines[row] = ",".join(cells)
    return ("\n".join(lines) + "\n").encode()


@fuzz(data=scan_logs())
def test_the_scan_reader_returns_points_on_the_plate_or_one_line_naming_the_file(data):
    """A scan with hostile metadata or values: points on its plausible plate with a velocity above the floor, or
    one InputFileError line naming the file; the file unchanged."""
    scan = read_or_refused("scan.csv", data, read_scan)
    if scan is None:
        return
    plate = scan.plate.plate()
    assert plate_problem(plate) is None and scan.velocity.max() >= MIN_PEAK_VELOCITY
    assert all(point_problem(plate, x, y) is None for x, y in zip(scan.x, scan.y))


# --- the run configuration's sections ------------------------------------------------------------

DEFAULTS = default_config()
config_values = st.one_of(
    st.integers(-(10**20), 10**20), st.floats(), st.booleans(), st.text(max_size=8),
    st.lists(st.one_of(st.floats(-1e3, 1e3), st.integers(-5, 500), st.text(max_size=4)), max_size=4),
)


def near(default):
    """Values like ``default``: mostly of its type and near it (so that some configurations are valid)."""
    if isinstance(default, bool):
        return st.booleans()
    if isinstance(default, int):
        return st.integers(-2 * abs(default) - 2, 2 * abs(default) + 2)
    if isinstance(default, float):
        return st.floats(-2 * abs(default) - 1.0, 2 * abs(default) + 1.0)
    if isinstance(default, list):
        return st.lists(near(default[0]) if default else st.text(max_size=6), min_size=len(default) > 0, max_size=4)
    return st.sampled_from(sorted({default, "paper", "PZT-5H", "eigenstrain", "coupled", "warn", "refuse", ""}))


@st.composite
def configurations(draw) -> dict:
    """A user configuration: a few keys of a few sections, each set to something like its default or to anything."""
    user = {}
    for section in draw(st.lists(st.sampled_from(sorted(DEFAULTS)), min_size=1, max_size=3, unique=True)):
        keys = draw(st.lists(st.sampled_from(sorted(DEFAULTS[section])), min_size=1, max_size=3, unique=True))
        user[section] = {key: draw(st.one_of(near(DEFAULTS[section][key]), config_values)) for key in keys}
    return user


@fuzz(user=configurations())
def test_a_configuration_is_refused_naming_its_file_or_checked_and_printed_as_toml_that_reads_back(user):
    """Any values in any section: one InputFileError naming the file; or a configuration whose numbers lie in their
    ranges and whose --print-config text is TOML that reads back to it."""
    try:
        config = merge(DEFAULTS, user, source="user.toml")
    except InputFileError as error:
        assert str(error).startswith("user.toml: ") and len(str(error).splitlines()) == 1, error
        return
    assert tomllib.loads(to_toml(config)) == config
    for key, (low, high) in LIMITS.items():
        section, _, name = key.partition(".")
        if name in config.get(section, {}):
            value = config[section][name]
            assert all(low <= item <= high for item in (value if isinstance(value, list) else [value])), key


# --- resuming a log after any hand edit ----------------------------------------------------------

RESUMED_PLAN = CampaignPlan(32126.0, span=600.0, points_per_sweep=7, voltages=(5.0, 10.0))
"""The plan of the corpus's campaign log (tests/data/hostile/resume/campaign/complete.csv)."""
RESUMED_LOG = (CORPUS / "resume" / "campaign" / "complete.csv").read_text(encoding="utf-8")
edits = st.lists(st.tuples(st.sampled_from(["repeat", "delete", "reformat", "move", "comment", "blank", "spoil"]),
                           st.integers(0, 20), st.integers(0, 20)), max_size=5)


def edited_log(actions, cut: int) -> tuple[str, bool]:
    """The campaign log with ``actions`` applied to its rows and ``cut`` characters taken off its end; and whether
    a row then holds a point of no plan (a frequency moved beyond the log's precision; an unterminated last line
    with its six fields is a row)."""
    lines = RESUMED_LOG.splitlines()
    header = lines.index(",".join(logformat.COLUMNS))
    head, rows = lines[: header + 1], lines[header + 1:]
    for action, i, j in actions:
        i, j = i % len(rows), j % len(rows)
        cells = rows[i].split(",")
        if action == "repeat":
            rows.insert(j, rows[i])
        elif action == "delete" and len(rows) > 1:
            rows.pop(i)
        elif action == "reformat" and not rows[i].startswith("#") and rows[i].strip():
            cells[0], cells[1], cells[3] = f"{float(cells[0]):.12e}", f"{float(cells[1]):.4f}", f"{float(cells[3]):.1f}"
            rows[i] = ",".join(cells)
        elif action == "move":
            rows.insert(j, rows.pop(i))
        elif action in ("comment", "blank"):
            rows.insert(j, "# a note" if action == "comment" else "")
        elif action == "spoil" and not rows[i].startswith("#") and rows[i].strip():
            cells[0] = repr(float(cells[0]) + 0.5)
            rows[i] = ",".join(cells)
    text = "\n".join(head + rows) + "\n"
    text = text[: len(text) - cut] if cut else text
    spoiled = any(line.split(",")[0] not in PLANNED_FREQUENCIES and _six_numbers(line)  # a last line cut in its
                  for line in text.splitlines()[header + 1:] if not line.startswith("#"))  # phase may still be a row
    return text, spoiled


def _six_numbers(line: str) -> bool:
    """Whether a line is a row: six fields, each a number or, in an optional column, empty (a last line cut to '-' in
    its phase is no row but a write cut short; cut to an empty phase it is a row without a phase)."""
    cells = line.split(",")
    if len(cells) != len(logformat.COLUMNS):
        return False
    try:
        return all(math.isfinite(float(cell)) for name, cell in zip(logformat.COLUMNS, cells)
                   if cell or name not in logformat.OPTIONAL_COLUMNS)
    except ValueError:
        return False


PLANNED_FREQUENCIES = {f"{point.frequency:.12g}" for point in RESUMED_PLAN.points()} | {
    f"{point.frequency:.12e}" for point in RESUMED_PLAN.points()}


def test_a_cut_note_keeps_its_spaces_when_the_resume_keeps_it_as_a_comment():
    """Found by the property below: a log cut inside a note ('# a ') resumed with the note kept as a comment but its
    trailing space dropped, so the log's bytes were no longer all kept."""
    text, spoiled = edited_log([("comment", 0, 12), ("delete", 0, 0), ("delete", 12, 0)], 40)
    assert text.endswith("# a ") and not spoiled
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "campaign.csv"
        path.write_text(text, encoding="utf-8")
        station, _ = simulated_station(default_bench_settings(), settle_time=0.0)
        q_campaign(station, path, RESUMED_PLAN, fsync=False)
        cut_at = text.rfind("\n") + 1
        assert path.read_text(encoding="utf-8").startswith(text[:cut_at] + INCOMPLETE_ROW + "# a \n")


@fuzz(actions=edits, cut=st.integers(0, 80))
def test_a_resume_after_any_edit_appends_only_the_missing_points_or_refuses_leaving_the_log(actions, cut):
    """Rows repeated, deleted, moved, reformatted, notes added, the end cut off: the resume appends exactly the
    planned points no row holds, after every byte of the log (a cut last line kept as a comment); a row moved off
    the plan makes it refuse in one line with the log byte for byte as it was."""
    text, spoiled = edited_log(actions, cut)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "campaign.csv"
        path.write_text(text, encoding="utf-8")
        before = read_log(path).rows
        station, _ = simulated_station(default_bench_settings(), settle_time=0.0)
        try:
            result = q_campaign(station, path, RESUMED_PLAN, fsync=False)
        except InputFileError as error:
            assert spoiled and str(path) in str(error) and len(str(error).splitlines()) == 1, error
            assert path.read_text(encoding="utf-8") == text
            return
        assert not spoiled
        after = path.read_bytes()
        cut_at = text.rfind("\n") + 1
        assert after.startswith(text.encode()) or after.startswith((text[:cut_at] + INCOMPLETE_ROW + text[cut_at:] + "\n").encode())
        planned = {point.key for point in RESUMED_PLAN.points()}
        held = {row_key(row) for row in before}
        assert result.measured == len(planned - held)
        assert planned <= {row_key(row) for row in read_log(path).rows}


# --- what the fuzzing found, kept as plain regression tests --------------------------------------

@pytest.mark.parametrize("data, reason", [
    (b"\r\x01", "line 1: a carriage return inside the line"),
    (b"frequency_hz,drive_voltage_v,velocity_m_s\r1,1,1\r", "line 1: a carriage return inside the line"),
    (b"frequency_hz,drive_voltage_v,velocity_m_s\n" + b"1" * 200_000 + b",1,1\n",
     "line 2: "),
    (b"\x01\x0b\x01", r"missing required column 'frequency_hz' (header: '\x01\x0b\x01')"),
])
def test_found_log_inputs_are_refused_in_one_line(data, reason):
    _, error = read_file_bytes(data)
    assert reason in str(error)


def test_found_driver_sequences_are_refused():
    device = GeneratorDevice(DRIVER_DEVICE_LIMIT)
    generator = FunctionGenerator(DevicePort(device), max_peak_voltage=0.0625)
    for command in ("OUTP?", "VOLT:OFFS?"):  # an unread reply would answer the next limit decision's query
        with pytest.raises(InstrumentError, match="a query's reply must be read"):
            generator.write(command)
    with pytest.raises(InstrumentError, match="not one line of printable ASCII"):
        generator.set("FREQ 1\u00b5")
    generator.reset()  # 0.1 Vpp into 50 ohm: 0.1 V peak, output off
    with pytest.raises(TactileError, match="exceeds the limit 0.0625 V"):
        generator.output = True
    assert not device.state.output and device.errors == []


@pytest.mark.parametrize("encoding, separator, reason", [
    ("utf-16", ",", "UTF-16 text, not UTF-8"),
    ("utf-8", ";", "line 1: fields separated by ';'; a log separates them by ','"),
    ("utf-8-sig", "\t", r"line 1: fields separated by '\t'"),
])
def test_a_spreadsheet_export_in_another_encoding_or_separator_is_named(encoding, separator, reason):
    text = separator.join(logformat.REQUIRED_COLUMNS) + "\n" + separator.join(["31000", "5", "0.1"]) + "\n"
    _, error = read_file_bytes(text.encode(encoding))
    assert reason in str(error)
