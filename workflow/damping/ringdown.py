"""Free decay of the vibration after a burst (ring-down), with amplitude-dependent damping.

Once the drive stops, the velocity envelope v (peak velocity at the antinode) of a mode at
f_r loses the fraction 2 pi / Q of its energy per cycle, so

    dv/dt = -pi f_r v / Q(v).

For the laws with a power-law loss, 1/Q = 1/Q0 + alpha |v|^n, this is a Bernoulli equation
with a closed form (a = pi f_r / Q0, b = pi f_r alpha):

    n = 2:  v(t)^2 = a v0^2 e^(-2at) / (a + b v0^2 (1 - e^(-2at)))
    n = 1:  v(t)   = a v0 e^(-at) / (a + b v0 (1 - e^(-at)))

and a constant Q decays exponentially.  Any other law is integrated in ln v by a fixed-step
fourth-order Runge-Kutta scheme, vectorised over walkers and bursts (:func:`integrated_decay`).
The resonance's small shift with amplitude (softening) is neglected during the decay.
"""

import numpy as np

from workflow.damping.laws import ConstantQ, LinearLoss, QuadraticLoss

RK4_MAX_STEP = 0.1
"""Largest Runge-Kutta step, in units of the fastest decay time Q(v0) / (pi f) [-]: the local error of ln v
stays below ~1e-7, the whole record's below ~1e-5, far below any envelope's noise."""


def decay_velocity(law, frequency, initial_velocity, time):
    """Envelope v(t) of the free decay [m/s], closed form where the law has one.

    Parameters
    ----------
    law : Q(v) law
        Parameters broadcasting against the other arguments (e.g. (W, 1)).
    frequency : array
        f_r during the decay [Hz].
    initial_velocity : array
        v0 at t = 0 (end of the burst), antinode peak velocity [m/s].
    time : array
        Time since the end of the burst [s], >= 0.
    """
    f, v0, t = (np.asarray(x, dtype=float) for x in (frequency, initial_velocity, time))
    if not isinstance(law, (ConstantQ, QuadraticLoss, LinearLoss)):
        return integrated_decay(law.quality_factor, f, v0, t)
    a = np.pi * f / np.asarray(law.q0)
    if isinstance(law, ConstantQ):
        return v0 * np.exp(-a * t)
    b = np.pi * f * np.asarray(law.alpha)
    if isinstance(law, QuadraticLoss):
        decay = np.exp(-2 * a * t)
        return np.sqrt(a * v0**2 * decay / (a + b * v0**2 * (1 - decay)))
    decay = np.exp(-a * t)  # LinearLoss
    return a * v0 * decay / (a + b * v0 * (1 - decay))


RK4_MAX_STEPS = 8
"""Most steps between neighbouring times [-]: bounds the cost for walkers far out in the prior (Q near 1)."""


def integrated_decay(quality_factor, frequency, initial_velocity, time, max_step=RK4_MAX_STEP):
    """v(t) of dv/dt = -pi f v / Q(v) by RK4 in ln v on the sorted distinct ``time`` values [m/s].

    Vectorised over everything but time: the arguments broadcast to one shape, and the
    integration runs once over the distinct times (a record's samples are shared by its
    bursts), in steps of at most ``max_step`` decay times (:func:`decay_on_grid`).
    """
    f, v0, t = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (frequency, initial_velocity, time)))
    grid, where = np.unique(t, return_inverse=True)
    values = decay_on_grid(quality_factor, f, v0, grid, max_step)
    return np.take_along_axis(values, where.reshape((1,) + t.shape), axis=0)[0]


def decay_on_grid(quality_factor, frequency, initial_velocity, grid, max_step=RK4_MAX_STEP):
    """v at each time of the sorted ``grid`` [s] (>= 0) for every element of the broadcast ``frequency`` [Hz] and
    ``initial_velocity`` [m/s] by RK4 in ln v: shape ``(len(grid),) + broadcast shape`` [m/s].

    Between neighbouring times, equal steps of at most ``max_step`` times the fastest decay time
    Q(v0) / (pi f) of all elements (the decay only slows down: Q(v) is non-increasing, v falls),
    and at most :data:`RK4_MAX_STEPS` of them.
    """
    f, v0 = np.broadcast_arrays(np.asarray(frequency, dtype=float), np.asarray(initial_velocity, dtype=float))

    def slope(ln_v):
        return -np.pi * f / quality_factor(np.exp(ln_v))

    ln_v = np.log(v0)
    with np.errstate(invalid="ignore"):
        rates = -slope(ln_v)
    fastest = float(np.max(rates[np.isfinite(rates)], initial=0.0))
    values = np.empty((len(grid),) + ln_v.shape)
    previous = 0.0
    for i, target in enumerate(grid):
        steps = min(int(np.ceil((target - previous) * fastest / max_step)), RK4_MAX_STEPS) if target > previous else 0
        h = (target - previous) / max(steps, 1)
        for _ in range(steps):
            k1 = slope(ln_v)
            k2 = slope(ln_v + 0.5 * h * k1)
            k3 = slope(ln_v + 0.5 * h * k2)
            k4 = slope(ln_v + h * k3)
            ln_v = ln_v + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        values[i] = ln_v
        previous = target
    return np.exp(values)


def burst_decays(law, frequency, initial_velocity, burst, time):
    """Envelope of every ring-down sample, one row per walker [m/s], shape (W, N).

    Parameters
    ----------
    law : Q(v) law
        Parameters of shape (W, 1).
    frequency : array (B,)
        f_r of each burst [Hz].
    initial_velocity : array (W, B)
        v0 of each burst [m/s].
    burst, time : array (N,)
        Burst index and time since the burst's end [s] of each sample.

    Closed forms are evaluated at each sample; any other law is integrated once per walker and
    burst over the distinct sample times (:func:`decay_on_grid`), not once per sample.
    """
    if isinstance(law, (ConstantQ, QuadraticLoss, LinearLoss)):
        return decay_velocity(law, np.asarray(frequency)[burst], initial_velocity[:, burst], time)
    grid, where = np.unique(time, return_inverse=True)
    values = decay_on_grid(law.quality_factor, frequency, initial_velocity, grid)  # (G, W, B)
    return values[where, :, burst].T


def decay_quality_factors(frequency, velocity, burst, time):
    """Model-free Q(v) points from each ring-down: Q = pi f dt / -d ln v between neighbouring samples.

    Returns
    -------
    velocity : numpy.ndarray
        Geometric mean of each pair's velocities [m/s] (at the measurement point).
    quality_factor : numpy.ndarray
        [-]; pairs whose velocity did not fall are left out.
    """
    points_v, points_q = [], []
    for j in np.unique(burst):
        mine = burst == j
        order = np.argsort(time[mine])
        t, v, f = time[mine][order], velocity[mine][order], frequency[mine][order]
        step = max(1, len(t) // 8)
        t, v, f = t[::step], v[::step], f[::step]
        fall = np.log(v[:-1]) - np.log(v[1:])
        good = (fall > 0) & (v[1:] > 0)
        points_v.append(np.sqrt(v[:-1] * np.abs(v[1:]))[good])
        points_q.append((np.pi * f[:-1] * np.diff(t) / np.where(good, fall, 1.0))[good])
    return np.concatenate(points_v), np.concatenate(points_q)
