"""Free decay of the vibration after a burst (ring-down), with amplitude-dependent damping.

Once the drive stops, the velocity envelope v (peak velocity at the antinode) of a mode at
f_r loses the fraction 2 pi / Q of its energy per cycle, so

    dv/dt = -pi f_r v / Q(v),   i.e.   t(v) = (1 / (pi f_r)) * integral_v^v0 Q(u) / u du.

For the laws with a power-law loss, 1/Q = 1/Q0 + alpha |v|^n, this is a Bernoulli equation
with a closed form (a = pi f_r / Q0, b = pi f_r alpha):

    n = 2:  v(t)^2 = a v0^2 e^(-2at) / (a + b v0^2 (1 - e^(-2at)))
    n = 1:  v(t)   = a v0 e^(-at) / (a + b v0 (1 - e^(-at)))

and a constant Q decays exponentially.  The flexible law is linear in v^2 on each segment, where the
integral has the same closed form: its decay is exact segment by segment (:func:`spline_decay`).  Any
other law is tabulated: t(v) by quadrature on a grid in ln v, then inverted (:func:`decay_on_grid`),
vectorised over walkers and bursts, without a time-stepping loop.  The resonance's small shift with
amplitude (softening) is neglected during the decay.
"""

import numpy as np
from scipy import special

from workflow.damping.laws import ConstantQ, LinearLoss, MonotoneSpline, QuadraticLoss

CLOSED_FORMS = (ConstantQ, QuadraticLoss, LinearLoss, MonotoneSpline)
"""Laws whose decay has a closed form, evaluated at each sample [-]."""


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
    if isinstance(law, MonotoneSpline):
        return spline_decay(spline_schedule(law, f, v0), f, t)
    if not isinstance(law, CLOSED_FORMS):
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


def _log1p_ratio(z):
    """ln(1 + z) / z, 1 at z = 0 [-]."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(z == 0, 1.0, np.log1p(z) / np.where(z == 0, 1.0, z))


def spline_schedule(law: MonotoneSpline, frequency, initial_velocity) -> np.ndarray:
    """Where and when a decay from ``initial_velocity`` [m/s] enters each segment of the flexible law.

    On a segment 1/Q = c + m v^2 (:attr:`~workflow.damping.laws.MonotoneSpline.segments`), from v_a with
    1/Q(v_a) = L_a, the decay integrates exactly to

        v(t)^2 = v_a^2 / (1 + a exprel(a q)),   a = 2 pi f t L_a,   q = c / L_a,

    exprel(x) = (e^x - 1) / x, so the time to fall from v_a^2 to y is (y_a / y - 1) ln(1 + z) / z / (2 pi f L_a),
    z = q (v_a^2 / y - 1).  The decay starts in the segment of v0 and enters each lower one at its upper knot.

    Returns
    -------
    numpy.ndarray (4, 8, ...)
        Per segment (second axis) and element of the broadcast ``frequency`` [Hz], ``initial_velocity`` and law
        parameters: the time the decay enters it [s] (inf: never), v^2 [m^2/s^2] and 1/Q [-] there, and its slope m
        [s^2/m^2].
    """
    squared, loss, slope = law.segments
    y0 = np.square(initial_velocity)
    shape = np.broadcast_shapes(np.shape(frequency), y0.shape, *(np.shape(x) for x in squared + loss + slope))
    lower, knot_loss, slope = (np.stack([np.broadcast_to(x, shape) for x in group]) for group in (squared, loss, slope))
    rate = 2 * np.pi * np.broadcast_to(frequency, shape)
    first = np.sum(lower[1:] <= y0, axis=0)  # the segment of v0
    segment = np.arange(len(lower)).reshape((-1,) + (1,) * len(shape))
    start_y = np.where(segment == first, y0, np.append(lower[1:], lower[-1:], axis=0))
    start_loss = np.where(segment == first, law.loss(np.sqrt(y0)), np.append(knot_loss[1:], knot_loss[-1:], axis=0))
    ratio = start_y[1:] / lower[1:] - 1  # y_a / y_b - 1 down to the lower knot of each segment but the first
    crossing = ratio * _log1p_ratio((1 - slope[1:] * start_y[1:] / start_loss[1:]) * ratio) / (rate * start_loss[1:])
    crossing = np.where(segment[1:] <= first, crossing, 0.0)
    reached = np.cumsum(crossing[::-1], axis=0)[::-1]  # time from v0 down to the upper knot of each segment but the last
    start_time = np.where(segment < first, np.append(reached, reached[-1:], axis=0), np.where(segment == first, 0.0, np.inf))
    return np.stack([start_time, start_y, start_loss, slope])


def spline_decay(schedule: np.ndarray, frequency, time):
    """v(t) [m/s] of the decay :func:`spline_schedule` describes, at ``time`` [s] (broadcasting against its elements)."""
    time = np.asarray(time)
    shape = np.broadcast_shapes(schedule.shape[2:], time.shape)
    schedule = np.broadcast_to(schedule.reshape(schedule.shape[:2] + (1,) * (len(shape) + 2 - schedule.ndim)
                                                + schedule.shape[2:]), schedule.shape[:2] + shape)
    segment = np.argmax(schedule[0] <= time, axis=0)  # the deepest segment entered by then
    start_time, start_y, start_loss, slope = np.take_along_axis(schedule, segment[None, None], axis=1)[:, 0]
    a = 2 * np.pi * np.asarray(frequency) * (time - start_time) * start_loss
    return np.sqrt(start_y / (1 + a * special.exprel(a * (1 - slope * start_y / start_loss))))


QUADRATURE_NODES = 128
"""Nodes of the quadrature of t(v) on the ln v grid of :func:`decay_on_grid` [-]."""
MAX_DROP = 50.0
"""Deepest fall of ln v tabulated [-]: below e^-50 v0 the decay continues at the last node's rate."""


