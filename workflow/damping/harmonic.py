"""Steady-state harmonic response with amplitude-dependent damping, solved self-consistently.

A single resonant mode driven at frequency f has the deflection amplitude

    w = w_s / sqrt((1 - r^2)^2 + (r / Q)^2),   r = f / f_r,

with w_s the quasi-static deflection (at resonance w = Q w_s).  When Q depends on the
velocity amplitude v = 2 pi f w, w appears on both sides.  One solver,
:func:`self_consistent_deflection`, solves the general form w = D(Q(omega w)) for any
deflection D increasing in Q (the single mode above, or the FEM's multi-mode
``deflection_at_q``); :func:`self_consistent_amplitude` is its single-mode case, used by
the bench simulator, the fit's forward model and the beam design alike.

Because every Q(v) law is non-increasing in v, T(w) = D(Q(omega w)) is non-increasing and
the residual in u = ln w, H(u) = u - ln T(e^u), has slope dH/du >= 1: the root is unique
(no second branch), bracketed by [ln T(w_0), ln w_0] with w_0 = D(Q(0)), and
|ln w - ln w*| <= |H(ln w)| at any w, so the residual bounds the error.

A resonance that softens with amplitude, f_r(v) = f_r0 (1 - kappa v^2), breaks that
monotonicity: the curve can fold over and a frequency can have two stable amplitudes.
:func:`softened_amplitudes` then solves a sweep's points in their measuring order, each from
the previous one's amplitude (:func:`follow_branch`, :func:`root_near`), vectorised across
walkers and sweeps; :func:`single_valued` proves where the order cannot matter.
"""

import numpy as np

from workflow.errors import TactileError

FIRST_STEP = 1e-7
"""Relative size of the first secant step below w_0 = D(Q(0)) [-] (a finite-difference Newton step)."""


class HarmonicSolveError(TactileError):
    """The self-consistent solve did not reach its tolerance."""


def response_amplitude(static_amplitude, frequency_ratio, q):
    """Deflection amplitude of a driven mode with constant Q [m].

    Parameters
    ----------
    static_amplitude : array
        Quasi-static deflection w_s [m] (w at resonance divided by Q).
    frequency_ratio : array
        r = f / f_r [-].
    q : array
        Quality factor [-].
    """
    r = np.asarray(frequency_ratio)
    return np.asarray(static_amplitude) / np.sqrt((1 - r**2) ** 2 + (r / np.asarray(q)) ** 2)


def self_consistent_amplitude(static_amplitude, frequency, resonance_frequency, quality_factor, rtol=1e-12, max_iter=50):
    """Solve w = w_s / sqrt((1 - r^2)^2 + (r / Q(2 pi f w))^2), r = f / f_r, for w, elementwise [m].

    The single-mode case of :func:`self_consistent_deflection` (same tolerance and errors).

    Parameters
    ----------
    static_amplitude : array
        Quasi-static deflection w_s [m], >= 0.
    frequency : array
        Drive frequency f [Hz].
    resonance_frequency : array
        f_r [Hz].
    quality_factor : callable
        Q(v) with v the peak velocity amplitude [m/s], non-increasing in v; its parameters
        may be arrays that broadcast (one row per walker, posterior draw or geometry).
    rtol : float
        Tolerance on ln w (relative error of w) [-].
    max_iter : int

    Returns
    -------
    numpy.ndarray
        The deflection amplitude w [m], broadcast shape of the inputs and Q's parameters.
    """
    return self_consistent_deflection(single_mode_deflection(static_amplitude, frequency, resonance_frequency),
                                      quality_factor, 2 * np.pi * np.asarray(frequency, dtype=float), rtol, max_iter)


def single_mode_deflection(static_amplitude, frequency, resonance_frequency):
    """D(Q) = w_s / sqrt((1 - r^2)^2 + (r / Q)^2), r = f / f_r, of one driven mode, as a function of Q [m]."""
    w_s, f, f_r = (np.asarray(x, dtype=float) for x in (static_amplitude, frequency, resonance_frequency))
    ratio2 = (f / f_r) ** 2
    detuning2 = (1 - ratio2) ** 2

    def deflection_at_q(q):
        return w_s / np.sqrt(detuning2 + ratio2 / q**2)

    return deflection_at_q


