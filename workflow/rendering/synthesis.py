"""Drive synthesis: the envelope a texture asks for, the drive that produces it, and what it achieves.

For a texture and a finger motion (:mod:`.textures`) and a plate's envelope model
(:class:`~workflow.damping.envelope.EnvelopeModel`), :func:`render` samples the looped signal,
tunes the carrier to the resonance at the texture's highest amplitude (the resonance softens
with amplitude), and computes two drives held over each sample:

- pre-compensated: the envelope equation inverted in the periodic steady state
  (:func:`~workflow.damping.envelope.periodic_inversion`), clipped to [0, voltage limit], with
  each sample flagged where the limit (a rise) or the free decay (a fall) leaves the wanted
  envelope unreachable;
- plain switching: the steady-state drive of each wanted level (what a drive proportional to
  the texture does), for comparison;

and the envelope the model predicts for each.  :func:`search_periods` finds, for a grating
between two levels, the error as a function of its period in time; :meth:`PeriodSearch.smallest_period`
turns it into the smallest spatial period rendered within an error at a finger speed.
"""

from dataclasses import dataclass

import numpy as np

from workflow.damping.envelope import LIMITED_FALL, LIMITED_RISE, EnvelopeModel, periodic_inversion, periodic_play
from workflow.rendering.metrics import envelope_error
from workflow.rendering.textures import TextureError, loop_duration, wanted_deflection
from workflow.units import UM

RESOLUTION = 8
"""Drive samples per envelope time constant at the texture's highest amplitude [-]."""
MIN_POINTS = 8
"""Fewest samples of a looped drive (the 33500's shortest arbitrary waveform) [-]."""
ERROR_TARGET = 0.1
"""Envelope error within which a texture counts as rendered [-] (:mod:`.metrics`)."""
SETTLE = 10
"""Time constants of the slowest (lowest-amplitude) decay within which a grating's edges settle [-]."""
SEARCH_POINTS = 8
"""Grating periods (in time) at which :func:`search_periods` evaluates the error [-] (nearly a power law in
between: log-log interpolation)."""
CARRIER_ITERATIONS = 4
"""Fixed-point iterations of f = f_r(2 pi f w) in :func:`tuned_carrier` [-] (kappa v^2 < 1e-2: 1e-8 after four)."""


def tuned_carrier(model: EnvelopeModel, deflection: float) -> float:
    """The carrier at the plate's resonance when it vibrates at ``deflection`` [m]: f = f_r(2 pi f w) [Hz]."""
    frequency = float(model.resonance_frequency)
    for _ in range(CARRIER_ITERATIONS):
        frequency = float(model.resonance(2 * np.pi * frequency * deflection))
    return frequency


def check_reachable(model: EnvelopeModel, highest: float, voltage_limit: float) -> None:
    """TextureError unless the plate holds ``highest`` [m] steady within ``voltage_limit`` [V] (carrier set)."""
    reachable = model.reachable_velocity(voltage_limit) / (2 * np.pi * float(model.carrier))
    if highest > reachable:
        raise TextureError(f"the texture asks for {highest / UM:.3g} µm, above the {reachable / UM:.3g} µm this plate "
                           f"reaches at the voltage limit {voltage_limit:g} V")


@dataclass(frozen=True)
class Rendering:
    """A texture rendered for a plate: the looped signal, its drives and their predicted envelopes.

    Attributes
    ----------
    model : EnvelopeModel
        With the carrier the drives modulate [Hz].
    voltage_limit : float
        Largest drive amplitude [V peak across the ceramics].
    interval : float
        Sample duration [s]; sample k holds its drive on [k interval, (k + 1) interval).
    wanted : numpy.ndarray (N,)
        Antinode deflection amplitude wanted at k interval [m].
    drive, plain_drive : numpy.ndarray (N,)
        Pre-compensated and plain-switching drive amplitudes [V].
    envelope, plain_envelope : numpy.ndarray (N,)
        Deflection amplitude the model predicts at k interval in the periodic steady state [m].
    flags : numpy.ndarray of int (N,)
        Per sample of the pre-compensated drive: reached, limited rise, limited fall
        (:mod:`workflow.damping.envelope`).
    """

    model: EnvelopeModel
    voltage_limit: float
    interval: float
    wanted: np.ndarray
    drive: np.ndarray
    plain_drive: np.ndarray
    envelope: np.ndarray
    plain_envelope: np.ndarray
    flags: np.ndarray

    @property
    def time(self) -> np.ndarray:
        """Sample times from the start of the loop [s]."""
        return self.interval * np.arange(len(self.wanted))

    @property
    def duration(self) -> float:
        """The loop's duration [s]."""
        return self.interval * len(self.wanted)

    @property
    def error(self) -> float:
        """Predicted envelope error of the pre-compensated drive [-]."""
        return float(envelope_error(self.envelope, self.wanted))

    @property
    def plain_error(self) -> float:
        """Predicted envelope error of plain switching [-]."""
        return float(envelope_error(self.plain_envelope, self.wanted))

    @property
    def limited_rise_share(self) -> float:
        """Share of the loop where the voltage limit holds the envelope back [-]."""
        return float(np.mean(self.flags == LIMITED_RISE))

    @property
    def limited_fall_share(self) -> float:
        """Share of the loop where the free decay holds the envelope back [-]."""
        return float(np.mean(self.flags == LIMITED_FALL))

    def velocity(self, deflection):
        """Antinode velocity amplitude of a deflection amplitude at the carrier, 2 pi f w [m/s]."""
        return 2 * np.pi * float(self.model.carrier) * np.asarray(deflection)


