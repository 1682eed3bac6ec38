"""The simulated plate: one flexural mode with amplitude-dependent damping and thermal drift.

Deflection amplitude at the antinode (docs/damping.md)

    w = w_s / sqrt((1 - r^2)^2 + (r / Q(v))^2),   r = f / f_r(t),   v = 2 pi f w,

solved self-consistently by :func:`workflow.damping.harmonic.softened_amplitudes`, starting
from the deflection the plate had at the previous readout (so that, with a softening
resonance, f_r(v) = f_r(t) (1 - kappa v^2), up and down sweeps follow different branches);
w_s = g V with g the quasi-static deflection per volt of the beam model and V the peak
voltage across the ceramics.  The velocity leads the drive by 90 deg minus the
displacement lag atan2(r/Q, 1 - r^2).

After a burst of N cycles at f the plate rings down from v0 = v_ss (1 - exp(-pi N / Q(v_ss)))
(v_ss the steady velocity at f; the build-up of a linear mode with the steady state's Q),
following dv/dt = -pi f_r v / Q(v) (:func:`workflow.damping.ringdown.decay_velocity`).
The plate warms with the power it dissipates (:mod:`.thermal`): with a rise theta over the ambient,
f_r(t, theta) = (f_r + drift_rate t) (1 + beta theta); the linear drift reads as a slow warming of
the ambient, T = T_amb + theta + drift_rate t / (beta f_r).

Under an amplitude-modulated drive the envelope follows the driven envelope equation of
:mod:`workflow.damping.envelope` with this plate's own law, softening and resonance
(:meth:`PlateResponse.envelope_model`).
"""

from dataclasses import dataclass

import numpy as np

