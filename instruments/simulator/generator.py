"""Simulated function generator: the 33500-series SCPI subset of docs/instruments.md, one channel.

State changes that would exceed the output's peak-voltage limit (amplitude/2 + |offset|)
are refused with ``-222,"Data out of range"`` in the error queue; the output keeps its
previous value (in burst mode as in continuous mode: a burst carries the set amplitude).

Burst mode (as PyMeasure's ``Agilent33500`` driver uses it): ``BURS:STAT``, ``BURS:MODE
TRIG|GAT``, ``BURS:NCYC``, ``BURS:INT:PER``, ``TRIG:SOUR IMM|EXT|BUS`` and ``*TRG``, with
their queries.  A triggered burst with the output on (``*TRG`` with the BUS source, or the
next readout with IMM) is reported to the bench through ``on_burst``.  An over-long line (-363) and a reply lost to a full output queue (-430)
are reported in the error queue too.

Arbitrary waveforms and amplitude modulation (docs/rendering.md#on-the-generator): ``DATA:ARB``
(values -1 to +1) and ``DATA:ARB:DAC`` (codes -32767 to +32767) into volatile memory,
``DATA:VOL:CLE``, ``DATA:VOL:CAT?``, ``FUNC:ARB``, ``FUNC:ARB:SRAT``, ``FUNC:ARB:FILT``, and
``AM:STAT``, ``AM:SOUR INT``, ``AM:INT:FUNC``, ``AM:INT:FREQ``, ``AM:DEPT``.  With AM on, the carrier's
amplitude is scaled by (1 + d m(t)) / 2, d the depth and m the modulating waveform (-1 to +1);
a depth above 100 % raises the output's peak above the carrier amplitude, and the peak-voltage
limit counts it.  Every change of the output (state or waveform data) is reported to the bench
through ``on_change`` (the modulated plate starts from it).
"""

from dataclasses import dataclass, replace

import numpy as np

from instruments.drivers.arbitrary import DAC_FULL_SCALE, MIN_POINTS, NAME, SAMPLE_RATE_RANGE
from instruments.drivers.generator import AMPLITUDE_RANGE, FREQUENCY_RANGE
from instruments.simulator.scpi import header_regex, split_program

IDENTITY = "Agilent Technologies,33521A,TACTILE-SIM,1.0-sim"
"""``*IDN?`` reply (manufacturer, model, serial, firmware), as the 33500 series formats it."""
MAX_ERRORS = 20
"""Depth of the error queue; further errors replace the last one with -350 (queue overflow)."""
FUNCTIONS = ("SIN", "SQU", "TRI", "RAMP", "PULS", "PRBS", "NOIS", "ARB", "DC")
FUNCTION_LONG_FORMS = {"SINUSOID": "SIN", "SQUARE": "SQU", "TRIANGLE": "TRI", "PULSE": "PULS", "NOISE": "NOIS"}
NO_ERROR = '+0,"No error"'
SOURCE_IMPEDANCE = 50.0
"""Output impedance of the generator [ohm]."""
LOAD_RANGE = (1.0, 10e3)
"""Settable load resistances [ohm]; ``INF`` (High Z) is also accepted."""
DEFAULT_LOAD = 50.0
"""Load setting after power-on and ``*RST`` [ohm] (as the 33500 series)."""
HIGH_Z_REPLY = 9.9e37
"""What ``OUTP:LOAD?`` answers for the High Z (infinite) setting."""
VRMS_PER_VPP = 1 / (2 * np.sqrt(2))
BURST_CYCLES_RANGE = (1, 100_000_000)
"""Cycles per burst accepted by ``BURS:NCYC`` [-]."""
BURST_PERIOD_RANGE = (1e-6, 8000.0)
"""Internal burst period accepted by ``BURS:INT:PER`` [s]."""
AM_DEPTH_RANGE = (0.0, 120.0)
"""``AM:DEPT`` range [%]: above 100 % the output's peak exceeds the carrier amplitude."""
AM_FREQUENCY_RANGE = (1e-6, 1e6)
"""``AM:INT:FREQ`` range [Hz]."""
AM_FUNCTIONS = {"SIN": "SIN", "SINUSOID": "SIN", "SQU": "SQU", "SQUARE": "SQU", "TRI": "TRI", "TRIANGLE": "TRI",
                "RAMP": "RAMP", "NRAM": "NRAM", "NRAMP": "NRAM", "ARB": "ARB"}
