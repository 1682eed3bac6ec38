"""Simulated laser vibrometer: Polytec-style ``Get``/``Set`` lines and a lock-in velocity readout.

The protocol is documented in ``docs/instruments.md``.  Every command line gets exactly
one reply line (``Set`` replies with the value now in effect, as Polytec controllers do
with acknowledge on).  The readout is over-range when the velocity exceeds the decoder's
full scale; it is then reported as ``OVER`` with the full-scale value, never clipped silently.
"""

from collections.abc import Callable

import numpy as np

from instruments.drivers.vibrometer import format_position, format_range, full_scale
from workflow.models.limits import LIMITS

CONTROLLER_NAME = "OFV-5000 tactile-sim"
CONTROLLER_VERSION = "1.0-sim"
DECODER_NAME = "VD-09"
DECODER_RANGES = tuple(mm_s_v * 1e-3 for mm_s_v in (1, 2, 5, 10, 20, 50, 100))
"""Velocity decoder ranges [m/s per volt of analog output]."""
RECORD_SAMPLES_RANGE = LIMITS["campaign.ringdown_samples"]
"""Samples of one envelope record (its reply line stays under the 4 kB output buffer) [-]."""
RECORD_INTERVAL_US_RANGE = LIMITS["campaign.ringdown_interval_us"]
"""Time between record samples [us]."""
DEFAULT_RECORD_SAMPLES = 100
DEFAULT_RECORD_INTERVAL_US = 50


