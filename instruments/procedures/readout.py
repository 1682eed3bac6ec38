"""The velocity readout: the vibrometer's decoder output read by the lock-in, ranged, settled and converted to m/s.

The decoder puts out velocity / range [V]; the lock-in, referenced to the generator's sync, reads its
component at the drive frequency as R [V rms] and theta.  So

    v = sqrt(2) R range,     phase = theta + 360 f tau_d

with tau_d the decoder's signal delay (its output lags the surface; ``Get,VeloDec,1,SignalDelay``).
A reading is taken once the lock-in's output filter has settled to 1e-3 after the last change of the
drive or of the decoder range (:func:`~instruments.drivers.lockin.settle_time`).  Ranging starts on the
decoder's largest range (nothing overloads there).  An input overload (the decoder output beyond the
lock-in's 1 V input range, or the decoder's own clip) steps the decoder range up; an output overload
steps the sensitivity up; a reading a smaller range would hold with 25 % headroom moves to that
range; each time the reading is taken again (the noise floor scales with the range), and the
sensitivity follows (the smallest above 1.25 R).  Overloads that ranging cannot clear (the largest
range overloaded) are an :class:`InstrumentError`.
"""

import math
from dataclasses import dataclass

from instruments.drivers.errors import InstrumentError
from instruments.drivers.lockin import (
    INPUT_RANGES,
    OVERLOAD_INPUT,
    OVERLOAD_OUTPUT,
    OVERLOAD_UNLOCKED,
    SENSITIVITIES,
    TEMPERATURE_SENSOR_SCALE,
    TIME_CONSTANTS,
    LockIn,
    nearest_index,
    settle_time,
)
from instruments.drivers.vibrometer import Vibrometer

DEFAULT_TIME_CONSTANT = 0.03
"""Lock-in time constant of the sweeps and the hold [s] (>= 10 Q / (pi f) of any tactile plate)."""
DEFAULT_FILTER_POLES = 4
"""Output filter of the readout: 24 dB/oct."""
SETTLE_TOLERANCE = 1e-3
"""A reading is taken once a step has settled to this fraction [-]."""
HEADROOM = 1.25
"""A range is used only if its full scale exceeds the last reading by this factor [-]."""
INPUT_RANGE = INPUT_RANGES[0]
"""The lock-in's input range of the readout [V peak] (the decoder range keeps the signal below it)."""
RANGING_STEPS = 12
"""Most readings of one point while ranging (every decoder range and sensitivity step included) [-]."""


@dataclass(frozen=True)
class VelocityReading:
    """One settled reading at the drive frequency.

    Attributes
    ----------
    amplitude : float
        Peak velocity amplitude at the laser spot [m/s].
    phase_deg : float
        Phase of the velocity relative to the drive, the decoder's delay removed [deg].
    """

    amplitude: float
    phase_deg: float


def wrap_degrees(angle: float) -> float:
    """``angle`` [deg] in (-180, 180]."""
    return -((-angle + 180.0) % 360.0 - 180.0)


