"""The self-consistent harmonic solve: closed forms, agreement of the two solvers, monotonicity."""

import numpy as np
import pytest

from workflow.damping.harmonic import (
    HarmonicSolveError,
    response_amplitude,
    self_consistent_amplitude,
    self_consistent_amplitude_newton,
)
from workflow.damping.laws import ConstantQ, LinearLoss, QuadraticLoss

SOLVERS = {
    "illinois": lambda w_s, f, f_r, law: self_consistent_amplitude(w_s, f, f_r, law.quality_factor),
    "newton": self_consistent_amplitude_newton,
}


@pytest.mark.parametrize("solver", SOLVERS.values(), ids=SOLVERS.keys())
def test_quadratic_law_at_resonance_solves_the_cubic(solver):
    # At r = 1: w (1/Q0 + alpha omega^2 w^2) = w_s, a cubic with one positive root.
    q0, alpha, f_r = 150.0, 0.25, 31e3
    w_s = np.array([1e-10, 5e-9, 2e-8, 1e-7])
    omega = 2 * np.pi * f_r
    w = solver(w_s, f_r, f_r, QuadraticLoss(q0, alpha))
    for ws, wi in zip(w_s, w):
        roots = np.roots([alpha * omega**2, 0.0, 1 / q0, -ws])
        real = roots[np.abs(roots.imag) < 1e-12 * np.abs(roots).max()].real
        assert wi == pytest.approx(real[real > 0][0], rel=1e-9)


@pytest.mark.parametrize("solver", SOLVERS.values(), ids=SOLVERS.keys())
def test_linear_law_at_resonance_solves_the_quadratic(solver):
    q0, alpha, f_r, w_s = 120.0, 0.5, 30e3, 1e-8
    omega = 2 * np.pi * f_r
    a, b, c = alpha * omega, 1 / q0, -w_s
    expected = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    assert solver(w_s, f_r, f_r, LinearLoss(q0, alpha)) == pytest.approx(expected, rel=1e-9)


def test_constant_q_is_the_linear_response():
    f = np.linspace(29e3, 33e3, 41)
    w = self_consistent_amplitude_newton(1e-8, f, 31e3, ConstantQ(54.0))
    assert np.allclose(w, response_amplitude(1e-8, f / 31e3, 54.0), rtol=1e-12)


def test_solvers_agree_with_walker_shaped_parameters():
    rng = np.random.default_rng(4)
    f = np.linspace(30e3, 32e3, 101)
    law = QuadraticLoss(rng.uniform(80, 300, (16, 1)), rng.uniform(0.05, 1.0, (16, 1)))
    newton = self_consistent_amplitude_newton(2e-8, f, 31e3, law)
    illinois = self_consistent_amplitude(2e-8, f, 31e3, law.quality_factor)
    assert newton.shape == (16, 101)
    assert np.allclose(newton, illinois, rtol=1e-8)
    # and the result is self-consistent
    v = 2 * np.pi * f * newton
    assert np.allclose(newton, response_amplitude(2e-8, f / 31e3, law.quality_factor(v)), rtol=1e-8)


def test_more_drive_more_deflection_and_more_loss_less_deflection():
    f_r = 31e3
    w_s = np.linspace(1e-9, 5e-8, 50)
    w = self_consistent_amplitude_newton(w_s, f_r, f_r, QuadraticLoss(150.0, 0.25))
    assert np.all(np.diff(w) > 0)
    alphas = np.linspace(0.0, 2.0, 21)[:, None]
    w_alpha = self_consistent_amplitude_newton(2e-8, f_r, f_r, QuadraticLoss(150.0, alphas))
    assert np.all(np.diff(w_alpha[:, 0]) < 0)
    # saturation: the deflection grows slower than the drive
    assert w[-1] / w[0] < w_s[-1] / w_s[0]


def test_a_law_increasing_with_velocity_is_reported():
    class Growing:
        def quality_factor(self, v):
            return 50 + 1e6 * np.asarray(v) ** 2

    with pytest.raises(HarmonicSolveError):
        self_consistent_amplitude(1e-7, 31e3, 31e3, Growing().quality_factor, max_iter=5)
