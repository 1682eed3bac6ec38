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
    w_s, f, f_r = (np.asarray(x, dtype=float) for x in (static_amplitude, frequency, resonance_frequency))
    ratio2 = (f / f_r) ** 2
    detuning2 = (1 - ratio2) ** 2

    def deflection_at_q(q):
        return w_s / np.sqrt(detuning2 + ratio2 / q**2)

    return self_consistent_deflection(deflection_at_q, quality_factor, 2 * np.pi * f, rtol, max_iter)


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
    omega = np.asarray(angular_frequency, dtype=float)
    start = np.asarray(deflection_at_q(quality_factor(np.zeros_like(omega))), dtype=float)
    omega, start = np.broadcast_arrays(omega, start)
    driven = start != 0  # NaN stays in and is reported

    def residual(u):
        deflection = deflection_at_q(quality_factor(omega * np.exp(u)))
        return u - np.log(np.where(driven, deflection, 1.0))

    u0 = np.log(np.where(driven, start, 1.0))
    h0 = residual(u0)
    low, high = u0 - h0, u0
    u1 = u0 - FIRST_STEP
    h1 = residual(u1)
    for _ in range(max_iter):
        done = np.abs(h1) <= rtol
        if np.all(done):
            return np.where(driven, np.exp(u1), 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):  # h1 == h0 where done (held below)
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