def self_consistent_deflection(deflection_at_q, quality_factor, angular_frequency, rtol=1e-12, max_iter=50):
    """Solve w = D(Q(omega w)) for w, elementwise, with D increasing in Q [m].

    Secant iteration on H(u) = u - ln D(Q(omega e^u)), u = ln w, from u_0 = ln D(Q(0)),
    kept inside the bracket [ln D(Q(omega w_0)), u_0] (bisection when a step leaves it).
    dH/du >= 1, so the returned w has |ln w - ln w*| <= |H| <= ``rtol``; about seven
    iterations reach 1e-12 on the fit's campaigns.  D(Q(0)) = 0 gives w = 0.

    Parameters
    ----------
    deflection_at_q : callable
        D(Q) [m], vectorised, increasing in Q (e.g. the FEM's ``FemResult.deflection_at_q``).
    quality_factor : callable
        Q(v) with v the peak velocity amplitude [m/s]; non-increasing in v.
    angular_frequency : array
        omega = 2 pi f [rad/s], so that v = omega w.
    rtol : float
        Tolerance on ln w (relative error of w) [-]; above ~1e-13 (rounding of ln w).
    max_iter : int

    Returns
    -------
    numpy.ndarray
        w [m], broadcast shape of D's output and omega.

    Raises
    ------
    HarmonicSolveError
        If some element has not reached ``rtol`` after ``max_iter`` iterations (a Q(v)
        increasing with v, a D decreasing in Q, or non-finite inputs).
    """
    return np.exp(self_consistent_roots(deflection_at_q, quality_factor, angular_frequency, rtol, max_iter)[0])


def self_consistent_roots(deflection_at_q, quality_factor, angular_frequency, rtol=1e-12, max_iter=50, start=None,
                          slope=None):
    """ln w of :func:`self_consistent_deflection` (-inf where D(Q(0)) = 0), and the slope dH/du there [-].

    With ``start`` (a guess of ln w, at most u_0) and ``slope`` (of dH/du at the root), the iteration starts with
    the Newton step from ``start``, bracketed by dH/du >= 1 (the root lies within |H(start)| of it): from a
    neighbouring walker's root and slope, about 4 residual evaluations instead of 8; the root is unique, so only
    the tolerance separates the two.
    """
    omega = np.asarray(angular_frequency, dtype=float)
    w0 = np.asarray(deflection_at_q(quality_factor(np.zeros_like(omega))), dtype=float)
    omega, w0 = np.broadcast_arrays(omega, w0)
    driven = w0 != 0  # NaN stays in and is reported

    def residual(u):
        deflection = deflection_at_q(quality_factor(omega * np.exp(u)))
        return u - np.log(np.where(driven, deflection, 1.0))

    u0 = np.log(np.where(driven, w0, 1.0))
    if start is None:
        h0 = residual(u0)
        low, high = u0 - h0, u0
        u1 = u0 - FIRST_STEP
        h1 = residual(u1)
    else:  # dH/du >= 1 brackets the root within |H| of the start; a point beside it on the line of the given
        # slope makes the first secant step Newton's
        u1 = np.minimum(np.where(driven, start, u0), u0)
        h1 = residual(u1)
        low, high = np.where(h1 > 0, u1 - h1, u1), np.minimum(np.where(h1 > 0, u1, u1 - h1), u0)
        u0, h0 = u1 + FIRST_STEP, h1 + np.where(np.asarray(slope) >= 1, slope, 1.0) * FIRST_STEP
    with np.errstate(divide="ignore", invalid="ignore"):
        rate = (h1 - h0) / (u1 - u0)
    for _ in range(max_iter):
        done = np.abs(h1) <= rtol
        if np.all(done):
            return np.where(driven, u1, -np.inf), rate
        with np.errstate(divide="ignore", invalid="ignore"):  # h1 == h0 where done (held below)
            rate = np.where(done, rate, (h1 - h0) / (u1 - u0))
            secant = u1 - h1 * (u1 - u0) / (h1 - h0)
        u = np.where((secant >= low) & (secant <= high), secant, 0.5 * (low + high))
        u = np.where(done, u1, u)
        h = residual(u)
        low, high = np.where(h < 0, u, low), np.where(h > 0, u, high)
        u0, h0, u1, h1 = u1, h1, u, h
    raise HarmonicSolveError(
        f"self-consistent deflection did not converge to rtol={rtol:g} in {max_iter} iterations; "
        "is Q(v) non-increasing in v and are the inputs finite?"
    )


