"""Steady-state harmonic response with amplitude-dependent damping, solved self-consistently.

A single resonant mode driven at frequency f has the deflection amplitude

    w = w_s / sqrt((1 - r^2)^2 + (r / Q)^2),   r = f / f_r,

with w_s the quasi-static deflection (at resonance w = Q w_s).  When Q depends on the
velocity amplitude v = 2 pi f w, w appears on both sides.  Because every Q(v) law is
non-increasing in v, h(w) = w - w(Q(2 pi f w)) is strictly increasing: the root is unique
and bracketed by [0, w(Q(0))], so a bracketing iteration always converges.

Two solvers: :func:`self_consistent_amplitude` needs only Q(v) (Illinois iteration);
:func:`self_consistent_amplitude_newton` uses the law's loss 1/Q and its slope for a
safeguarded Newton iteration, several times faster (the fit's inner loop).
"""

import numpy as np

from workflow.errors import TactileError


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


def self_consistent_amplitude(static_amplitude, frequency, resonance_frequency, quality_factor, rtol=1e-10, max_iter=200):
    """Solve w = w_s / sqrt((1 - r^2)^2 + (r / Q(2 pi f w))^2) for w, elementwise [m].

    Vectorised Illinois (modified regula falsi) iteration on the bracket [0, w(Q(0))]:
    it always converges because the residual is monotone.

    Parameters
    ----------
    static_amplitude : array
        Quasi-static deflection w_s [m], >= 0.
    frequency : array
        Drive frequency f [Hz].
    resonance_frequency : array
        f_r [Hz].
    quality_factor : callable
        Q(v) with v the peak velocity amplitude [m/s]; non-increasing in v.
    rtol : float
        Relative tolerance on w.
    max_iter : int

    Returns
    -------
    numpy.ndarray
        The deflection amplitude w [m], broadcast shape of the inputs.

    Raises
    ------
    HarmonicSolveError
        If the tolerance is not met (only with a law that is not non-increasing).
    """
    w_s, f, f_r = (np.asarray(x, dtype=float) for x in (static_amplitude, frequency, resonance_frequency))
    ratio = f / f_r
    return self_consistent_deflection(
        lambda q: response_amplitude(w_s, ratio, q), quality_factor, 2 * np.pi * f, rtol, max_iter
    )


def self_consistent_deflection(deflection_at_q, quality_factor, angular_frequency, rtol=1e-10, max_iter=200):
    """Solve w = D(Q(omega w)) for w, elementwise, with D increasing in Q [m].

    The general form of the self-consistent solve, for any deflection-versus-Q function
    (e.g. the FEM's ``FemResult.deflection_at_q``): vectorised Illinois (modified regula
    falsi) iteration on the bracket [0, D(Q(0))].  Because D increases with Q and Q(v) is
    non-increasing, the residual w - D(Q(omega w)) is increasing and the root unique.

    Parameters
    ----------
    deflection_at_q : callable
        D(Q) [m], vectorised.
    quality_factor : callable
        Q(v) with v the peak velocity amplitude [m/s]; non-increasing in v.
    angular_frequency : array
        omega = 2 pi f [rad/s], so that v = omega w.
    rtol : float
        Relative tolerance on w.
    max_iter : int

    Returns
    -------
    numpy.ndarray
        w [m], broadcast shape of D's output and omega.

    Raises
    ------
    HarmonicSolveError
        If the tolerance is not met (only with a law that is not non-increasing).
    """
    omega = np.asarray(angular_frequency, dtype=float)
    high = np.asarray(deflection_at_q(quality_factor(np.zeros_like(omega))), dtype=float)
    omega, high = np.broadcast_arrays(omega, high)
    high = high.astype(float)

    def residual(w):
        return w - deflection_at_q(quality_factor(omega * w))

    low = np.zeros_like(high)
    r_low, r_high = residual(low), residual(high)
    side = np.zeros(high.shape, dtype=int)
    scale = np.maximum(high, np.finfo(float).tiny)
    for _ in range(max_iter):
        if np.all(high - low <= rtol * scale):
            break
        denominator = r_high - r_low
        guess = np.where(denominator != 0, (low * r_high - high * r_low) / np.where(denominator != 0, denominator, 1), 0.5 * (low + high))
        guess = np.clip(guess, low, high)
        r_guess = residual(guess)
        go_high = r_guess > 0  # root below guess: guess becomes the new high end
        new_low = np.where(go_high, low, guess)
        new_high = np.where(go_high, guess, high)
        new_r_low = np.where(go_high, r_low, r_guess)
        new_r_high = np.where(go_high, r_guess, r_high)
        # Illinois: halve the residual of the end that stayed twice in a row.
        r_low_kept = np.where(go_high & (side == 1), 0.5 * new_r_low, new_r_low)
        r_high_kept = np.where(~go_high & (side == -1), 0.5 * new_r_high, new_r_high)
        side = np.where(go_high, 1, -1)
        exact = r_guess == 0
        low, high = np.where(exact, guess, new_low), np.where(exact, guess, new_high)
        r_low, r_high = np.where(exact, 0.0, r_low_kept), np.where(exact, 0.0, r_high_kept)
    else:
        if not np.all(high - low <= rtol * scale):
            raise HarmonicSolveError(
                f"self-consistent deflection did not converge to rtol={rtol:g} in {max_iter} iterations; "
                "is the Q(v) law non-increasing in v?"
            )
    return 0.5 * (low + high)


