"""Textures, friction curves and finger motions: what the plate renders, as deflection against time.

A texture is the antinode deflection amplitude wanted at each position along the finger's stroke
x [m]: a :class:`Grating` (two levels alternating with a spatial period) or a :class:`Profile`
(amplitude sampled along the stroke, linear between samples).  A :class:`FrictionCurve` (the
user's measured friction ratio against amplitude) turns friction levels into amplitudes; no
friction model is assumed.  The finger moves at a :class:`ConstantSpeed` or along a recorded
:class:`Trace` x(t).  The generator loops its waveform, so the rendered signal repeats every
:func:`loop_duration`: one grating period at constant speed, the stroke of a profile, the trace.
"""

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from workflow.errors import TactileError
from workflow.units import MM, UM


class TextureError(TactileError, ValueError):
    """A texture, friction curve or finger motion that cannot be rendered.

    Attributes
    ----------
    index : int or None
        The sample at fault (a file reader turns it into a line number), if one is.
    """

    def __init__(self, message: str, index: int | None = None):
        super().__init__(message)
        self.index = index


def _first(mask) -> int:
    """Index of the first True of ``mask``."""
    return int(np.argmax(mask))


def _pairs(first, second, what: str) -> tuple:
    """Two equally long 1-D arrays of finite numbers, at least two samples, or TextureError naming ``what``."""
    first, second = np.asarray(first, dtype=float), np.asarray(second, dtype=float)
    if first.ndim != 1 or second.shape != first.shape or len(first) < 2:
        raise TextureError(f"{what} needs at least two samples, each with both values")
    if not (np.all(np.isfinite(first)) and np.all(np.isfinite(second))):
        raise TextureError(f"{what}: expected finite numbers")
    return first, second


@dataclass(frozen=True)
class Grating:
    """Two amplitude levels alternating along the stroke.

    Attributes
    ----------
    period : float
        Spatial period [m], > 0.
    duty : float
        Share of each period at the ``high`` level, starting at x = 0 [-], in (0, 1).
    low, high : float
        Antinode deflection amplitudes [m], 0 <= low < high.
    """

    period: float
    duty: float
    low: float
    high: float

    def __post_init__(self):
        if not (np.isfinite(self.period) and self.period > 0):
            raise TextureError(f"grating period must be positive, got {self.period / MM:g} mm")
        if not 0 < self.duty < 1:
            raise TextureError(f"grating duty cycle must be between 0 and 1 (exclusive), got {self.duty:g}")
        if not (np.isfinite(self.low) and np.isfinite(self.high) and 0 <= self.low < self.high):
            raise TextureError(f"grating levels must satisfy 0 <= low < high, got {self.low / UM:g} and "
                               f"{self.high / UM:g} µm")

    @property
    def levels(self) -> tuple:
        """(low, high) [m]."""
        return self.low, self.high

    def amplitude(self, position):
        """Wanted deflection at ``position`` [m] -> [m]: high on [k period, (k + duty) period)."""
        phase = np.mod(np.asarray(position, dtype=float) / self.period, 1.0)
        return np.where(phase < self.duty, self.high, self.low)


@dataclass(frozen=True)
class Profile:
    """Wanted amplitude sampled along the stroke, linear between samples.

    Attributes
    ----------
    position : numpy.ndarray
        Strictly increasing positions [m], at least two.
    amplitude : numpy.ndarray
        Antinode deflection amplitude at each position [m], >= 0.
    """

    position: np.ndarray
    amplitude: np.ndarray

    def __post_init__(self):
        position, amplitude = _pairs(self.position, self.amplitude, "a profile (position, amplitude)")
        steps = np.diff(position) > 0
        if not np.all(steps):
            raise TextureError("profile positions must increase strictly along the stroke", _first(~steps) + 1)
        if np.any(amplitude < 0):
            raise TextureError("profile amplitudes must be >= 0", _first(amplitude < 0))

    @property
    def levels(self) -> tuple:
        """(lowest, highest) amplitude [m]."""
        return float(np.min(self.amplitude)), float(np.max(self.amplitude))

    def amplitude_at(self, position):
        """Wanted deflection at ``position`` [m] -> [m] (within the profile's positions)."""
        return np.interp(position, self.position, self.amplitude)


