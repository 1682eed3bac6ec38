"""Envelope captures through the lock-in's capture buffer: the one place an envelope is recorded.

A capture records R and theta (``CAPTURECFG 2``) at one of the SR860's rates, 2^k / 1.25 MHz apart,
from the trigger on the lock-in's TRIG IN (the generator's trigger output: a burst's start, a
modulation period's start).  The reference is the lock-in's internal oscillator at the drive
frequency (a burst stops the generator's sync), the output filter 24 dB/oct with the longest time
constant at most a quarter of the interval (:func:`~instruments.drivers.lockin.capture_time_constant`):
the filter delays the envelope by 4 TC, which the sample times account for, and forgets a kink in it
(a burst's end) after 10 TC.  A :class:`CaptureWindow` says which samples a procedure keeps; their
times are known before anything is sent, so a plan's log keys are.  An input overloaded during the
capture (``LIAS?`` bit 4) steps the decoder range up and captures again.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from instruments.drivers.errors import InstrumentError
from instruments.drivers.lockin import (
    BYTES_PER_VALUE,
    CAPTURE_FILTER_POLES,
    CAPTURE_GET_KB,
    CAPTURE_LENGTH_KB,
    CAPTURE_MAX_RATE_EXPONENT,
    CAPTURE_SETTLE_CONSTANTS,
    INPUT_RANGES,
    OVERLOAD_INPUT,
    SENSITIVITIES,
    capture_delay,
    capture_interval,
    capture_time_constant,
    is_capture_interval,
)
from instruments.procedures.sweeps import PlanError, Station

CAPTURE_POLLS = 20
"""Most ``CAPTURESTAT?`` polls while a capture finishes [-]."""
VALUES_PER_SAMPLE = 2
"""R and theta."""
CAPTURE_INPUT_RANGE = INPUT_RANGES[0]
"""The lock-in's input range during a capture [V peak] (the decoder range keeps the signal below it)."""
CAPTURE_SENSITIVITY = SENSITIVITIES[0]
"""The lock-in's sensitivity during a capture, held fixed [V rms full scale]."""


@dataclass(frozen=True)
class EnvelopeRecord:
    """A captured envelope.

    Attributes
    ----------
    time : numpy.ndarray
        The samples' times on the procedure's clock (since a burst's end, since a loop's start) [s].
    amplitude : numpy.ndarray
        Envelope (peak velocity at the laser spot) [m/s].
    """

    time: np.ndarray
    amplitude: np.ndarray


@dataclass(frozen=True)
class CaptureWindow:
    """``samples`` samples ``interval`` apart, the first the ``first``-th after the trigger.

    Attributes
    ----------
    interval : float
        A capture interval, 2^k / 1.25 MHz [s].
    first : int
        Index of the first sample kept [-].
    samples : int
    """

    interval: float
    first: int
    samples: int

    def __post_init__(self):
        if not is_capture_interval(self.interval):
            raise PlanError(f"{self.interval * 1e6:g} us is not a capture interval of the lock-in (2^k x 0.8 us; nearest "
                            f"{capture_interval(self.interval) * 1e6:g} us)")
        if not 2 <= self.samples:
            raise PlanError(f"a capture keeps at least 2 samples, got {self.samples}")
        if self.length_kb > CAPTURE_LENGTH_KB[1]:
            raise PlanError(f"{self.first + self.samples} samples of {self.interval * 1e6:g} us do not fit the lock-in's "
                            f"{CAPTURE_LENGTH_KB[1]} kB capture buffer")

    @classmethod
    def after(cls, interval: float, start: float, samples: int) -> "CaptureWindow":
        """The window whose first sample is the first whose delay-corrected time after the trigger is at least
        ``start`` [s]."""
        return cls(interval, math.ceil((start + capture_delay(interval)) / interval - 1e-9), samples)

    @classmethod
    def after_kink(cls, interval: float, kink: float, samples: int) -> "CaptureWindow":
        """The window starting once the filter has forgotten a kink of the signal at ``kink`` [s] after the trigger."""
        settled = kink + CAPTURE_SETTLE_CONSTANTS * capture_time_constant(interval)
        return cls(interval, math.ceil(settled / interval - 1e-9), samples)

    @property
    def time_constant(self) -> float:
        return capture_time_constant(self.interval)

    def times(self) -> np.ndarray:
        """The kept samples' times after the trigger, less the filter's delay [s]."""
        return (self.first + np.arange(self.samples)) * self.interval - capture_delay(self.interval)

    @property
    def length_kb(self) -> int:
        """Capture length holding every sample up to the last kept one [kB], even (as the SR860 takes it)."""
        kb = math.ceil((self.first + self.samples) * VALUES_PER_SAMPLE * BYTES_PER_VALUE / 1024)
        return kb + kb % 2


