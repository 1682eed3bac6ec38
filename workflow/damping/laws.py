"""Laws for the quality factor as a function of the vibration velocity, Q(v).

v is the peak surface velocity amplitude at the antinodes [m/s] (docs/damping.md).  Each
law is a frozen dataclass whose parameters may be numpy arrays (e.g. one value per
walker, shape (n, 1)) that broadcast against the velocities.  Every law is
non-increasing in |v|, which the harmonic solve relies on.
"""

from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class QuadraticLoss:
    """1/Q(v) = 1/Q0 + alpha v^2 (Takahashi, Hirose & Uchino 1994).

    Attributes
    ----------
    q0 : float or array
        Low-velocity quality factor [-].
    alpha : float or array
        Velocity-squared loss coefficient [s^2/m^2], >= 0.
    """

    q0: float
    alpha: float
    name: ClassVar[str] = "quadratic"

    def quality_factor(self, velocity):
        """Q at the peak velocity amplitude ``velocity`` [m/s] -> [-]."""
        return 1.0 / self.loss(velocity)

    def loss(self, velocity):
        """Loss factor 1/Q at ``velocity`` [m/s] -> [-]."""
        return 1.0 / np.asarray(self.q0) + np.asarray(self.alpha) * np.square(velocity)


@dataclass(frozen=True)
class LinearLoss:
    """1/Q(v) = 1/Q0 + alpha |v| (loss growing linearly with velocity).

    Attributes
    ----------
    q0 : float or array
        Low-velocity quality factor [-].
    alpha : float or array
        Velocity loss coefficient [s/m], >= 0.
    """

    q0: float
    alpha: float
    name: ClassVar[str] = "linear"

    def quality_factor(self, velocity):
        """Q at the peak velocity amplitude ``velocity`` [m/s] -> [-]."""
        return 1.0 / self.loss(velocity)

    def loss(self, velocity):
        """Loss factor 1/Q at ``velocity`` [m/s] -> [-]."""
        return 1.0 / np.asarray(self.q0) + np.asarray(self.alpha) * np.abs(velocity)


@dataclass(frozen=True)
class ConstantQ:
    """Q(v) = Q0: no amplitude dependence (the design with constant Q).

    Attributes
    ----------
    q0 : float or array
        Quality factor [-].
    """

    q0: float
    name: ClassVar[str] = "constant"

    def quality_factor(self, velocity):
        """Q0, broadcast to the shape of ``velocity`` [-]."""
        return np.asarray(self.q0) + np.zeros_like(np.asarray(velocity, dtype=float))


LAWS = {law.name: law for law in (QuadraticLoss, LinearLoss, ConstantQ)}
"""The Q(v) laws by name."""
SAMPLED_LAWS = tuple(name for name in LAWS if name != "constant")
"""Laws whose posterior can be sampled; the constant Q is the baseline of the comparison (BIC at the MAP)."""


def parameter_names(law_class) -> tuple:
    """Names of a law class's parameters, e.g. ("q0", "alpha")."""
    return tuple(f.name for f in fields(law_class))


def law_parameters(law) -> dict:
    """Parameter name -> value of a law instance."""
    return {f.name: getattr(law, f.name) for f in fields(law)}


def quadratic_law_through(q_low: float, q_work: float, v_work: float) -> QuadraticLoss:
    """The quadratic law with Q(0) = ``q_low`` that passes through Q(``v_work``) = ``q_work``.

    Parameters
    ----------
    q_low : float
        Low-velocity quality factor [-], > q_work.
    q_work : float
        Quality factor at the working point [-].
    v_work : float
        Peak velocity amplitude at the working point [m/s].
    """
    if not q_low > q_work > 0 or not v_work > 0:
        raise ValueError("need q_low > q_work > 0 and v_work > 0")
    return QuadraticLoss(q0=q_low, alpha=(1 / q_work - 1 / q_low) / v_work**2)