def self_consistent_amplitude_newton(static_amplitude, frequency, resonance_frequency, law, rtol=1e-10, max_iter=100):
    """Solve w = w_s / sqrt((1 - r^2)^2 + (r / Q(2 pi f w))^2) for w with Newton's method [m].

    With eta = 1/Q and D(w) = (1 - r^2)^2 + r^2 eta(2 pi f w)^2, the root of
    F(w) = w sqrt(D(w)) - w_s is sought from the bracket's upper end w = w(Q(0)), where
    F >= 0.  F is increasing, and convex for the quadratic and linear laws (a product of
    increasing convex functions), so the Newton iterates fall monotonically onto the
    root; a step that leaves the bracket [low, high] is replaced by bisection, so any
    non-increasing Q(v) converges.

    Parameters
    ----------
    static_amplitude : array
        Quasi-static deflection w_s [m], >= 0.
    frequency : array
        Drive frequency f [Hz].
    resonance_frequency : array
        f_r [Hz].
    law : object
        A Q(v) law with ``loss(v)`` = 1/Q [-] and ``loss_slope(v)`` = d(1/Q)/dv [s/m]
        (see :mod:`workflow.damping.laws`); parameters may be arrays that broadcast.
    rtol : float
        Relative tolerance on w.
    max_iter : int

    Returns
    -------
    numpy.ndarray
        The deflection amplitude w [m], broadcast shape of the inputs and the law's parameters.

    Raises
    ------
    HarmonicSolveError
        If the tolerance is not met in ``max_iter`` iterations.
    """
    w_s, f, f_r = (np.asarray(x, dtype=float) for x in (static_amplitude, frequency, resonance_frequency))
    ratio2 = (f / f_r) ** 2
    detuning2 = (1 - ratio2) ** 2
    omega = 2 * np.pi * f
    high = w_s / np.sqrt(detuning2 + ratio2 * law.loss(0.0 * omega) ** 2)
    shape = np.broadcast(high, omega, law.loss(omega)).shape
    high = np.broadcast_to(high, shape).copy()
    low = np.zeros(shape)
    w = high.copy()
    for _ in range(max_iter):
        velocity = omega * w
        loss = law.loss(velocity)
        root = np.sqrt(detuning2 + ratio2 * loss**2)
        residual = w * root - w_s
        slope = root + ratio2 * loss * law.loss_slope(velocity) * velocity / root
        above = residual > 0
        high = np.where(above, w, high)
        low = np.where(above, low, w)
        newton = w - residual / slope
        w_new = np.where((newton >= low) & (newton <= high), newton, 0.5 * (low + high))
        converged = np.abs(w_new - w) <= rtol * w_new
        w = w_new
        if np.all(converged | (residual == 0)):
            return w
    raise HarmonicSolveError(
        f"self-consistent deflection (Newton) did not converge to rtol={rtol:g} in {max_iter} iterations"
    )