class VibrometerDevice:
    """The vibrometer's command interpreter.

    Parameters
    ----------
    signal : callable
        () -> (velocity amplitude [m/s], phase [deg]) of the true surface velocity at the
        drive frequency; called once per readout (it may advance the bench clock).
    rng : numpy.random.Generator
        Measurement noise.
    relative_noise : float
        Standard deviation of the relative amplitude error [-].
    floor_fraction : float
        Standard deviation of the additive noise, as a fraction of the range's full scale [-].
    phase_noise : float
        Standard deviation of the phase error [deg].
    record : callable, optional
        (samples, interval [s]) -> true velocity envelope [m/s] after the latest burst, or None
        when no burst fired since the last record; without it the record commands are unknown.
    temperature : callable, optional
        () -> plate temperature [deg C]; without it the temperature command is unknown.
    scanner : tuple of float or None
        (L/2, b/2) [m]: the plate's half extents, within which the laser spot can be positioned
        (``Set,Scanner,0,X|Y,<mm>``); None for a single-point head without a scanner.

    Attributes
    ----------
    position : tuple of float
        Laser spot (x, y) from the plate's centre [m].
    """

    def __init__(self, signal: Callable, rng, relative_noise: float, floor_fraction: float, phase_noise: float,
                 record: Callable | None = None, temperature: Callable | None = None, scanner: tuple | None = None):
        self.signal = signal
        self.record = record
        self.record_samples = DEFAULT_RECORD_SAMPLES
        self.record_interval_us = DEFAULT_RECORD_INTERVAL_US
        self.rng = rng
        self.relative_noise = relative_noise
        self.floor_fraction = floor_fraction
        self.phase_noise = phase_noise
        self.decoder_range = DECODER_RANGES[-1]
        self.scanner = scanner
        self.position = (0.0, 0.0)
        self._gets = {
            ("GetDevInfo", "Controller", "0", "Name"): lambda: CONTROLLER_NAME,
            ("GetDevInfo", "Controller", "0", "Version"): lambda: CONTROLLER_VERSION,
            ("GetDevInfo", "VeloDec", "1", "Name"): lambda: DECODER_NAME,
            ("GetDevInfo", "VeloDec", "1", "Ranges"): lambda: ";".join(map(format_range, DECODER_RANGES)),
            ("Get", "VeloDec", "1", "Range"): lambda: format_range(self.decoder_range),
            ("Get", "LockIn", "0", "Velocity"): self._readout,
        }
        if record is not None:
            self._gets[("Get", "Record", "0", "Samples")] = lambda: str(self.record_samples)
            self._gets[("Get", "Record", "0", "Interval")] = lambda: str(self.record_interval_us)
            self._gets[("Get", "Record", "0", "Envelope")] = self._record_readout
        if temperature is not None:
            self._gets[("Get", "Sensor", "0", "Temperature")] = lambda: f"{temperature():.3f}"

    def handle_line(self, line: str) -> str:
        """Execute one command line and return its reply line."""
        fields = tuple(field.strip() for field in line.strip().split(","))
        if fields in self._gets:
            return self._gets[fields]()
        if self.scanner is not None and fields[1:3] == ("Scanner", "0"):
            return self._scanner(fields)
        if fields[:4] == ("Set", "VeloDec", "1", "Range") and len(fields) == 5:
            choices = {format_range(r).lower(): r for r in DECODER_RANGES}
            if fields[4].lower() not in choices:
                return "Error,2,Invalid value"
            self.decoder_range = choices[fields[4].lower()]
            return format_range(self.decoder_range)
        if self.record is not None and fields[:3] == ("Set", "Record", "0") and len(fields) == 5:
            return self._set_record(fields[3], fields[4])
        return "Error,1,Unknown command"

    def _set_record(self, name: str, text: str) -> str:
        limits = {"Samples": RECORD_SAMPLES_RANGE, "Interval": RECORD_INTERVAL_US_RANGE}
        if name not in limits:
            return "Error,1,Unknown command"
        if not text.isdigit() or not limits[name][0] <= int(text) <= limits[name][1]:
            return "Error,2,Invalid value"
        setattr(self, "record_samples" if name == "Samples" else "record_interval_us", int(text))
        return str(int(text))

    def _record_readout(self) -> str:
        envelope = self.record(self.record_samples, self.record_interval_us * 1e-6)
        if envelope is None:
            return "Error,5,No trigger"
        limit = full_scale(self.decoder_range)
        noise = self.rng.standard_normal((3, len(envelope)))
        phasor = envelope * (1 + self.relative_noise * noise[0]) + self.floor_fraction * limit * (noise[1] + 1j * noise[2]) / np.sqrt(2)
        measured = np.abs(phasor)
        status = "OVER" if np.any(measured > limit) else "OK"
        values = ";".join(f"{v:.5E}" for v in np.minimum(measured, limit))
        return f"{status},{self.record_interval_us},{len(envelope)},{values}"

    def _scanner(self, fields: tuple) -> str:
        """The positioning commands: range, and the spot's x and y in mm from the plate's centre."""
        half = dict(zip("XY", self.scanner))
        if fields == ("GetDevInfo", "Scanner", "0", "Range"):
            return ",".join(format_position(sign * half[axis]) for axis in "XY" for sign in (-1, 1))
        if len(fields) == 4 and fields[0] == "Get" and fields[3] in half:
            return format_position(self.position["XY".index(fields[3])])
        if len(fields) == 5 and fields[0] == "Set" and fields[3] in half:
            try:
                value = float(fields[4]) * 1e-3
            except ValueError:
                return "Error,2,Invalid value"
            if not abs(value) <= half[fields[3]] * (1 + 1e-9):
                return "Error,4,Position off the plate"
            position = list(self.position)
            position["XY".index(fields[3])] = value
            self.position = tuple(position)
            return format_position(value)
        return "Error,1,Unknown command"

    def input_overrun(self) -> str:
        """The reply to a command line that overran the input buffer and was discarded."""
        return "Error,3,Input buffer overrun"

    def reply_lost(self) -> None:
        """A reply found the output queue full: the controller has no error queue, the reply is just lost."""

    def _readout(self) -> str:
        amplitude, phase = self.signal()
        limit = full_scale(self.decoder_range)
        noise = self.rng.standard_normal(4)
        phasor = amplitude * (1 + self.relative_noise * noise[0]) * np.exp(1j * np.radians(phase + self.phase_noise * noise[1]))
        phasor += self.floor_fraction * limit * (noise[2] + 1j * noise[3]) / np.sqrt(2)
        measured, measured_phase = abs(phasor), float(np.degrees(np.angle(phasor)))
        status = "OK"
        if measured > limit:
            measured, status = limit, "OVER"
        return f"{measured:.6E},{measured_phase:+.3f},{status}"