def capture_settings(window: CaptureWindow) -> dict:
    """The lock-in's settings during a capture (what :func:`prepare_capture` sets), for a log's metadata: they replace
    those of the sweep readout (:meth:`~instruments.procedures.readout.Readout.describe`), which a capture does not
    use."""
    return {"lockin_reference": "INT at the drive frequency", "lockin_time_constant_s": window.time_constant,
            "lockin_filter_db_oct": 6 * CAPTURE_FILTER_POLES, "lockin_input_range_v": CAPTURE_INPUT_RANGE,
            "lockin_sensitivity_v": CAPTURE_SENSITIVITY, "lockin_capture_interval_s": window.interval,
            "lockin_settle_s": "none: a capture starts at the trigger",
            "ranging": "decoder range per burst (stepped up and the burst fired again on an overload); lock-in fixed"}


def prepare_capture(station: Station, window: CaptureWindow, frequency: float) -> int:
    """Set the lock-in up for ``window`` at the drive ``frequency`` [Hz]: internal reference there, the window's time
    constant and a 24 dB/oct filter, the 1 V input range; returns the ``CAPTURERATE`` exponent giving its interval.

    Raises
    ------
    InstrumentError
        The lock-in cannot capture at the window's interval with that time constant.
    """
    lockin = station.lockin
    lockin.write("*CLS")
    lockin.reference_source = "INT"
    lockin.frequency = frequency
    lockin.time_constant = window.time_constant
    lockin.filter_poles = CAPTURE_FILTER_POLES
    lockin.input_range = CAPTURE_INPUT_RANGE
    lockin.sensitivity = CAPTURE_SENSITIVITY
    lockin.check_status(f"configuring a capture at {frequency:.9g} Hz")
    exponent = round(math.log2(lockin.capture_max_rate * window.interval))
    if not 0 <= exponent <= CAPTURE_MAX_RATE_EXPONENT:
        raise InstrumentError(f"{lockin.name} cannot capture every {window.interval * 1e6:g} us at a "
                              f"{window.time_constant * 1e6:g} us time constant (its fastest rate: "
                              f"{lockin.capture_max_rate:g} Sa/s)")
    return exponent


def _read_capture(station: Station, window: CaptureWindow) -> np.ndarray:
    """R [V rms] of the window's samples, read from the stopped capture in blocks."""
    sample_bytes = VALUES_PER_SAMPLE * BYTES_PER_VALUE
    first_kb = window.first * sample_bytes // 1024
    values = []
    for offset in range(first_kb, window.length_kb, CAPTURE_GET_KB):
        values.extend(station.lockin.capture_block(offset, min(CAPTURE_GET_KB, window.length_kb - offset)))
    samples = np.asarray(values, dtype=float).reshape(-1, VALUES_PER_SAMPLE)
    start = window.first - first_kb * 1024 // sample_bytes
    magnitude = samples[start:start + window.samples, 0]
    if magnitude.shape != (window.samples,) or not np.all(np.isfinite(magnitude) & (magnitude >= 0)):
        raise InstrumentError(f"{station.lockin.name}: the capture holds no valid R for the {window.samples} samples "
                              f"from sample {window.first}")
    return magnitude


def capture_envelope(station: Station, window: CaptureWindow, exponent: int, arm: Callable | None = None,
                     clock_offset: float = 0.0) -> EnvelopeRecord:
    """Capture ``window`` (rate exponent from :func:`prepare_capture`): arm the lock-in, ``arm()`` (e.g. fire a burst),
    wait for the capture and read it; an input overload steps the decoder range up and captures again.  The times are
    the window's, less ``clock_offset`` [s]."""
    readout, lockin = station.readout, station.lockin
    while True:
        lockin.latched_status
        lockin.start_capture("RT", exponent, window.length_kb)
        if arm is not None:
            arm()
        station.sleep((window.first + window.samples) * window.interval)
        for _ in range(CAPTURE_POLLS):
            status = lockin.capture_status
            if status & 2 and not status & 1:  # triggered, no longer recording
                break
            station.sleep(window.samples * window.interval / 4)
        else:
            raise InstrumentError(f"{lockin.name}: the capture did not finish (no trigger on TRIG IN?)")
        if not lockin.latched_status & OVERLOAD_INPUT:
            break
        larger = [r for r in readout.ranges if r > readout.range]
        if not larger:
            raise InstrumentError(f"{lockin.name} input overloaded during a capture on the decoder's largest range "
                                  f"{readout.range * 1e3:g} mm/s/V")
        readout.set_range(larger[0])
    magnitude = _read_capture(station, window)
    readout.used_ranges.add(readout.range)
    return EnvelopeRecord(window.times() - clock_offset, math.sqrt(2) * magnitude * readout.range)
