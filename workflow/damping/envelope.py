"""The working mode's envelope under an amplitude-modulated drive: the ring-down equation with a drive.

One mode (resonance f_r, quality factor Q, quasi-static deflection per volt g) driven by
V(t) cos(omega t), the carrier omega = 2 pi f fixed and V(t) slowly varying, answers
w(t) = Re[a(t) e^(i omega t)].  Dropping the second derivative of a and the damping of its
first (terms of order 1/Q), the complex velocity envelope u = i omega a obeys

    du/dt = -(omega_r / (2 Q(|u|)) - i (omega_r^2 - omega^2) / (2 omega)) u + omega_r^2 g V(t) / 2,

    omega_r = 2 pi f_r(|u|),  f_r(v) = f_r0 (1 - kappa v^2)  (softening, :func:`~.harmonic.softened_resonance`).

|u| = v is the peak velocity at the antinode (the fit's velocity convention) and arg u its
phase against the drive.  Two special cases are the fit's own equations:

- V = 0: d|u|/dt = -pi f_r |u| / Q(|u|), the ring-down (:mod:`.ringdown`);
- du/dt = 0: |u| = omega g V / sqrt((1 - r^2)^2 + (r / Q)^2), r = f / f_r(|u|), the steady
  harmonic response (:mod:`.harmonic`), solved here in closed form for V
  (:meth:`EnvelopeModel.steady_voltage`).

The drive is held constant over each sample of an arbitrary waveform (the generator's STEP
filter) and integrated by fourth-order Runge-Kutta in steps of at most
:data:`MAX_STEP` times the fastest time scale (decay or detuning), vectorised
over a batch (designs, posterior draws, periods).  :func:`play` gives the envelope of a drive,
:func:`invert` the drive that makes the envelope follow a wanted one within a voltage limit
(the pre-compensation), both also in the periodic steady state the looping generator reaches
(:func:`periodic_play`, :func:`periodic_inversion`).
"""

from dataclasses import dataclass, replace

import numpy as np

from workflow.damping.harmonic import response_amplitude, self_consistent_amplitude, softened_resonance
from workflow.errors import TactileError

REACHABLE_GRID = 4001
"""Velocities at which :meth:`EnvelopeModel.reachable_velocity` checks the steady drive [-]."""
PERIODIC_TOLERANCE = 1e-7
"""Relative change of the state over one period below which a periodic solution has converged [-]."""
MAX_PERIODS = 60
"""Most periods evaluated to find a periodic steady state (Newton steps or, failing those, repetitions) [-]."""
MAX_STEP = 0.5
"""Largest RK4 step in units of the fastest time scale (decay plus detuning rate) [-]: a grating's envelope
then differs by 4e-6 of its amplitude from one integrated with steps 25 times smaller."""
OVERSHOOT = 1.5
"""Margin on the steady amplitude at the voltage limit for the transients' largest amplitude [-]."""
REFINEMENTS = 3
"""Most Newton refinements of each sample's drive in :func:`invert` after the affine estimate [-]."""
REFINED = 1e-9
"""Relative miss of the wanted envelope below which a sample's drive is not refined further [-]."""
REACHED = 0
"""Flag of a sample whose wanted envelope the drive reaches."""
LIMITED_RISE = 1
"""Flag of a sample where the drive sits at the voltage limit and the envelope still rises too slowly."""
LIMITED_FALL = 2
"""Flag of a sample where even the drive switched off lets the envelope fall too slowly (the free decay)."""


class EnvelopeSolveError(TactileError):
    """A looping drive whose envelope did not settle into a periodic state."""