@dataclass(frozen=True)
class FrictionCurve:
    """The user's measured friction ratio against vibration amplitude, interpolated monotonically (PCHIP).

    Attributes
    ----------
    amplitude : numpy.ndarray
        Strictly increasing antinode deflection amplitudes [m], >= 0, at least two.
    friction : numpy.ndarray
        Friction ratio at each amplitude [-] (1: the plate at rest), strictly monotonic.
    """

    amplitude: np.ndarray
    friction: np.ndarray

    def __post_init__(self):
        amplitude, friction = _pairs(self.amplitude, self.friction, "a friction curve (amplitude, friction ratio)")
        if np.any(amplitude < 0):
            raise TextureError("friction curve amplitudes must be >= 0", _first(amplitude < 0))
        rising = np.diff(amplitude) > 0
        if not np.all(rising):
            raise TextureError("friction curve amplitudes must increase strictly", _first(~rising) + 1)
        steps = np.sign(np.diff(friction))
        if not np.all(steps == steps[0]) or steps[0] == 0:
            raise TextureError("the friction ratio must be strictly monotonic in the amplitude (one amplitude per "
                               "friction level)", _first(steps != steps[0]) + 1 if steps[0] else 1)

    @property
    def friction_range(self) -> tuple:
        """(lowest, highest) friction ratio the curve covers [-]."""
        return float(np.min(self.friction)), float(np.max(self.friction))

    def amplitude_for(self, friction):
        """The amplitude [m] giving ``friction`` [-] (monotone PCHIP of the inverse curve); TextureError outside it."""
        friction = np.asarray(friction, dtype=float)
        low, high = self.friction_range
        outside = (friction < low) | (friction > high) | ~np.isfinite(friction)
        if np.any(outside):
            index = _first(np.ravel(outside))
            raise TextureError(f"friction ratio {np.ravel(friction)[index]:g} is outside the friction curve's range "
                               f"{low:g} to {high:g}", index)
        order = np.argsort(self.friction)
        return PchipInterpolator(self.friction[order], self.amplitude[order])(friction)


@dataclass(frozen=True)
class ConstantSpeed:
    """The finger slides at ``speed`` [m/s] (> 0) from the start of the stroke."""

    speed: float

    def __post_init__(self):
        if not (np.isfinite(self.speed) and self.speed > 0):
            raise TextureError(f"finger speed must be positive, got {self.speed / MM:g} mm/s")

    @property
    def typical_speed(self) -> float:
        """[m/s]"""
        return self.speed


@dataclass(frozen=True)
class Trace:
    """A recorded finger position against time, linear between samples.

    Attributes
    ----------
    time : numpy.ndarray
        Strictly increasing times [s], at least two.
    position : numpy.ndarray
        Finger position along the stroke at each time [m].
    """

    time: np.ndarray
    position: np.ndarray

    def __post_init__(self):
        time, position = _pairs(self.time, self.position, "a finger trace (time, position)")
        forward = np.diff(time) > 0
        if not np.all(forward):
            index = _first(~forward) + 1
            raise TextureError(f"the finger trace goes backwards in time (t = {time[index]:g} s after "
                               f"{time[index - 1]:g} s)", index)

    @property
    def typical_speed(self) -> float:
        """Median |dx/dt| over the trace [m/s]."""
        return float(np.median(np.abs(np.diff(self.position) / np.diff(self.time))))


def loop_duration(texture, motion) -> float:
    """Duration of the signal the generator loops [s]: a grating period at constant speed, a profile's stroke
    at constant speed, or the trace."""
    if isinstance(motion, Trace):
        return float(motion.time[-1] - motion.time[0])
    if isinstance(texture, Grating):
        return texture.period / motion.speed
    return float(texture.position[-1] - texture.position[0]) / motion.speed


def finger_position(texture, motion, time):
    """Finger position [m] at ``time`` [s] from the start of the loop."""
    if isinstance(motion, Trace):
        return np.interp(np.asarray(time) + motion.time[0], motion.time, motion.position)
    start = 0.0 if isinstance(texture, Grating) else float(texture.position[0])
    return start + motion.speed * np.asarray(time, dtype=float)


def wanted_deflection(texture, motion, time):
    """The antinode deflection amplitude the texture asks for at ``time`` [s] of the loop -> [m].

    Raises
    ------
    TextureError
        A trace that leaves a profile's positions.
    """
    position = finger_position(texture, motion, time)
    if isinstance(texture, Grating):
        return texture.amplitude(position)
    low, high = texture.position[0], texture.position[-1]
    outside = (position < low - 1e-12) | (position > high + 1e-12)
    if np.any(outside):
        index = _first(outside)
        raise TextureError(f"the finger trace leaves the profile: x = {position[index] / MM:g} mm at "
                           f"t = {np.asarray(time)[index]:g} s, the profile spans {low / MM:g} to {high / MM:g} mm")
    return texture.amplitude_at(position)
