"""Simulated function generator: the 33500-series SCPI subset of docs/instruments.md, one channel.

State changes that would exceed the output's peak-voltage limit (amplitude/2 + |offset|)
are refused with ``-222,"Data out of range"`` in the error queue; the output keeps its
previous value (in burst mode as in continuous mode: a burst carries the set amplitude).

Burst mode (as PyMeasure's ``Agilent33500`` driver uses it): ``BURS:STAT``, ``BURS:MODE
TRIG|GAT``, ``BURS:NCYC``, ``BURS:INT:PER``, ``TRIG:SOUR IMM|EXT|BUS`` and ``*TRG``, with
their queries.  A triggered burst with the output on (``*TRG`` with the BUS source, or the
next readout with IMM) is reported to the bench through ``on_burst``.  An over-long line (-363) and a reply lost to a full output queue (-430)
are reported in the error queue too.
"""

from dataclasses import dataclass, replace

import numpy as np

from instruments.simulator.scpi import header_regex, split_program

IDENTITY = "Agilent Technologies,33521A,TACTILE-SIM,1.0-sim"
"""``*IDN?`` reply (manufacturer, model, serial, firmware), as the 33500 series formats it."""
MAX_ERRORS = 20
"""Depth of the error queue; further errors replace the last one with -350 (queue overflow)."""
FREQUENCY_RANGE = (1e-6, 20e6)
"""Sine frequency range [Hz]."""
AMPLITUDE_RANGE = (1e-3, 10.0)
"""Amplitude range of the output stage [V peak-to-peak]."""
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
"""Sine: V_rms / V_pp [-]."""


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

    @property
    def open_circuit_gain(self) -> float:
        """Terminal voltage into a high-impedance input (an amplifier) over the stated one [-]:
        (R_load + 50 ohm) / R_load, 1 for High Z, 2 for the default 50 ohm setting."""
        return 1.0 if np.isinf(self.load) else (self.load + SOURCE_IMPEDANCE) / self.load

    @property
    def peak_voltage(self) -> float:
        """Largest |output voltage| at the terminals into a high-impedance input,
        (amplitude/2 + |offset|) times :attr:`open_circuit_gain` [V]."""
        return (self.amplitude_vpp / 2 + abs(self.offset)) * self.open_circuit_gain

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

    def __init__(self, peak_voltage_limit: float, on_burst=None):
        self.peak_voltage_limit = peak_voltage_limit
        self.on_burst = on_burst
        self.state = GeneratorState()
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
        self.state = candidate

    def _identify(self, argument):
        return IDENTITY

    def _reset(self, argument):
        self.state = GeneratorState()

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