@dataclass(frozen=True)
class EnvelopeModel:
    """The envelope dynamics of a plate's working mode driven at a fixed carrier.

    Attributes
    ----------
    resonance_frequency : float or array
        f_r0, the small-amplitude resonance [Hz].
    gain : float or array
        g, quasi-static antinode deflection per volt across the ceramics [m/V] (at resonance
        the deflection is Q g V).
    law : Q(v) law
        :mod:`~workflow.damping.laws`; parameters may be arrays broadcasting against a batch.
    softening : float or array
        kappa in f_r(v) = f_r0 (1 - kappa v^2) [s^2/m^2].
    carrier_frequency : float or array or None
        The drive's carrier f [Hz]; None: f_r0.
    """

    resonance_frequency: float
    gain: float
    law: object
    softening: float = 0.0
    carrier_frequency: float | None = None

    @property
    def carrier(self):
        """The carrier frequency f [Hz]."""
        return self.resonance_frequency if self.carrier_frequency is None else self.carrier_frequency

    def with_carrier(self, frequency) -> "EnvelopeModel":
        """The same plate driven at ``frequency`` [Hz]."""
        return replace(self, carrier_frequency=frequency)

    def resonance(self, velocity):
        """f_r(v) [Hz] at the antinode velocity amplitude ``velocity`` [m/s]."""
        return softened_resonance(self.resonance_frequency, self.softening, velocity)

    def rate(self, envelope, voltage):
        """du/dt [m/s^2] of the complex envelope ``envelope`` [m/s] under the drive amplitude ``voltage`` [V]."""
        return self.rate_function()(envelope, voltage)

    def rate_function(self):
        """:meth:`rate` with the model's constants evaluated once (the integrators call it millions of times)."""
        resonance, softening = np.asarray(self.resonance_frequency, dtype=float), np.asarray(self.softening, dtype=float)
        omega = 2 * np.pi * np.asarray(self.carrier, dtype=float)
        half_gain, omega2 = 0.5 * np.asarray(self.gain, dtype=float), omega**2
        quality_factor = self.law.quality_factor

        def rate(envelope, voltage):
            velocity = np.abs(envelope)
            omega_r = (2 * np.pi) * softened_resonance(resonance, softening, velocity)
            square = omega_r * omega_r
            growth = (0.5j / omega) * (square - omega2) - 0.5 * omega_r / quality_factor(velocity)
            return growth * envelope + (half_gain * voltage) * square

        return rate

    def steady_voltage(self, velocity):
        """Drive amplitude that holds the antinode velocity amplitude ``velocity`` [m/s] steady [V].

        The steady state of the envelope equation read backwards: V = v / (omega g A), A the
        harmonic response per unit quasi-static deflection at r = f / f_r(v) with Q(v)
        (:func:`~.harmonic.response_amplitude`).
        """
        velocity = np.asarray(velocity, dtype=float)
        omega = 2 * np.pi * np.asarray(self.carrier)
        ratio = np.asarray(self.carrier) / self.resonance(velocity)
        per_static = response_amplitude(1.0, ratio, self.law.quality_factor(velocity))
        return velocity / (omega * np.asarray(self.gain) * per_static)

    def reachable_velocity(self, voltage_limit: float) -> float:
        """The largest antinode velocity amplitude a drive within ``voltage_limit`` [V] holds steady [m/s].

        Climbing from rest the plate passes every lower amplitude, so v is reachable when the
        steady drive of every amplitude up to v is within the limit (a softening resonance can
        need more at some lower amplitude than at v itself).  Scalar parameters only.
        """
        ceiling = 2 * np.pi * float(self.carrier) * float(self.gain) * float(self.law.quality_factor(0.0)) * voltage_limit
        velocity = np.linspace(0.0, 1.01 * ceiling, REACHABLE_GRID)[1:]
        within = np.maximum.accumulate(self.steady_voltage(velocity)) <= voltage_limit
        if not within[0]:
            return 0.0
        first_out = len(within) if np.all(within) else int(np.argmin(within))
        return float(velocity[first_out - 1])

    def time_constant(self, velocity):
        """Envelope time constant Q(v) / (pi f_r(v)) at ``velocity`` [m/s] [s]."""
        return self.law.quality_factor(velocity) / (np.pi * self.resonance(velocity))

    def fastest_rate(self, voltage_limit, amplitude=0.0) -> float:
        """An upper bound of |d ln u / dt| over the amplitudes a drive within ``voltage_limit`` [V] reaches from a
        start at ``amplitude`` [m/s] [1/s].

        The largest amplitude is bounded by the steady response at exact resonance with Q(v) (detuning,
        softening included, only lowers it) with a margin of :data:`OVERSHOOT` for transients, or the start.
        """
        carrier = np.asarray(self.carrier, dtype=float)
        static = np.asarray(self.gain) * np.asarray(voltage_limit, dtype=float)
        steady = 2 * np.pi * carrier * self_consistent_amplitude(static, carrier, carrier, self.law.quality_factor)
        ceiling = np.maximum(OVERSHOOT * steady, np.max(amplitude))
        lowest_q = self.law.quality_factor(ceiling)
        detuning = np.maximum(np.abs(self.resonance(0.0) - carrier), np.abs(self.resonance(ceiling) - carrier))
        return float(np.max(np.pi * self.resonance(0.0) / lowest_q + 2 * np.pi * detuning))


