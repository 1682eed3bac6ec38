"""The simulated plate: one flexural mode with amplitude-dependent damping and thermal drift.

Deflection amplitude at the antinode (docs/damping.md)

    w = w_s / sqrt((1 - r^2)^2 + (r / Q(v))^2),   r = f / f_r(t),   v = 2 pi f w,

solved self-consistently by :func:`workflow.damping.harmonic.self_consistent_amplitude`;
w_s = g V with g the quasi-static deflection per volt of the beam model and V the peak
voltage across the ceramics.  The velocity leads the drive by 90 deg minus the
displacement lag atan2(r/Q, 1 - r^2).
"""

from dataclasses import dataclass

import numpy as np

from workflow.damping.harmonic import self_consistent_amplitude
from workflow.damping.laws import QuadraticLoss, quadratic_law_through
from workflow.models import analytical
from workflow.models.materials import DESIGN_VOLTAGE, PLATE_Q
from workflow.models.plate import ORIGINAL_PLATE, Plate

DEFAULT_LOW_VELOCITY_Q = 150.0
"""Q(v -> 0) of the default simulated plate [-]: glued plates damp well below the ceramic's Q."""


@dataclass(frozen=True)
class PlateResponse:
    """The physics of the simulated plate.

    Attributes
    ----------
    resonance_frequency : float
        f_r at time 0 [Hz].
    deflection_per_volt : float
        Quasi-static antinode deflection per volt across the ceramics, w_s / V [m/V].
    law : object
        Q(v) law with ``quality_factor(velocity)`` (:mod:`workflow.damping.laws`).
    drift_rate : float
        Thermal drift of the resonance, d f_r / d t [Hz/s].
    """

    resonance_frequency: float
    deflection_per_volt: float
    law: object
    drift_rate: float = 0.0

    def resonance_at(self, time):
        """f_r(t) = f_r + drift_rate t [Hz] at ``time`` [s]."""
        return self.resonance_frequency + self.drift_rate * np.asarray(time)

    def deflection(self, frequency, ceramic_voltage, time=0.0):
        """Antinode deflection amplitude w [m] at drive ``frequency`` [Hz], ``ceramic_voltage`` [V peak]."""
        static = self.deflection_per_volt * np.abs(np.asarray(ceramic_voltage, dtype=float))
        return self_consistent_amplitude(static, frequency, self.resonance_at(time), self.law.quality_factor)

    def velocity(self, frequency, ceramic_voltage, time=0.0):
        """Antinode velocity amplitude [m/s] and its phase relative to the drive [deg].

        Parameters
        ----------
        frequency : array
            Drive frequency [Hz].
        ceramic_voltage : array
            Peak voltage across the ceramics [V].
        time : array
            Time since the bench started [s] (drift).
        """
        frequency = np.asarray(frequency, dtype=float)
        w = self.deflection(frequency, ceramic_voltage, time)
        v = 2 * np.pi * frequency * w
        r = frequency / self.resonance_at(time)
        lag = np.degrees(np.arctan2(r / self.law.quality_factor(v), 1 - r**2))
        return v, 90.0 - lag


def working_point_velocity(plate: Plate = ORIGINAL_PLATE, q: float = PLATE_Q, voltage: float = DESIGN_VOLTAGE) -> float:
    """Peak velocity at resonance v = 2 pi f_r Q g V [m/s] of ``plate`` with quality factor ``q`` at ``voltage`` [V]."""
    return float(
        2 * np.pi * analytical.resonance_frequency(plate) * q * analytical.deflection_per_volt_per_q(plate) * voltage
    )


def default_law(
    plate: Plate = ORIGINAL_PLATE,
    low_velocity_q: float = DEFAULT_LOW_VELOCITY_Q,
    working_q: float = PLATE_Q,
    working_voltage: float = DESIGN_VOLTAGE,
) -> QuadraticLoss:
    """The quadratic law 1/Q = 1/Q0 + alpha v^2 with Q0 = ``low_velocity_q`` and Q = ``working_q`` at the working point.

    The working point is self-consistent by construction: at resonance w = Q g V, so the
    velocity there is :func:`working_point_velocity` with Q = ``working_q``.
    """
    return quadratic_law_through(low_velocity_q, working_q, working_point_velocity(plate, working_q, working_voltage))


def plate_response(plate: Plate = ORIGINAL_PLATE, law=None, drift_rate: float = 0.0) -> PlateResponse:
    """The simulated response of ``plate``: f_r and w_s / V from the beam model (:mod:`workflow.models.analytical`).

    The quasi-static gain is the calibrated beam model's deflection per volt per unit Q,
    so that Q = 54 at 15 V reproduces the beam model's deflection.
    """
    return PlateResponse(
        resonance_frequency=float(analytical.resonance_frequency(plate)),
        deflection_per_volt=float(analytical.deflection_per_volt_per_q(plate)),
        law=default_law(plate) if law is None else law,
        drift_rate=drift_rate,
    )