class Readout:
    """The vibrometer controller and the lock-in as one velocity meter.

    Parameters
    ----------
    vibrometer : Vibrometer
    lockin : LockIn
    time_constant : float
        Lock-in time constant [s] (the nearest SR860 value is used).
    temperature_aux : int or None
        Aux In (1-4) carrying the plate temperature sensor (:data:`~instruments.drivers.lockin.TEMPERATURE_SENSOR_SCALE`), or None.
    """

    def __init__(self, vibrometer: Vibrometer, lockin: LockIn, time_constant: float = DEFAULT_TIME_CONSTANT,
                 temperature_aux: int | None = None):
        self.vibrometer = vibrometer
        self.lockin = lockin
        self.time_constant = TIME_CONSTANTS[nearest_index(TIME_CONSTANTS, time_constant)]
        self.temperature_aux = temperature_aux
        self.ranges: list[float] = []
        self.range = None
        self.sensitivity = None
        self.delay = 0.0
        self.used_ranges: set = set()
        """Decoder ranges of the readings and captures taken [m/s/V]."""
        self.used_sensitivities: set = set()
        """Lock-in sensitivities of the readings taken [V]."""

    @property
    def settle(self) -> float:
        """Wait after a change before a reading [s]."""
        return settle_time(self.time_constant, DEFAULT_FILTER_POLES, SETTLE_TOLERANCE)

    def describe(self) -> dict:
        """Identity strings and settings for a log's metadata (queried, nothing set)."""
        return {**self.vibrometer.settings(), "lockin": self.lockin.identity,
                "lockin_reference": "EXT (the generator's sync)", "lockin_time_constant_s": self.time_constant,
                "lockin_filter_db_oct": 6 * DEFAULT_FILTER_POLES, "lockin_input_range_v": INPUT_RANGE,
                "lockin_sensitivity_v": f"{SENSITIVITIES[0]:g} at the start, then per reading",
                "lockin_settle_s": self.settle, "ranging": "auto: decoder range and lock-in sensitivity per reading",
                "temperature_sensor": "none" if self.temperature_aux is None
                else f"lock-in Aux In {self.temperature_aux}, {TEMPERATURE_SENSOR_SCALE * 1e3:g} mV/degC"}

    def prepare(self) -> None:
        """Acknowledge off; the decoder's ranges and delay; the lock-in on the external reference (the sync's rising
        TTL edge), the readout's time constant and filter, the 1 V input range; the decoder's largest range."""
        self.vibrometer.acknowledge_off()
        self.used_ranges, self.used_sensitivities = set(), set()
        self.ranges = self.vibrometer.ranges
        self.delay = self.vibrometer.signal_delay
        lockin = self.lockin
        lockin.write("*CLS")
        lockin.reference_source = "EXT"
        lockin.reference_trigger = 1
        lockin.time_constant = self.time_constant
        lockin.filter_poles = DEFAULT_FILTER_POLES
        lockin.input_range = INPUT_RANGE
        lockin.sensitivity = SENSITIVITIES[0]
        lockin.check_status("configuring the readout")
        self.sensitivity = SENSITIVITIES[0]
        self.set_range(self.ranges[-1])

    def set_range(self, decoder_range: float) -> None:
        """Put the decoder on ``decoder_range`` [m/s/V] (the lock-in must settle again)."""
        self.vibrometer.decoder_range = decoder_range
        self.range = decoder_range

    def _set_sensitivity(self, sensitivity: float) -> None:
        if sensitivity != self.sensitivity:
            self.lockin.sensitivity = sensitivity
            self.sensitivity = sensitivity

    def read(self, frequency: float, sleep) -> VelocityReading:
        """A settled reading at the drive ``frequency`` [Hz], ranged; ``sleep`` waits [s] (the lock-in settling).

        Raises
        ------
        InstrumentError
            The reference is not locked, or an overload persists on the largest decoder range and sensitivity.
        """
        for _ in range(RANGING_STEPS):
            sleep(self.settle)
            reading = self.lockin.read()
            if reading.overload & OVERLOAD_UNLOCKED:
                raise InstrumentError(f"{self.lockin.name} not locked to the generator's sync at {frequency:.6g} Hz "
                                      "(check the sync cable to REF IN)")
            if reading.overload & OVERLOAD_INPUT:
                larger = [r for r in self.ranges if r > self.range]
                if not larger:
                    raise InstrumentError(f"{self.lockin.name} input overloaded on the decoder's largest range "
                                          f"{self.range * 1e3:g} mm/s/V at {frequency:.6g} Hz")
                self.set_range(larger[0])
                continue
            if reading.overload & OVERLOAD_OUTPUT:
                larger = [s for s in SENSITIVITIES if s > self.sensitivity]
                if not larger:
                    raise InstrumentError(f"{self.lockin.name} output overloaded at its largest sensitivity")
                self._set_sensitivity(min(larger))
                continue
            velocity = math.sqrt(2) * reading.magnitude * self.range
            fitting = [s for s in SENSITIVITIES if s >= HEADROOM * reading.magnitude]
            self._set_sensitivity(min(fitting) if fitting else SENSITIVITIES[0])
            holding = [r for r in self.ranges if velocity / r * HEADROOM <= INPUT_RANGE]
            if not (holding and holding[0] < self.range):
                break
            self.set_range(holding[0])
        else:
            raise InstrumentError(f"{self.lockin.name}: still ranging after {RANGING_STEPS} readings at "
                                  f"{frequency:.6g} Hz")
        self.used_ranges.add(self.range)
        self.used_sensitivities.add(self.sensitivity)
        return VelocityReading(velocity, wrap_degrees(reading.phase_deg + 360.0 * frequency * self.delay))

    def usage(self) -> str:
        """The settings the readings used, for a ``#`` line after a run's rows ("" before any reading)."""
        if not self.used_ranges:
            return ""
        ranges = ", ".join(f"{r * 1e3:g}" for r in sorted(self.used_ranges))
        sensitivities = ", ".join(f"{v:g}" for v in sorted(self.used_sensitivities))
        return (f"readout: decoder ranges {ranges} mm/s/V" + (f"; lock-in sensitivities {sensitivities} V" if sensitivities
                                                             else "") + f"; time constant {self.time_constant:g} s")

    def read_temperature(self) -> float | None:
        """Plate temperature [deg C] from its sensor on the lock-in's Aux In, or None without one."""
        if self.temperature_aux is None:
            return None
        return self.lockin.aux_input(self.temperature_aux) / TEMPERATURE_SENSOR_SCALE
