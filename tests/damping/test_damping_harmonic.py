"""The self-consistent harmonic solve against closed forms and an independent root finder."""

import numpy as np
import pytest
from scipy.optimize import brentq

from instruments.simulator.physics import plate_response
from workflow.damping.harmonic import (
    HarmonicSolveError,
    response_amplitude,
    self_consistent_amplitude,
    self_consistent_deflection,
)
from workflow.damping.laws import ConstantQ, LinearLoss, QuadraticLoss


def brent_amplitude(w_s, f, f_r, quality_factor):
    """The root of w - w(Q(2 pi f w)) on [0, w(Q(0))] by Brent's method, one element at a time."""

    def residual(w):
        return w - response_amplitude(w_s, f / f_r, quality_factor(2 * np.pi * f * w))

    return brentq(residual, 0.0, response_amplitude(w_s, f / f_r, quality_factor(0.0)), xtol=1e-30, rtol=1e-15)


def test_quadratic_law_at_resonance_is_cardanos_root():
    # At r = 1: w (1/Q0 + alpha omega^2 w^2) = w_s, the depressed cubic w^3 + p w + q = 0 with p > 0.
    q0, alpha, f_r = 150.0, 0.25, 31e3
    w_s = np.array([1e-12, 1e-10, 5e-9, 2e-8, 1e-7])
    a = alpha * (2 * np.pi * f_r) ** 2
    p, q = 1 / (q0 * a), -w_s / a
    root = np.sqrt(q**2 / 4 + p**3 / 27)
    expected = np.cbrt(-q / 2 + root) + np.cbrt(-q / 2 - root)
    w = self_consistent_amplitude(w_s, f_r, f_r, QuadraticLoss(q0, alpha).quality_factor)
    assert np.allclose(w, expected, rtol=1e-9, atol=0)


def test_linear_law_at_resonance_solves_the_quadratic():
    q0, alpha, f_r, w_s = 120.0, 0.5, 30e3, 1e-8
    a, b, c = alpha * 2 * np.pi * f_r, 1 / q0, -w_s
    expected = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    assert self_consistent_amplitude(w_s, f_r, f_r, LinearLoss(q0, alpha).quality_factor) == pytest.approx(expected, rel=1e-9)


def test_constant_q_is_the_linear_response():
    f = np.linspace(29e3, 33e3, 41)
    w = self_consistent_amplitude(1e-8, f, 31e3, ConstantQ(54.0).quality_factor)
    assert np.allclose(w, response_amplitude(1e-8, f / 31e3, 54.0), rtol=1e-12)


def test_walker_shaped_parameters_match_brents_method_off_resonance():
    rng = np.random.default_rng(4)
    f = np.linspace(30e3, 32e3, 41)
    law = QuadraticLoss(rng.uniform(80, 300, (8, 1)), rng.uniform(0.05, 1.0, (8, 1)))
    w = self_consistent_amplitude(2e-8, f, 31e3, law.quality_factor)
    assert w.shape == (8, 41)
    for i in range(8):
        single = QuadraticLoss(law.q0[i, 0], law.alpha[i, 0])
        expected = [brent_amplitude(2e-8, fj, 31e3, single.quality_factor) for fj in f]
        assert np.allclose(w[i], expected, rtol=1e-10, atol=0)


@pytest.mark.parametrize("rtol", [1e-4, 1e-8, 1e-12])
def test_the_tolerance_bounds_the_relative_error(rtol):
    law = QuadraticLoss(150.0, 2.0)  # strongly saturated: w(Q(0)) is ~40 times the root at resonance
    f = np.linspace(30.5e3, 31.5e3, 21)
    w = self_consistent_amplitude(1e-7, f, 31e3, law.quality_factor, rtol=rtol)
    expected = np.array([brent_amplitude(1e-7, fj, 31e3, law.quality_factor) for fj in f])
    assert np.max(np.abs(np.log(w / expected))) <= rtol


def test_the_simulated_bench_has_one_branch_and_the_solver_finds_it():
    # The simulator's default law at twice the campaign's highest drive, over the sweep span:
    # w - w(Q(2 pi f w)) changes sign exactly once on a fine scan of [0, w(Q(0))].
    response = plate_response()
    f_r = response.resonance_frequency
    f = np.linspace(f_r - 800.0, f_r + 800.0, 33)
    w_s = response.deflection_per_volt * 30.0
    w = self_consistent_amplitude(w_s, f, f_r, response.law.quality_factor)
    for fj, wj in zip(f, w):
        upper = response_amplitude(w_s, fj / f_r, response.law.quality_factor(0.0))
        scan = np.linspace(0.0, upper, 20001)
        residual = scan - response_amplitude(w_s, fj / f_r, response.law.quality_factor(2 * np.pi * fj * scan))
        crossings = np.flatnonzero(np.diff(np.sign(residual)) != 0)
        assert len(crossings) == 1
        assert scan[crossings[0]] <= wj <= scan[crossings[0] + 1]


def test_a_multi_mode_deflection_matches_brents_method():
    # Two modes near each other, as the FEM's deflection_at_q sees them, with the quadratic law.
    omega = 2 * np.pi * 31e3
    eigenvalues, forces = omega**2 * np.array([1.0, 1.02]), np.array([1.0, 0.3])

    def deflection_at_q(q):
        loss = 1 / np.asarray(q, dtype=float)[..., None]
        return np.abs(np.sum(1e-8 * omega**2 * forces / (eigenvalues * (1 + 1j * loss) - omega**2), axis=-1))

    law = QuadraticLoss(150.0, 0.25)
    w = self_consistent_deflection(deflection_at_q, law.quality_factor, omega)
    expected = brentq(lambda x: x - deflection_at_q(law.quality_factor(omega * x)), 0.0,
                      deflection_at_q(law.quality_factor(0.0)), xtol=1e-30, rtol=1e-15)
    assert float(w) == pytest.approx(expected, rel=1e-10)


def test_zero_drive_gives_zero_deflection():
    w = self_consistent_amplitude(np.array([0.0, 1e-8]), 31e3, 31e3, QuadraticLoss(150.0, 0.25).quality_factor)
    assert w[0] == 0.0 and w[1] > 0


def test_more_drive_more_deflection_and_more_loss_less_deflection():
    f_r = 31e3
    w_s = np.linspace(1e-9, 5e-8, 50)
    w = self_consistent_amplitude(w_s, f_r, f_r, QuadraticLoss(150.0, 0.25).quality_factor)
    assert np.all(np.diff(w) > 0)
    alphas = np.linspace(0.0, 2.0, 21)[:, None]
    w_alpha = self_consistent_amplitude(2e-8, f_r, f_r, QuadraticLoss(150.0, alphas).quality_factor)
    assert np.all(np.diff(w_alpha[:, 0]) < 0)
    # saturation: the deflection grows slower than the drive
    assert w[-1] / w[0] < w_s[-1] / w_s[0]


def test_a_law_increasing_with_velocity_is_reported():
    def growing(v):
        return 50 + 1e6 * np.asarray(v) ** 2

    with pytest.raises(HarmonicSolveError, match="did not converge to rtol=1e-12 in 50 iterations"):
        self_consistent_amplitude(1e-7, 31e3, 31e3, growing)


def test_a_non_finite_input_is_reported():
    with pytest.raises(HarmonicSolveError, match="inputs finite"):
        self_consistent_amplitude(np.array([1e-8, np.nan]), 31e3, 31e3, QuadraticLoss(150.0, 0.25).quality_factor)