BRACKET_STEPS = np.array([0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
"""Distances in ln w tried, in the direction the residual points, to bracket the nearest root [-]."""
SECANT_STEPS = 8
"""Secant steps tried from the previous root before the bracketed search takes over."""


def root_near(residual, start, slope=1.0, rtol=1e-10, max_iter=60):
    """A root of ``residual`` near ``start``, elementwise: the one a continuation from ``start`` reaches.

    Used where the residual H(u) = u - ln T(e^u) can have several roots (a softening
    resonance folds over, :func:`follow_branch`).  H -> -inf as u -> -inf and +inf as
    u -> +inf, so from ``start`` a root lies in the direction -sign(H(start)).  A few
    secant steps from the Newton step u_1 = u_0 - H(u_0) / ``slope`` settle the elements
    whose branch continues; the others (a branch that ended at a fold, or a step that
    left in the wrong direction) are bracketed by steps of :data:`BRACKET_STEPS` in that
    direction and solved by the Illinois method.

    Parameters
    ----------
    residual : callable
        u -> H(u), vectorised, the shape of ``start``.
    start : numpy.ndarray
        Where the continuation starts (ln of the previous deflection) [-].
    slope : array
        Estimate of dH/du at the root (e.g. the previous point's); 1 is H's slope far from resonance.
    rtol : float
        Tolerance on |H| (relative error of w) [-].
    max_iter : int
        Illinois iterations at most.

    Returns
    -------
    roots : numpy.ndarray
        NaN where none was bracketed or ``start`` was not finite (the caller's
        log-probability turns it into -inf).
    slope : numpy.ndarray
        The last secant slope, an estimate of dH/du for a neighbouring point's solve.
    """
    start = np.asarray(start, dtype=float)
    u0, h0 = start, residual(start)
    direction = -np.sign(h0)
    slope = np.where(np.asarray(slope) >= 0.1, slope, 1.0)
    u1 = u0 - h0 / slope
    h1 = residual(u1)
    for _ in range(SECANT_STEPS):
        done = np.abs(h1) <= rtol
        if np.all(done):
            break
        with np.errstate(divide="ignore", invalid="ignore"):
            secant = (h1 - h0) / (u1 - u0)
            step = u1 - h1 / secant
        slope = np.where(done | ~np.isfinite(secant), slope, secant)
        u0, h0 = u1, h1
        u1 = np.where(done | ~np.isfinite(step), u1, step)
        h1 = np.where(done, h1, residual(u1))
    good = (np.abs(h1) <= rtol) & (np.sign(u1 - start) != -direction)
    if not np.all(good):
        u1 = np.where(good, u1, _bracketed_root(residual, start, direction, rtol, max_iter))
    return u1, slope


def _bracketed_root(residual, start, direction, rtol, max_iter):
    """The root nearest ``start`` in ``direction`` (bracket by growing steps, then Illinois), NaN if none."""
    h_start = residual(start)
    trials = start + direction * BRACKET_STEPS.reshape((-1,) + (1,) * start.ndim)
    h_trials = residual(trials)
    flipped = np.sign(h_trials) != np.sign(h_start)
    first = np.argmax(flipped, axis=0)
    found = np.take_along_axis(flipped, first[None], axis=0)[0] | (h_start == 0)
    b = np.take_along_axis(trials, first[None], axis=0)[0]
    hb = np.take_along_axis(h_trials, first[None], axis=0)[0]
    previous = np.where(first > 0, np.take_along_axis(trials, np.maximum(first - 1, 0)[None], axis=0)[0], start)
    h_previous = np.where(first > 0, np.take_along_axis(h_trials, np.maximum(first - 1, 0)[None], axis=0)[0], h_start)
    a, ha = previous, h_previous
    for _ in range(max_iter):
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.where(hb != ha, b - hb * (b - a) / (hb - ha), 0.5 * (a + b))
        hc = residual(c)
        done = np.abs(hc) <= rtol
        if np.all(done | ~found):
            return np.where(found, c, np.nan)
        same = np.sign(hc) == np.sign(hb)
        a, ha = np.where(same, a, b), np.where(same, 0.5 * ha, hb)
        b, hb = c, hc
    return np.where(found & (np.abs(hb) <= rtol), b, np.nan)


def follow_branch(residual, start, n_points, rtol=1e-10):
    """Roots u_p of ``residual(p, u) = 0`` for p = 0 .. n_points - 1, each continued from u_{p-1}.

    The self-consistent solve along a sweep, in the order it was measured: with a softening
    resonance a frequency can have two stable amplitudes, and the plate stays on the branch
    it is on until that branch ends (jump, hysteresis), so the start of point p's iteration
    is the amplitude of point p - 1 (:func:`root_near`).  Vectorised across everything but
    the points (walkers and sweeps solve together).

    Parameters
    ----------
    residual : callable
        (p, u) -> H_p(u), vectorised over the shape of ``start``.
    start : numpy.ndarray
        Start of the first point's iteration (ln deflection) [-].
    n_points : int
    rtol : float
        Tolerance on |H| [-].

    Returns
    -------
    numpy.ndarray
        u, shape ``start.shape + (n_points,)``; NaN where no root was found.
    """
    roots = []
    u, slope = np.asarray(start, dtype=float), 1.0
    for p in range(n_points):
        u, slope = root_near(lambda x: residual(p, x), u, slope, rtol)
        roots.append(u)
        u = np.where(np.isfinite(u), u, np.asarray(start, dtype=float))
    return np.stack(roots, axis=-1)


MIN_SOFTENED_FRACTION = 1e-3
"""f_r(v) = f_r0 (1 - kappa v^2) is held above this fraction of f_r0 (a guard far outside any fit's prior) [-]."""


def softened_resonance(resonance_frequency, softening, velocity):
    """f_r(v) = f_r0 (1 - kappa v^2) [Hz]: amplitude softening of the resonance.

    Parameters
    ----------
    resonance_frequency : array
        f_r0, the small-amplitude resonance [Hz].
    softening : array
        kappa [s^2/m^2], >= 0.
    velocity : array
        Peak velocity amplitude at the antinode [m/s].
    """
    return np.asarray(resonance_frequency) * np.maximum(1 - np.asarray(softening) * np.square(velocity), MIN_SOFTENED_FRACTION)


def softened_amplitudes(static_amplitude, frequency, resonance_frequency, softening, quality_factor, start=None,
                        follow=True, rtol=1e-10):
    """Deflection amplitudes along a sweep with Q(v) and softening [m].

    Solves w = w_s / sqrt((1 - r^2)^2 + (r / Q(v))^2), r = f / f_r(v), v = 2 pi f w,
    f_r(v) = f_r0 (1 - kappa v^2) (:func:`softened_resonance`).  With ``follow``, the points
    of the last axis are solved in the order they were measured, each continued from the
    previous one (:func:`follow_branch`): up and down sweeps give different curves when the
    resonance folds over.  Without it all points are solved at once (valid where
    :func:`single_valued` holds: then there is one root and the order does not matter).

    Parameters
    ----------
    static_amplitude, frequency, resonance_frequency : array (..., P)
        w_s [m], drive frequency [Hz], f_r0 [Hz] at each point, the last axis in measuring order.
    softening : array
        kappa [s^2/m^2], broadcasting against (..., P) without the last axis (e.g. (W, 1)).
    quality_factor : callable
        Q(v), v the antinode peak velocity [m/s]; parameters broadcast against (...).
    start : array, optional
        Deflection the plate had before the first point [m] (default: its small-amplitude response).
    follow : bool
    rtol : float

    Returns
    -------
    numpy.ndarray (..., P)
        w [m]; NaN where no root was found.
    """
    if not follow:
        return np.exp(softened_roots(static_amplitude, frequency, resonance_frequency, softening, quality_factor,
                                     rtol=rtol)[0])
    residual_at, (w_s, f, f_r0) = _softened_residual(static_amplitude, frequency, resonance_frequency, softening,
                                                      quality_factor)
    if start is None:
        start = response_amplitude(w_s[0], f[0] / f_r0[0], quality_factor(np.zeros_like(f[0])))
    return np.exp(follow_branch(residual_at, np.log(start), len(f), rtol))


def softened_roots(static_amplitude, frequency, resonance_frequency, softening, quality_factor, start=None, slope=1.0,
                   rtol=1e-10):
    """ln w of every point of :func:`softened_amplitudes` solved at once (no order: where :func:`single_valued`
    holds), from ``start``, and the slope dH/du there (to start a neighbouring solve).

    Parameters
    ----------
    static_amplitude, frequency, resonance_frequency, softening, quality_factor
        As :func:`softened_amplitudes`.
    start : array (..., P), optional
        ln w to start each point's iteration from (default: the small-amplitude response); with one root, any start
        reaches it, a near one in fewer residual evaluations (:func:`root_near`).
    slope : array (..., P)
        Estimate of dH/du at each root (1: far from resonance).
    rtol : float

    Returns
    -------
    roots, slope : numpy.ndarray (..., P)
        ln w [-] (NaN where no root was found) and the last secant slope [-].
    """
    residual_at, (w_s, f, f_r0) = _softened_residual(static_amplitude, frequency, resonance_frequency, softening,
                                                      quality_factor)
    if start is None:
        start = np.log(response_amplitude(w_s, f / f_r0, quality_factor(np.zeros_like(f))))
    else:
        start = np.moveaxis(np.broadcast_to(start, np.moveaxis(w_s, 0, -1).shape), -1, 0)
    slope = np.moveaxis(np.broadcast_to(slope, np.moveaxis(w_s, 0, -1).shape), -1, 0)
    roots, slope = root_near(lambda u: residual_at(Ellipsis, u), start, slope, rtol)
    return np.moveaxis(roots, 0, -1), np.moveaxis(slope, 0, -1)


def _softened_residual(static_amplitude, frequency, resonance_frequency, softening, quality_factor):
    """H_p(u) = u - ln w_s + ln A / 2 of the softened single mode as ``residual_at(point index, u)``, and the inputs
    with the points' axis first (w_s, f, f_r0)."""
    w_s, f, f_r0 = (np.moveaxis(x, -1, 0) for x in np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (static_amplitude, frequency, resonance_frequency))))
    kappa = np.asarray(softening, dtype=float)
    omega = 2 * np.pi * f
    ln_static = np.log(np.where(w_s > 0, w_s, np.nan))

    def residual_at(index, u):
        velocity = omega[index] * np.exp(u)
        ratio2 = (f[index] / softened_resonance(f_r0[index], kappa, velocity)) ** 2
        return u - ln_static[index] + 0.5 * np.log((1 - ratio2) ** 2 + ratio2 / quality_factor(velocity) ** 2)

    return residual_at, (w_s, f, f_r0)