"""Modulating shapes of ``AM:INT:FUNC`` the simulator plays (NOISe and PRBS are refused)."""
ARB_POINTS_RANGE = (MIN_POINTS, 1_000_000)
"""Points of an arbitrary waveform in volatile memory [-]."""
ARB_FILTERS = {"NORM": "NORM", "NORMAL": "NORM", "STEP": "STEP", "OFF": "OFF"}
MODULATION_SAMPLES = 256
"""Samples per period of a standard modulating shape (SIN, SQU, ...) as the simulator plays it [-]."""


@dataclass(frozen=True)
class GeneratorState:
    """What the output produces.

    Attributes
    ----------
    function : str
    frequency : float
        [Hz]
    amplitude_vpp : float
        [V peak-to-peak]
    unit : str
        ``VPP`` or ``VRMS``: the unit of ``VOLT`` and ``VOLT?``.
    offset : float
        [V]
    output : bool
    load : float
        Load setting [ohm] (``inf``: High Z): amplitude and offset are stated into this load.
    """

    function: str = "SIN"
    frequency: float = 1000.0
    amplitude_vpp: float = 0.1
    unit: str = "VPP"
    offset: float = 0.0
    output: bool = False
    load: float = DEFAULT_LOAD
    burst: bool = False
    burst_mode: str = "TRIG"
    burst_cycles: int = 1
    burst_period: float = 0.01
    trigger_source: str = "IMM"
    am: bool = False
    am_function: str = "SIN"
    am_frequency: float = 100.0
    am_depth: float = 100.0
    arb: str | None = None
    arb_sample_rate: float = 40e3
    arb_filter: str = "STEP"

    @property
    def modulation_peak(self) -> float:
        """Largest envelope factor (1 + d m) / 2 over m in [-1, 1] with AM on, at least 1 [-]."""
        return max(1.0, (1 + self.am_depth / 100) / 2) if self.am else 1.0

    @property
    def open_circuit_gain(self) -> float:
        """Terminal voltage into a high-impedance input (an amplifier) over the stated one [-]:
        (R_load + 50 ohm) / R_load, 1 for High Z, 2 for the default 50 ohm setting."""
        return 1.0 if np.isinf(self.load) else (self.load + SOURCE_IMPEDANCE) / self.load

    @property
    def peak_voltage(self) -> float:
        """Largest |output voltage| at the terminals into a high-impedance input,
        (amplitude/2 x :attr:`modulation_peak` + |offset|) times :attr:`open_circuit_gain` [V]."""
        return (self.amplitude_vpp / 2 * self.modulation_peak + abs(self.offset)) * self.open_circuit_gain

    @property
    def terminal_amplitude_vpp(self) -> float:
        """Amplitude at the terminals into a high-impedance input [V peak-to-peak]."""
        return self.amplitude_vpp * self.open_circuit_gain


class CommandError(Exception):
    """A SCPI error: code and message for the error queue."""

    def __init__(self, code: int, message: str):
        super().__init__(f'{code:+d},"{message}"')
        self.code = code


def _number(argument: str) -> float:
    try:
        value = float(argument)
    except ValueError:
        raise CommandError(-104, "Data type error") from None
    if not np.isfinite(value):
        raise CommandError(-224, "Illegal parameter value")
    return value


def _format(value: float) -> str:
    return f"{value:+.14E}"


def _channel(suffix: str | None) -> None:
    if suffix not in (None, "", "1"):
        raise CommandError(-114, "Header suffix out of range")