def integrated_decay(quality_factor, frequency, initial_velocity, time, nodes=QUADRATURE_NODES):
    """v(t) of dv/dt = -pi f v / Q(v) for any law, by quadrature in ln v (:func:`decay_on_grid`) [m/s].

    Vectorised over everything: the arguments broadcast to one shape, and the table runs once over
    the distinct times (a record's samples are shared by its bursts).
    """
    f, v0, t = (np.asarray(x, dtype=float) for x in (frequency, initial_velocity, time))
    with np.errstate(invalid="ignore", divide="ignore"):
        shape = np.broadcast_shapes(f.shape, v0.shape, t.shape, np.shape(quality_factor(v0)))  # with Q's parameters
    f, v0, t = (np.broadcast_to(x, shape) for x in (f, v0, t))
    grid, where = np.unique(t, return_inverse=True)
    values = decay_on_grid(quality_factor, f, v0, grid, nodes)
    return np.take_along_axis(values, where.reshape((1,) + t.shape), axis=0)[0]


def _cumulative_integral(values, step):
    """integral from node 0 to each node of a function sampled at equal ``step`` along the first axis (>= 4 nodes).

    Fourth order: each interval integrates the cubic through its four nearest nodes, weights (-1, 13, 13, -1) / 24
    inside and (9, 19, -5, 1) / 24 at the ends.
    """
    inner = (13 * (values[1:-2] + values[2:-1]) - values[:-3] - values[3:]) / 24
    first = (9 * values[0] + 19 * values[1] - 5 * values[2] + values[3]) / 24
    last = (values[-4] - 5 * values[-3] + 19 * values[-2] + 9 * values[-1]) / 24
    pieces = np.concatenate([first[None], inner, last[None]]) * step
    return np.concatenate([np.zeros_like(values[:1]), np.cumsum(pieces, axis=0)])


def decay_on_grid(quality_factor, frequency, initial_velocity, grid, nodes=QUADRATURE_NODES):
    """v at each time of the sorted ``grid`` [s] (>= 0) for every element of the broadcast ``frequency`` [Hz] and
    ``initial_velocity`` [m/s]: shape ``(len(grid),) + broadcast shape`` [m/s].

    The exact solution t(x) = (1 / (pi f)) integral_0^x Q(v0 e^-u) du, x = ln(v0 / v), is tabulated on ``nodes``
    + 1 equal steps of x from 0 to the largest fall the record allows, pi f t_end / Q(v0) (Q only grows as v
    falls; at most :data:`MAX_DROP`), with one vectorised Q(v) call and a fourth-order quadrature
    (:func:`_cumulative_integral`), then inverted at the grid's times by cubic Hermite interpolation of x(t),
    whose slope dx/dt = pi f / Q is known at every node.  Accuracy: |delta ln v| < 1e-7 over a record that
    falls by e^-5 (tested against the closed forms).
    """
    f, v0 = (np.asarray(x, dtype=float) for x in (frequency, initial_velocity))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        q_start = quality_factor(v0)
    f, v0 = (np.broadcast_to(x, np.broadcast_shapes(f.shape, v0.shape, q_start.shape)) for x in (f, v0))
    grid = np.asarray(grid, dtype=float)
    end = float(grid[-1]) if grid.size else 0.0
    if end <= 0.0:
        return np.broadcast_to(v0, grid.shape + v0.shape).copy()
    rate = np.pi * f
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        drop = np.minimum(_largest_fall(quality_factor, v0, rate * end, q_start), MAX_DROP)
        fall = drop * np.linspace(0.0, 1.0, nodes + 1).reshape((-1,) + (1,) * v0.ndim)
        q = quality_factor(v0 * np.exp(-fall))
        elapsed = _cumulative_integral(q, drop / nodes) / rate  # t at each node
        slope = rate / q  # dx/dt at each node
    elapsed, slope, fall = (np.ascontiguousarray(np.broadcast_to(x, q.shape).reshape(nodes + 1, -1).T)
                            for x in (elapsed, slope, fall))
    x = _inverse_hermite(elapsed, fall, slope, grid)
    return np.exp(-x.T).reshape(grid.shape + v0.shape) * v0