def _substeps(model: EnvelopeModel, interval, voltage_limit, max_step: float, start=0.0) -> int:
    """Runge-Kutta steps per drive sample: each at most ``max_step`` / the fastest rate from ``start`` [-]."""
    fastest = model.fastest_rate(voltage_limit, np.abs(start))
    return max(1, int(np.ceil(float(np.max(interval)) * fastest / max_step)))


def _advance(rate, envelope, voltage, step, substeps: int):
    """The envelope after ``substeps`` RK4 steps of ``step`` [s] with the drive ``voltage`` [V] held."""
    for _ in range(substeps):
        k1 = rate(envelope, voltage)
        k2 = rate(envelope + 0.5 * step * k1, voltage)
        k3 = rate(envelope + 0.5 * step * k2, voltage)
        k4 = rate(envelope + step * k3, voltage)
        envelope = envelope + step * (k1 + 2 * k2 + 2 * k3 + k4) / 6
    return envelope


def play(model: EnvelopeModel, voltage, interval, start=0.0, max_step: float = MAX_STEP) -> np.ndarray:
    """The complex envelope at the sample boundaries of a drive held over each sample [m/s].

    Parameters
    ----------
    model : EnvelopeModel
    voltage : array (..., N)
        Drive amplitude across the ceramics during each sample [V], >= 0.
    interval : float or array (...)
        Duration of a sample [s].
    start : complex or array (...)
        Envelope at t = 0 [m/s] (0: at rest).
    max_step : float
        Largest RK4 step in units of the fastest time scale [-].

    Returns
    -------
    numpy.ndarray (..., N + 1)
        u at t = 0, interval, ..., N interval.
    """
    voltage = np.asarray(voltage, dtype=float)
    interval = np.asarray(interval, dtype=float)
    substeps = _substeps(model, interval, np.max(voltage, initial=0.0), max_step, start)
    shape = np.broadcast_shapes(np.shape(start), voltage.shape[:-1], interval.shape)
    envelope = np.broadcast_to(np.asarray(start, dtype=complex), shape).copy()
    states, rate = [envelope], model.rate_function()
    for k in range(voltage.shape[-1]):
        envelope = _advance(rate, envelope, voltage[..., k], interval / substeps, substeps)
        states.append(envelope)
    return np.stack(states, axis=-1)