SINGLE_VALUED_GRID = 16
"""Velocities at which :func:`single_valued` checks its bound [-]."""


def single_valued(static_amplitude, frequency, resonance_frequency, softening, quality_factor):
    """Whether every point of each sweep (last axis) has one self-consistent deflection, by a sufficient bound.

    With H(u) = u - ln w_s + ln A / 2, A = (1 - r^2)^2 + r^2 / Q^2, the softening term of
    dH/du is bounded using A >= 2 |1 - r^2| r / Q: |d ln A / du| <= 4 kappa v^2 Q(v) r / s
    with s = 1 - kappa v^2 (the loss term only adds to dH/du, Q being non-increasing), so
    H increases (one root) if 2 kappa v^2 Q(v) r / s < 1 for all v a root can reach, r <= f_max / (f_r0 s).
    A root has w <= w_s Q(v) / r, i.e. v / Q(v) <= 2 pi f_r0 w_s: the bound is checked on
    :data:`SINGLE_VALUED_GRID` velocities up to the first beyond that (a 10 % margin).

    Returns
    -------
    numpy.ndarray of bool, the shape of the inputs without the last axis.
    """
    w_s, f, f_r0 = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (static_amplitude, frequency, resonance_frequency)))
    kappa = np.asarray(softening, dtype=float)
    reach = 2 * np.pi * np.max(f_r0 * w_s, axis=-1)
    bound = reach * quality_factor(np.zeros(f.shape[:-1]))
    velocity = bound * np.linspace(0.0, 1.0, SINGLE_VALUED_GRID).reshape((-1,) + (1,) * bound.ndim)
    q = quality_factor(velocity)
    reachable = np.concatenate([np.ones_like(velocity[:1], dtype=bool), velocity[:-1] / q[:-1] <= 1.1 * reach])
    s = np.maximum(1 - kappa * velocity**2, MIN_SOFTENED_FRACTION)
    ratio = np.max(f, axis=-1) / np.min(f_r0, axis=-1) / s
    return np.max(np.where(reachable, 2 * kappa * velocity**2 * q * ratio / s, 0.0), axis=0) < 1