FALL_STEPS, FALL_PASSES = 8, 2
"""Steps and passes of the lower Riemann sums that bound the fall of ln v over a record (:func:`_largest_fall`) [-]."""


def _largest_fall(quality_factor, initial_velocity, budget, q_start):
    """An upper bound of x = ln(v0 / v) at the end of a record, ``budget`` = pi f t_end [-]; ``q_start`` = Q(v0).

    Q only grows as v falls, so pi f t(x) = integral_0^x Q(v0 e^-u) du is bounded below by its left Riemann sum
    on any grid: from the first bound budget / Q(v0), each pass sums Q on :data:`FALL_STEPS` equal steps up to
    the current bound and moves the bound to where that sum spends the budget (one Q(v) call per pass).  Tighter
    than budget / Q(v0) where Q rises during the decay, so the quadrature's nodes fall where the decay goes.
    """
    bound = budget / q_start  # Q(v0)
    fraction = (np.arange(FALL_STEPS) / FALL_STEPS).reshape((-1,) + (1,) * np.ndim(bound))
    for _ in range(FALL_PASSES):
        width = bound / FALL_STEPS
        q = quality_factor(initial_velocity * np.exp(-fraction * bound))
        spent = np.cumsum(q, axis=0) * width  # the lower sum at the end of each step
        step = np.minimum(np.sum(spent < budget, axis=0), FALL_STEPS - 1)[None]  # where the budget runs out
        q_step = np.take_along_axis(q, step, axis=0)[0]
        before = np.take_along_axis(spent, step, axis=0)[0] - q_step * width
        bound = np.minimum(bound, step[0] * width + (budget - before) / q_step)
    return bound


def _inverse_hermite(elapsed, fall, slope, grid):
    """x at each time of the sorted ``grid``, from rows of increasing times ``elapsed`` (R, K + 1) at which x =
    ``fall`` with slope dx/dt = ``slope``: cubic Hermite on the interval holding each time; past a row's last node,
    the last slope continued.  Shape (R, G).

    The interval of each time is found without a search per row: every node's place among the grid's times
    (one search into ``grid``), then per row the count of nodes at or before each time (one histogram).
    """
    rows, nodes = elapsed.shape[0], elapsed.shape[1] - 1
    place = np.searchsorted(grid, np.where(np.isnan(elapsed), np.inf, elapsed), side="left")  # times before each node
    place = np.maximum.accumulate(place, axis=1)  # non-decreasing along each row, whatever rounding did
    counts = np.bincount((place + (len(grid) + 1) * np.arange(rows)[:, None]).ravel(), minlength=rows * (len(grid) + 1))
    index = np.cumsum(counts.reshape(rows, -1), axis=1)[:, :-1] - 1  # node at or before each time, (R, G)
    lower = np.minimum(index, nodes - 1) + (nodes + 1) * np.arange(rows)[:, None]  # flat, into the tables
    t0, t1, x0, x1, s0, s1 = (table.ravel()[at] for table in (elapsed, fall, slope) for at in (lower, lower + 1))
    width = t1 - t0
    with np.errstate(invalid="ignore", divide="ignore"):
        u = (grid - t0) / width
        hermite = ((1 + 2 * u) * (1 - u) ** 2 * x0 + u * (1 - u) ** 2 * width * s0 + u**2 * (3 - 2 * u) * x1
                   - u**2 * (1 - u) * width * s1)
    return np.where(index >= nodes, x1 + (grid - t1) * s1, hermite)


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

    Closed forms are evaluated at each sample (the flexible law's segment schedule once per walker and burst); any
    other law is tabulated once per walker and burst over the distinct sample times (:func:`decay_on_grid`).
    """
    frequency = np.asarray(frequency)
    if isinstance(law, CLOSED_FORMS) and not isinstance(law, MonotoneSpline):
        return decay_velocity(law, frequency[burst], initial_velocity[:, burst], time)
    grid, where = np.unique(time, return_inverse=True)
    if isinstance(law, MonotoneSpline):
        values = spline_decay(spline_schedule(law, frequency, initial_velocity), frequency, grid[:, None, None])
    else:
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