def render(model: EnvelopeModel, texture, motion, voltage_limit: float, max_points: int | None = None) -> Rendering:
    """Render ``texture`` under ``motion`` on the plate of ``model`` within ``voltage_limit`` [V].

    The carrier is ``model.carrier_frequency`` if set, else :func:`tuned_carrier` at the texture's
    highest amplitude.  The loop is sampled :data:`RESOLUTION` times per time constant at that
    amplitude, with at least :data:`MIN_POINTS` and at most ``max_points`` samples (the
    generator's waveform memory or line length; coarser sampling then).

    Raises
    ------
    TextureError
        An amplitude the plate does not reach at the voltage limit, a trace leaving a profile.
    """
    highest = texture.levels[1]
    if model.carrier_frequency is None:
        model = model.with_carrier(tuned_carrier(model, highest))
    check_reachable(model, highest, voltage_limit)
    duration = loop_duration(texture, motion)
    step = float(model.time_constant(2 * np.pi * float(model.carrier) * highest)) / RESOLUTION
    points = max(MIN_POINTS, int(np.ceil(duration / step)))
    points = points if max_points is None else min(points, max_points)
    interval = duration / points
    wanted = wanted_deflection(texture, motion, interval * np.arange(points))
    to_velocity = 2 * np.pi * float(model.carrier)
    inversion = periodic_inversion(model, to_velocity * wanted, interval, voltage_limit)
    plain_drive = model.steady_voltage(to_velocity * wanted)
    plain = periodic_play(model, plain_drive, interval)
    return Rendering(model, voltage_limit, interval, wanted, inversion.voltage, plain_drive,
                     np.abs(inversion.envelope[:-1]) / to_velocity, np.abs(plain[:-1]) / to_velocity, inversion.flags)


@dataclass(frozen=True)
class PeriodSearch:
    """Envelope error of a grating against its period in time, both drives.

    Attributes
    ----------
    time_period : numpy.ndarray
        Periods in time [s], ascending.
    error, plain_error : numpy.ndarray
        Predicted envelope error of the pre-compensated and the plain-switching drive [-].
    """

    time_period: np.ndarray
    error: np.ndarray
    plain_error: np.ndarray

    def smallest_time_period(self, target: float = ERROR_TARGET, plain: bool = False) -> tuple:
        """The shortest period in time rendered within ``target`` [s], and how it was found.

        Between evaluated periods the error is interpolated in log-log; beyond the longest
        period, where the edges have settled, the squared error integrated over a period is
        fixed and the error falls as 1 / sqrt(period).

        Returns
        -------
        (float, str)
            The period and ``"interpolated"``, ``"extrapolated"`` or ``"at most"`` (already
            within the target at the shortest period evaluated).
        """
        error = self.plain_error if plain else self.error
        over = np.nonzero(error > target)[0]
        if len(over) == 0:
            return float(self.time_period[0]), "at most"
        last = int(over[-1])
        if last == len(error) - 1:
            return float(self.time_period[-1] * (error[-1] / target) ** 2), "extrapolated"
        log_t, log_e = np.log(self.time_period[last : last + 2]), np.log(error[last : last + 2])
        return float(np.exp(np.interp(np.log(target), log_e[::-1], log_t[::-1]))), "interpolated"

    def smallest_period(self, speed: float, target: float = ERROR_TARGET, plain: bool = False) -> tuple:
        """The shortest spatial period [m] rendered within ``target`` at the finger ``speed`` [m/s], and how found."""
        period, how = self.smallest_time_period(target, plain)
        return speed * period, how


def search_periods(model: EnvelopeModel, low: float, high: float, voltage_limit: float, duty: float = 0.5,
                   points: int | None = None) -> PeriodSearch:
    """Envelope errors of a grating between ``low`` and ``high`` [m] at ``points`` (default :data:`SEARCH_POINTS`)
    periods in time.

    The error depends on the period in time only (the finger speed maps it to space).  The periods
    run geometrically from the time constant at ``high`` to :data:`SETTLE` time constants of the
    slowest decay over the shorter of the two half-periods, every period sampled with the same
    number of samples (the longest :data:`RESOLUTION` times per fast time constant), all in one
    batch.  The carrier is tuned to ``high`` unless the model sets it.
    """
    if model.carrier_frequency is None:
        model = model.with_carrier(tuned_carrier(model, high))
    check_reachable(model, high, voltage_limit)
    to_velocity = 2 * np.pi * float(model.carrier)
    fast, slow = (float(model.time_constant(to_velocity * level)) for level in (high, low))
    periods = np.geomspace(fast, SETTLE * max(fast, slow) / min(duty, 1 - duty), points or SEARCH_POINTS)
    samples = max(MIN_POINTS, int(np.ceil(periods[-1] * RESOLUTION / fast)))
    wanted = np.where(np.arange(samples) < duty * samples, high, low) * to_velocity
    wanted = np.broadcast_to(wanted, (len(periods), samples))
    interval = periods / samples
    inversion = periodic_inversion(model, wanted, interval, voltage_limit)
    plain = periodic_play(model, model.steady_voltage(wanted), interval)
    return PeriodSearch(periods, envelope_error(np.abs(inversion.envelope[:, :-1]), wanted),
                        envelope_error(np.abs(plain[:, :-1]), wanted))