def envelope_at(model: EnvelopeModel, voltage, interval: float, boundaries, times, max_step: float = MAX_STEP):
    """The complex envelope at any ``times`` [s] within a drive, from its states at the sample boundaries [m/s].

    Parameters
    ----------
    voltage : array (N,)
        The drive held over each sample [V].
    interval : float
        Sample duration [s].
    boundaries : array (N + 1,)
        u at t = 0, interval, ..., N interval (e.g. from :func:`play`) [m/s].
    times : array
        0 <= t <= N interval [s].
    """
    times = np.asarray(times, dtype=float)
    voltage = np.asarray(voltage, dtype=float)
    index = np.clip((times // interval).astype(int), 0, len(voltage) - 1)
    return play(model, voltage[index, None], times - index * interval, np.asarray(boundaries)[index], max_step)[..., -1]


def _periodic(period, shape, scale):
    """The start u* of a period with period(u*) = u*, and period's other output there.

    ``period(start)`` -> (end state, result), batched over a leading axis.  The map of a damped
    plate is a contraction, nearly affine in u: Newton's method on the real and imaginary parts
    (a 2 x 2 Jacobian from finite differences, evaluated in the same batched call) converges in
    a few periods where plain repetition needs ~10 time constants of the slowest decay; a Newton
    step that does not lower the residual falls back to one repetition.

    Raises
    ------
    EnvelopeSolveError
        Not settled within :data:`MAX_PERIODS` periods.
    """
    start = np.zeros(shape, dtype=complex)
    delta = 1e-6 * np.maximum(np.asarray(scale, dtype=float), 1e-12)
    best = np.full(shape, np.inf)
    for _ in range(MAX_PERIODS):
        ends, results = period(np.stack([start, start + delta, start + 1j * delta]))
        residual = ends[0] - start
        size = np.abs(residual)
        if np.all(size <= PERIODIC_TOLERANCE * np.maximum(np.abs(ends[0]), delta)):
            return start, results
        d_real, d_imag = (ends[1] - ends[0]) / delta - 1, (ends[2] - ends[0]) / delta - 1j
        determinant = d_real.real * d_imag.imag - d_imag.real * d_real.imag
        with np.errstate(divide="ignore", invalid="ignore"):
            x = (-residual.real * d_imag.imag + residual.imag * d_imag.real) / determinant
            y = (-residual.imag * d_real.real + residual.real * d_real.imag) / determinant
        newton = start + x + 1j * y
        improving = np.isfinite(newton) & (size < best)
        start = np.where(improving, newton, ends[0])
        best = np.minimum(best, size)
    raise EnvelopeSolveError(f"the looping drive's envelope did not settle within {MAX_PERIODS} periods (largest "
                             f"change over a period {float(np.max(best)):.3g} m/s); is the model's Q(v) positive?")


def periodic_play(model: EnvelopeModel, voltage, interval, max_step: float = MAX_STEP) -> np.ndarray:
    """:func:`play` of a looping drive in its periodic steady state (the state it repeats) [m/s].

    Returns u over one period, (..., N + 1) (first and last equal within :data:`PERIODIC_TOLERANCE`).
    """
    voltage = np.asarray(voltage, dtype=float)
    scale = 2 * np.pi * np.asarray(model.carrier) * np.asarray(model.gain) * np.max(voltage, axis=-1)

    def period(start):
        states = play(model, voltage, interval, start, max_step)
        return states[..., -1], states

    _, states = _periodic(period, voltage.shape[:-1], scale)
    return states[0]


@dataclass(frozen=True)
class Inversion:
    """A drive computed to make the envelope follow a wanted one, and what it achieves.

    Attributes
    ----------
    voltage : numpy.ndarray (..., N)
        Drive amplitude during each sample [V], within [0, limit].
    envelope : numpy.ndarray (..., N + 1)
        Complex envelope the model predicts at the sample boundaries [m/s].
    flags : numpy.ndarray of int (..., N)
        Per sample: :data:`REACHED`, :data:`LIMITED_RISE` (the voltage limit holds the rise back) or
        :data:`LIMITED_FALL` (the free decay holds the fall back).
    """

    voltage: np.ndarray
    envelope: np.ndarray
    flags: np.ndarray


def invert(model: EnvelopeModel, wanted, interval, voltage_limit, start=0.0, max_step: float = MAX_STEP) -> Inversion:
    """The drive that brings |u| to ``wanted`` at the end of each sample, within [0, ``voltage_limit``].

    Sample k holds the drive V_k chosen so that |u(t_k+1)| = wanted_k+1, the envelope equation
    inverted one sample at a time from the state the drive has actually reached: where the
    wanted envelope rises faster than the limit allows, V_k = limit (flag :data:`LIMITED_RISE`);
    where it falls faster than the free decay, the drive that lowers |u| most (flag :data:`LIMITED_FALL`); later samples
    catch up as fast as the bounds allow.  |u(V)| over one sample is nearly affine in V: the
    root of the affine estimate from V = 0 and V = limit is refined by Newton steps on the
    integrated sample until it misses by less than :data:`REFINED`.

    Parameters
    ----------
    model : EnvelopeModel
    wanted : array (..., N + 1)
        Wanted |u| at t = 0 .. N interval [m/s] (the first is not used).
    interval : float or array (...)
        Sample duration [s].
    voltage_limit : float or array (...)
        Largest drive amplitude [V].
    start : complex or array (...)
        u at t = 0 [m/s].
    """
    wanted = np.asarray(wanted, dtype=float)
    interval = np.asarray(interval, dtype=float)
    shape = np.broadcast_shapes(np.shape(start), wanted.shape[:-1], interval.shape, np.shape(voltage_limit))
    limit = np.broadcast_to(np.asarray(voltage_limit, dtype=float), shape)
    substeps = _substeps(model, interval, np.max(limit), max_step, start)
    step = interval / substeps
    envelope = np.broadcast_to(np.asarray(start, dtype=complex), shape).copy()
    bounds = np.stack([np.zeros(shape), limit])
    states, voltages, flags, rate = [envelope], [], [], model.rate_function()
    for k in range(1, wanted.shape[-1]):
        target = wanted[..., k]
        off, full = _advance(rate, envelope, bounds, step, substeps)
        share, flag = _affine_share(off, full - off, target)
        reached = _advance(rate, envelope, share * limit, step, substeps)
        for _ in range(REFINEMENTS):
            miss = np.where(flag == REACHED, np.abs(reached) - target, 0.0)
            if np.all(np.abs(miss) <= REFINED * target):
                break
            slope = np.real(np.conj(reached) * (full - off)) / np.maximum(np.abs(reached), 1e-300)
            share = np.clip(share - miss / np.where(slope > 0, slope, np.inf), 0.0, 1.0)
            reached = _advance(rate, envelope, share * limit, step, substeps)
        envelope = reached
        voltages.append(share * limit)
        flags.append(flag)
        states.append(envelope)
    return Inversion(np.stack(voltages, axis=-1), np.stack(states, axis=-1), np.stack(flags, axis=-1))


def _affine_share(off, change, target):
    """s in [0, 1] with |off + s change| = target (the larger root), and its flag; where no s in [0, 1]
    gets that low, the s of the smallest |off + s change|."""
    a = np.maximum(np.abs(change) ** 2, 1e-300)
    b = 2 * np.real(np.conj(off) * change)
    c = np.abs(off) ** 2 - target**2
    discriminant = b**2 - 4 * a * c
    root = (-b + np.sqrt(np.maximum(discriminant, 0.0))) / (2 * a)
    lowest = np.clip(-b / (2 * a), 0.0, 1.0)
    flag = np.where(root > 1.0, LIMITED_RISE, np.where((root < 0.0) | (discriminant < 0), LIMITED_FALL, REACHED))
    return np.where(flag == LIMITED_FALL, lowest, np.clip(root, 0.0, 1.0)), flag


def periodic_inversion(model: EnvelopeModel, wanted, interval, voltage_limit,
                       max_step: float = MAX_STEP) -> Inversion:
    """:func:`invert` of a looping wanted envelope in its periodic steady state: the pre-compensated drive of
    a texture the generator plays over and over.

    Parameters
    ----------
    wanted : array (..., N)
        Wanted |u| at t = 0 .. (N - 1) interval of one period [m/s]; the period is N interval.

    Returns
    -------
    Inversion
        Of one period: voltage and flags (..., N), envelope (..., N + 1) at t = 0 .. N interval.
    """
    wanted = np.asarray(wanted, dtype=float)
    closed = np.concatenate([wanted, wanted[..., :1]], axis=-1)

    def period(start):
        result = invert(model, closed, interval, voltage_limit, start, max_step)
        return result.envelope[..., -1], result

    _, result = _periodic(period, wanted.shape[:-1], np.max(wanted, axis=-1))
    return Inversion(result.voltage[0], result.envelope[0], result.flags[0])