from instruments.simulator.thermal import AMBIENT_TEMPERATURE, FREQUENCY_COEFFICIENT, ThermalModel, thermal_model
from workflow.damping.envelope import EnvelopeModel
from workflow.damping.harmonic import self_consistent_amplitude, softened_amplitudes
from workflow.damping.ringdown import decay_velocity
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
    softening : float
        kappa in f_r(v) = f_r(t) (1 - kappa v^2), v the antinode velocity [s^2/m^2] (0: none).
    thermal : ThermalModel or None
        The plate's heating by the power it dissipates (:mod:`.thermal`); None: it does not warm.

    The methods take ``heating``, the plate's temperature rise over the ambient [K] (the bench's state).
    """

    resonance_frequency: float
    deflection_per_volt: float
    law: object
    drift_rate: float = 0.0
    softening: float = 0.0
    thermal: ThermalModel | None = None

    @property
    def frequency_coefficient(self) -> float:
        """beta = (df_r / dT) / f_r [1/K] (the thermal model's, else the literature value)."""
        return FREQUENCY_COEFFICIENT if self.thermal is None else self.thermal.frequency_coefficient

    def resonance_at(self, time, heating=0.0):
        """f_r(t, theta) = (f_r + drift_rate t) (1 + beta theta) [Hz] at ``time`` [s], ``heating`` theta [K] (small amplitude)."""
        return (self.resonance_frequency + self.drift_rate * np.asarray(time)) * (1 + self.frequency_coefficient * heating)

    def temperature_at(self, time, heating=0.0):
        """Plate temperature [deg C] at ``time`` [s]: the ambient, the drift read through beta, plus ``heating`` [K]."""
        drift = self.drift_rate * np.asarray(time) / (self.frequency_coefficient * self.resonance_frequency)
        return AMBIENT_TEMPERATURE + drift + heating

    def dissipated_power(self, frequency, velocity) -> float:
        """Power the plate dissipates [W] at antinode ``velocity`` [m/s] and drive ``frequency`` [Hz] (0 without a thermal model)."""
        if self.thermal is None:
            return 0.0
        return float(self.thermal.dissipated_power(frequency, velocity, self.law.quality_factor(velocity)))

    def deflection(self, frequency, ceramic_voltage, time=0.0, previous=None, heating=0.0):
        """Antinode deflection amplitude w [m] at drive ``frequency`` [Hz], ``ceramic_voltage`` [V peak].

        Without softening the root is unique and arrays are solved elementwise.  With it the points
        (the last axis of the broadcast arguments) are a sweep in measuring order, the first continued
        from ``previous``, the deflection before it [m] (default: the small-amplitude response).
        """
        static = self.deflection_per_volt * np.abs(np.asarray(ceramic_voltage, dtype=float))
        resonance = self.resonance_at(time, heating)
        if not self.softening:
            return self_consistent_amplitude(static, frequency, resonance, self.law.quality_factor)
        if not np.any(static):
            return np.zeros(np.broadcast(static, frequency, resonance).shape)
        shape = np.broadcast(static, frequency, resonance).shape
        points = (np.atleast_1d(x) for x in (static, frequency, resonance))
        return softened_amplitudes(*points, self.softening, self.law.quality_factor, start=previous).reshape(shape)

    def velocity(self, frequency, ceramic_voltage, time=0.0, previous=None, heating=0.0):
        """Antinode velocity amplitude [m/s] and its phase relative to the drive [deg].

        Parameters
        ----------
        frequency : float
            Drive frequency [Hz].
        ceramic_voltage : float
            Peak voltage across the ceramics [V].
        time : float
            Time since the bench started [s] (drift).
        previous : float, optional
            Deflection before this point [m] (see :meth:`deflection`).
        heating : float
            Temperature rise over the ambient [K].
        """
        frequency = np.asarray(frequency, dtype=float)
        w = self.deflection(frequency, ceramic_voltage, time, previous, heating)
        v = 2 * np.pi * frequency * w
        r = frequency / (self.resonance_at(time, heating) * (1 - self.softening * v**2))
        lag = np.degrees(np.arctan2(r / self.law.quality_factor(v), 1 - r**2))
        return v, 90.0 - lag

    def burst_build_up(self, frequency, ceramic_voltage, elapsed, time, heating=0.0):
        """Antinode velocity ``elapsed`` [s] into a burst from rest [m/s]: v_ss (1 - exp(-pi f t / Q(v_ss)))."""
        steady, _ = self.velocity(frequency, ceramic_voltage, time, heating=heating)
        return steady * (1 - np.exp(-np.pi * frequency * np.asarray(elapsed) / self.law.quality_factor(steady)))

    def envelope_model(self, frequency: float, time: float, heating=0.0) -> EnvelopeModel:
        """The plate's envelope dynamics under a carrier at ``frequency`` [Hz], with the resonance at ``time`` [s]."""
        return EnvelopeModel(float(self.resonance_at(time, heating)), self.deflection_per_volt, self.law, self.softening,
                             frequency)

    def ringdown(self, initial_velocity, decay_time, time, heating=0.0):
        """Antinode velocity envelope ``decay_time`` [s] after a burst that ended at ``time`` [s] with ``initial_velocity`` [m/s]."""
        return decay_velocity(self.law, self.resonance_at(time, heating), initial_velocity, decay_time)


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


def plate_response(plate: Plate = ORIGINAL_PLATE, law=None, drift_rate: float = 0.0, softening: float = 0.0,
                   heating: bool = True) -> PlateResponse:
    """The simulated response of ``plate``: f_r and w_s / V from the beam model (:mod:`workflow.models.analytical`).

    The quasi-static gain is the calibrated beam model's deflection per volt per unit Q,
    so that Q = 54 at 15 V reproduces the beam model's deflection.  With ``heating`` the plate warms with
    the power it dissipates (:func:`.thermal.thermal_model`).
    """
    return PlateResponse(
        resonance_frequency=float(analytical.resonance_frequency(plate)),
        deflection_per_volt=float(analytical.deflection_per_volt_per_q(plate)),
        law=default_law(plate) if law is None else law,
        drift_rate=drift_rate,
        softening=softening,
        thermal=thermal_model(plate) if heating else None,
    )