QUERY_ONLY = frozenset({"query"})
"""Forms of a header that is only a query (``*IDN?``): its command form is an undefined header."""
EVENT = frozenset({"event"})
"""Forms of a command without a parameter and without a query (``*RST``): ``*RST?`` is an undefined header."""
SETTING = frozenset({"setting", "query"})
"""Forms of a setting: ``FREQ 1000`` (a parameter is required) and ``FREQ?``."""


def _form_error(form: str, forms: frozenset) -> CommandError:
    """The 33500's error for a header used in a ``form`` it does not have (-113, -108 or -109)."""
    if form == "query" or forms == QUERY_ONLY:
        return CommandError(-113, "Undefined header")
    if form == "setting":
        return CommandError(-108, "Parameter not allowed")
    return CommandError(-109, "Missing parameter")


class GeneratorDevice:
    """The generator's command interpreter and state.

    Parameters
    ----------
    peak_voltage_limit : float
        Largest output peak voltage accepted, amplitude/2 + |offset| [V]: the safety limit
        translated through the amplifier gain.
    """

    def __init__(self, peak_voltage_limit: float, on_burst=None, on_change=None):
        self.peak_voltage_limit = peak_voltage_limit
        self.on_burst = on_burst
        self.on_change = on_change
        self.state = GeneratorState()
        self.arbs: dict[str, np.ndarray] = {}
        """Waveforms in volatile memory: name (upper case) -> values in [-1, 1]."""
        self.errors: list[str] = []
        self._commands = [
            (header_regex(pattern), handler, forms)
            for pattern, handler, forms in (
                ("*IDN", self._identify, QUERY_ONLY),
                ("*RST", self._reset, EVENT),
                ("*CLS", self._clear, EVENT),
                ("*OPC", self._operation_complete, EVENT | {"query"}),
                ("*WAI", self._wait, EVENT),
                ("*TRG", self._trigger, EVENT),
                ("[SOURce#:]BURSt:STATe", self._burst_state, SETTING),
                ("[SOURce#:]BURSt:MODE", self._burst_mode, SETTING),
                ("[SOURce#:]BURSt:NCYCles", self._burst_cycles, SETTING),
                ("[SOURce#:]BURSt:INTernal:PERiod", self._burst_period, SETTING),
                ("TRIGger#:SOURce", self._trigger_source, SETTING),
                ("SYSTem:ERRor[:NEXT]", self._next_error, QUERY_ONLY),
                ("[SOURce#:]FUNCtion[:SHAPe]", self._function, SETTING),
                ("[SOURce#:]FREQuency[:CW]", self._frequency, SETTING),
                ("[SOURce#:]VOLTage:UNIT", self._unit, SETTING),
                ("[SOURce#:]VOLTage[:LEVel][:IMMediate]:OFFSet", self._offset, SETTING),
                ("[SOURce#:]VOLTage[:LEVel][:IMMediate][:AMPLitude]", self._amplitude, SETTING),
                ("OUTPut#:LOAD", self._load, SETTING),
                ("OUTPut#[:STATe]", self._output, SETTING),
                ("[SOURce#:]FUNCtion:ARBitrary", self._arb_select, SETTING),
                ("[SOURce#:]FUNCtion:ARBitrary:SRATe", lambda argument: self._number_setting(
                    argument, "arb_sample_rate", SAMPLE_RATE_RANGE), SETTING),
                ("[SOURce#:]FUNCtion:ARBitrary:FILTer", lambda argument: self._choice_setting(
                    argument, "arb_filter", ARB_FILTERS), SETTING),
                ("[SOURce#:]DATA:ARBitrary#", lambda argument: self._arb_data(argument, dac=False), frozenset({"setting"})),
                ("[SOURce#:]DATA:ARBitrary#:DAC", lambda argument: self._arb_data(argument, dac=True), frozenset({"setting"})),
                ("[SOURce#:]DATA:VOLatile:CLEar", self._volatile_clear, EVENT),
                ("[SOURce#:]DATA:VOLatile:CATalog", self._volatile_catalog, QUERY_ONLY),
                ("[SOURce#:]AM:STATe", self._am_state, SETTING),
                ("[SOURce#:]AM:SOURce", self._am_source, SETTING),
                ("[SOURce#:]AM:INTernal:FUNCtion", self._am_function, SETTING),
                ("[SOURce#:]AM:INTernal:FREQuency", lambda argument: self._number_setting(
                    argument, "am_frequency", AM_FREQUENCY_RANGE), SETTING),
                ("[SOURce#:]AM[:DEPTh]", lambda argument: self._number_setting(argument, "am_depth", AM_DEPTH_RANGE), SETTING),
            )
        ]

    def handle_line(self, line: str) -> str | None:
        """Execute one program line; the reply line (queries joined by ``;``) or None."""
        replies = []
        for header, argument in split_program(line):
            try:
                reply = self._dispatch(header if header.startswith(":") else ":" + header, argument)
            except CommandError as error:
                self._push_error(str(error))
                break
            if reply is not None:
                replies.append(reply)
        return ";".join(replies) if replies else None

    def _dispatch(self, header: str, argument: str):
        for regex, handler, forms in self._commands:
            match = regex.fullmatch(header)
            if match:
                *suffixes, query = match.groups()
                form = "query" if query else "setting" if argument else "event"
                if form not in forms:
                    raise _form_error(form, forms)
                if query and argument:
                    raise CommandError(-108, "Parameter not allowed")
                for suffix in suffixes:
                    _channel(suffix)
                return handler(argument if not query else None)
        raise CommandError(-113, "Undefined header")

    def input_overrun(self) -> None:
        """A command line overran the input buffer and was discarded: -363 in the error queue."""
        self._push_error(str(CommandError(-363, "Input buffer overrun")))

    def reply_lost(self) -> None:
        """A reply found the output queue full (queries sent without reading): -430 in the error queue."""
        self._push_error(str(CommandError(-430, "Query DEADLOCKED")))

    def _push_error(self, error: str) -> None:
        if len(self.errors) < MAX_ERRORS:
            self.errors.append(error)
        else:
            self.errors[-1] = '-350,"Queue overflow"'

    def _apply(self, **changes) -> None:
        candidate = replace(self.state, **changes)
        if candidate.peak_voltage > self.peak_voltage_limit + 1e-12:
            raise CommandError(-222, "Data out of range")
        if candidate != self.state:
            self.state = candidate
            self._changed()

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change()

    def _identify(self, argument):
        return IDENTITY

    def _reset(self, argument):
        self.state = GeneratorState()
        self._changed()

    def _clear(self, argument):
        self.errors.clear()

    def _operation_complete(self, argument):
        return "1" if argument is None else None

    def _next_error(self, argument):
        return self.errors.pop(0) if self.errors else NO_ERROR

    def _function(self, argument):
        if argument is None:
            return self.state.function
        name = argument.upper()
        name = FUNCTION_LONG_FORMS.get(name, name)
        if name not in FUNCTIONS:
            raise CommandError(-224, "Illegal parameter value")
        self._apply(function=name)

    def _frequency(self, argument):
        if argument is None:
            return _format(self.state.frequency)
        value = _number(argument)
        if not FREQUENCY_RANGE[0] <= value <= FREQUENCY_RANGE[1]:
            raise CommandError(-222, "Data out of range")
        self._apply(frequency=value)

    def _unit(self, argument):
        if argument is None:
            return self.state.unit
        unit = argument.upper()
        if unit not in ("VPP", "VRMS"):
            raise CommandError(-224, "Illegal parameter value")
        self._apply(unit=unit)

    def _amplitude(self, argument):
        per_vpp = VRMS_PER_VPP if self.state.unit == "VRMS" else 1.0
        if argument is None:
            return _format(self.state.amplitude_vpp * per_vpp)
        value = _number(argument) / per_vpp
        if not AMPLITUDE_RANGE[0] <= value <= AMPLITUDE_RANGE[1]:
            raise CommandError(-222, "Data out of range")
        self._apply(amplitude_vpp=value)

    def _offset(self, argument):
        if argument is None:
            return _format(self.state.offset)
        self._apply(offset=_number(argument))

    def _output(self, argument):
        if argument is None:
            return "1" if self.state.output else "0"
        states = {"1": True, "ON": True, "0": False, "OFF": False}
        if argument.upper() not in states:
            raise CommandError(-224, "Illegal parameter value")
        self._apply(output=states[argument.upper()])

    def _load(self, argument):
        if argument is None:
            return _format(HIGH_Z_REPLY if np.isinf(self.state.load) else self.state.load)
        word = argument.strip().upper()
        named = {"INF": np.inf, "INFINITY": np.inf, "MIN": LOAD_RANGE[0], "MINIMUM": LOAD_RANGE[0],
                 "MAX": LOAD_RANGE[1], "MAXIMUM": LOAD_RANGE[1], "DEF": DEFAULT_LOAD, "DEFAULT": DEFAULT_LOAD}
        value = named[word] if word in named else _number(argument)
        if not (np.isinf(value) or LOAD_RANGE[0] <= value <= LOAD_RANGE[1]):
            raise CommandError(-222, "Data out of range")
        self._apply(load=value)

    def _wait(self, argument):
        """``*WAI``: commands run in order here, so there is nothing to wait for."""

    def bursting(self) -> bool:
        """Whether the output emits triggered bursts (burst on, triggered mode, output on, a sine)."""
        state = self.state
        return state.burst and state.burst_mode == "TRIG" and state.output and state.function == "SIN"

    def _trigger(self, argument):
        if self.state.trigger_source == "BUS" and self.bursting() and self.on_burst is not None:
            self.on_burst()

    def _burst_state(self, argument):
        if argument is None:
            return "1" if self.state.burst else "0"
        states = {"1": True, "ON": True, "0": False, "OFF": False}
        if argument.upper() not in states:
            raise CommandError(-224, "Illegal parameter value")
        self._apply(burst=states[argument.upper()])

    def _burst_mode(self, argument):
        if argument is None:
            return self.state.burst_mode
        modes = {"TRIG": "TRIG", "TRIGGERED": "TRIG", "GAT": "GAT", "GATED": "GAT"}
        if argument.upper() not in modes:
            raise CommandError(-224, "Illegal parameter value")
        self._apply(burst_mode=modes[argument.upper()])

    def _burst_cycles(self, argument):
        if argument is None:
            return _format(self.state.burst_cycles)
        value = _number(argument)
        if value != round(value) or not BURST_CYCLES_RANGE[0] <= value <= BURST_CYCLES_RANGE[1]:
            raise CommandError(-222, "Data out of range")
        self._apply(burst_cycles=int(value))

    def _burst_period(self, argument):
        if argument is None:
            return _format(self.state.burst_period)
        value = _number(argument)
        if not BURST_PERIOD_RANGE[0] <= value <= BURST_PERIOD_RANGE[1]:
            raise CommandError(-222, "Data out of range")
        self._apply(burst_period=value)

    def _trigger_source(self, argument):
        if argument is None:
            return self.state.trigger_source
        sources = {"IMM": "IMM", "IMMEDIATE": "IMM", "EXT": "EXT", "EXTERNAL": "EXT", "BUS": "BUS"}
        if argument.upper() not in sources:
            raise CommandError(-224, "Illegal parameter value")
        self._apply(trigger_source=sources[argument.upper()])

    def modulation(self) -> tuple[np.ndarray, float] | None:
        """The modulating waveform as played: (values in [-1, 1] held over each sample, sample rate [Sa/s]),
        or None when the output is not an amplitude-modulated sine."""
        state = self.state
        if not (state.output and state.am and state.function == "SIN"):
            return None
        if state.am_function == "ARB":
            return self.arbs[state.arb], state.arb_sample_rate
        phase = (np.arange(MODULATION_SAMPLES) + 0.5) / MODULATION_SAMPLES
        shapes = {"SIN": np.sin(2 * np.pi * phase), "SQU": np.where(phase < 0.5, 1.0, -1.0),
                  "TRI": 1 - 4 * np.abs(np.mod(phase + 0.25, 1.0) - 0.5), "RAMP": 2 * phase - 1, "NRAM": 1 - 2 * phase}
        return shapes[state.am_function], MODULATION_SAMPLES * state.am_frequency

    def _arb_data(self, argument, dac: bool):
        name, _, values = argument.partition(",")
        name = _arb_name(name)
        if name in self.arbs:
            raise CommandError(-221, "Settings conflict")
        try:
            numbers = np.array([float(item) for item in values.split(",")])
        except ValueError:
            raise CommandError(-104, "Data type error") from None
        scale = DAC_FULL_SCALE if dac else 1.0
        if dac and not np.all(numbers == np.round(numbers)):
            raise CommandError(-104, "Data type error")
        if not (ARB_POINTS_RANGE[0] <= len(numbers) <= ARB_POINTS_RANGE[1] and np.all(np.abs(numbers) <= scale)):
            raise CommandError(-222, "Data out of range")
        self.arbs[name] = numbers / scale
        self._changed()

    def _volatile_clear(self, argument):
        if self.state.am and self.state.am_function == "ARB":
            raise CommandError(-221, "Settings conflict")
        self.arbs.clear()
        self._apply(arb=None)

    def _volatile_catalog(self, argument):
        return ",".join(f'"{name}"' for name in self.arbs) or '""'

    def _arb_select(self, argument):
        if argument is None:
            return f'"{self.state.arb or ""}"'
        name = _arb_name(argument)
        if name not in self.arbs:
            raise CommandError(-224, "Illegal parameter value")
        self._apply(arb=name)

    def _am_state(self, argument):
        if argument is None:
            return "1" if self.state.am else "0"
        states = {"1": True, "ON": True, "0": False, "OFF": False}
        if argument.upper() not in states:
            raise CommandError(-224, "Illegal parameter value")
        if states[argument.upper()] and self.state.am_function == "ARB" and self.state.arb is None:
            raise CommandError(-221, "Settings conflict")
        self._apply(am=states[argument.upper()])

    def _am_source(self, argument):
        if argument is None:
            return "INT"
        if argument.upper() not in ("INT", "INTERNAL"):
            raise CommandError(-224, "Illegal parameter value")

    def _am_function(self, argument):
        if argument is not None and AM_FUNCTIONS.get(argument.upper()) == "ARB" and self.state.am and self.state.arb is None:
            raise CommandError(-221, "Settings conflict")
        return self._choice_setting(argument, "am_function", AM_FUNCTIONS)

    def _number_setting(self, argument, field: str, bounds: tuple):
        """Query a number of the state, or set it within ``bounds`` (-222 outside)."""
        if argument is None:
            return _format(getattr(self.state, field))
        value = _number(argument)
        if not bounds[0] <= value <= bounds[1]:
            raise CommandError(-222, "Data out of range")
        self._apply(**{field: value})

    def _choice_setting(self, argument, field: str, choices: dict):
        """Query a word of the state, or set it to ``choices[ARGUMENT]`` (-224 for anything else)."""
        if argument is None:
            return getattr(self.state, field)
        if argument.upper() not in choices:
            raise CommandError(-224, "Illegal parameter value")
        self._apply(**{field: choices[argument.upper()]})


def _arb_name(text: str) -> str:
    """A waveform name from a command's argument (quotes optional), upper case; -224 if not a valid name."""
    name = text.strip().strip('"').strip("'")
    if not NAME.fullmatch(name):
        raise CommandError(-224, "Illegal parameter value")
    return name.upper()
