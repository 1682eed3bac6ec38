"""Bernoulli-Euler model of the plate: a half-wavelength simply supported bilayer beam.

Equations in docs/model.md.  All functions are pure and vectorised: the fields of :class:`Plate`
may be numpy arrays that broadcast together.  z is measured from the free face of
the ceramic (ceramic in [0, h_p], resonator in [h_p, h_p + h_i]).
"""

from dataclasses import dataclass

import numpy as np

from workflow.models.plate import Plate

BEAM_CALIBRATION = 20.0 / 54.0
"""Effective-amplification calibration of the beam model [-].

The paper's analytical figures (original plate, Q = 54, 15 V: 1.070 um, 32.13 kHz)
correspond to an effective dynamic amplification of 20 where the formula of
docs/model.md, taken literally with Q = 54, gives 2.89 um.  The ratio 20/54 = 0.370 is the
same for every geometry, so it is applied as one constant factor to the dynamic
deflection of the beam model only.  It is not a change of the plate's quality factor:
the FEM, the damping fit and the instruments use Q unscaled.
"""


def stiffness_ratio(plate: Plate):
    """alpha = E_i / c11p^E [-]."""
    return plate.resonator.youngs_modulus / plate.ceramic.youngs_modulus


def thickness_ratio(plate: Plate):
    """beta = h_i / h_p [-]."""
    return np.asarray(plate.resonator_thickness) / np.asarray(plate.ceramic_thickness)


def neutral_axis(plate: Plate):
    """Height z_0 of the neutral axis above the free face of the ceramic [m].

    z_0 = h_p (1 + alpha beta^2 + 2 alpha beta) / (2 (1 + alpha beta)).
    """
    a, b = stiffness_ratio(plate), thickness_ratio(plate)
    return np.asarray(plate.ceramic_thickness) * (1 + a * b**2 + 2 * a * b) / (2 * (1 + a * b))


def _neutral_fraction(plate: Plate):
    """f_0 = z_0 / h_p [-]."""
    return neutral_axis(plate) / np.asarray(plate.ceramic_thickness)


def _shape_terms(plate: Plate):
    """(1 - 2 f_0) and (1 - 3 f_0 + 3 f_0^2), shared by the deflection formulas."""
    f0 = _neutral_fraction(plate)
    return 1 - 2 * f0, 1 - 3 * f0 + 3 * f0**2


def inverse_a(plate: Plate):
    """1/a of the curvature formula [-].

    1/a = (1 - 2f_0) / (1 - 3f_0 + 3f_0^2 + alpha (3 beta + 3 beta^2 + beta^3 - 6 beta f_0
    - 3 beta^2 f_0 + 3 beta f_0^2)).
    """
    a, b = stiffness_ratio(plate), thickness_ratio(plate)
    f0 = _neutral_fraction(plate)
    numerator, ceramic_term = _shape_terms(plate)
    resonator_term = a * (3 * b + 3 * b**2 + b**3 - 6 * b * f0 - 3 * b**2 * f0 + 3 * b * f0**2)
    return numerator / (ceramic_term + resonator_term)


def curvature(plate: Plate, voltage):
    """Static curvature 1/rho from the field E_z = V / h_p [1/m].

    1/rho = 3 d31 E_z / (2 h_p a).
    """
    h_p = np.asarray(plate.ceramic_thickness)
    field_z = np.asarray(voltage) / h_p
    return 3 * plate.ceramic.d31 * field_z / (2 * h_p) * inverse_a(plate)


def static_deflection(plate: Plate, voltage):
    """Static deflection at lambda/4 of the half-wavelength beam, signed [m].

    w_max = -(3/16) d31 V / h_p^2 (lambda/2)^2 / a.
    """
    h_p = np.asarray(plate.ceramic_thickness)
    half_wave = np.asarray(plate.wavelength) / 2
    return -3 / 16 * plate.ceramic.d31 * np.asarray(voltage) / h_p**2 * half_wave**2 * inverse_a(plate)


def energy_ratio(plate: Plate):
    """U_mono / U_piezo = a (1 - 2 f_0) / (1 - 3 f_0 + 3 f_0^2) [-]."""
    numerator, denominator = _shape_terms(plate)
    return numerator / denominator / inverse_a(plate)


def dynamic_amplification(plate: Plate, q):
    """Q_dyn = Q a (1 - 2 f_0)/(1 - 3 f_0 + 3 f_0^2) = Q U_mono/U_piezo [-] (uncalibrated)."""
    return np.asarray(q) * energy_ratio(plate)


def deflection_per_volt_per_q(plate: Plate, calibration: float = BEAM_CALIBRATION):
    """Antinode deflection amplitude per volt and per unit of quality factor [m/V].

    |(-3/16) d31 / h_p^2 (lambda^2/4) (1 - 2f_0)/(1 - 3f_0 + 3f_0^2)| times the
    calibration; the dynamic deflection is this times Q times V.
    """
    h_p = np.asarray(plate.ceramic_thickness)
    numerator, denominator = _shape_terms(plate)
    wavelength = np.asarray(plate.wavelength)
    geometric = -3 / 16 * plate.ceramic.d31 / h_p**2 * wavelength**2 / 4 * numerator / denominator
    return calibration * np.abs(geometric)


def dynamic_deflection(plate: Plate, voltage, q, calibration: float = BEAM_CALIBRATION):
    """Antinode deflection amplitude at resonance [m].

    w_dyn = c Q (3/16) |d31| V / h_p^2 (lambda^2/4) |(1 - 2f_0)/(1 - 3f_0 + 3f_0^2)|,
    with c = :data:`BEAM_CALIBRATION`.

    Parameters
    ----------
    plate : Plate
    voltage : float or array
        Drive amplitude across each ceramic [V peak].
    q : float or array
        Quality factor of the plate [-].
    calibration : float
        Effective-amplification calibration [-]; 1 gives the literal formula.
    """
    return deflection_per_volt_per_q(plate, calibration) * np.asarray(q) * np.asarray(voltage)


@dataclass(frozen=True)
class BeamResponse:
    """The beam model's working mode as a :class:`~workflow.models.response.PlateResponse` (fields may be arrays: a
    batch of geometries).

    Attributes
    ----------
    frequency : float or numpy.ndarray
        f_r [Hz].
    per_q : float or numpy.ndarray
        Deflection at the voltage per unit of Q [m]: :func:`deflection_per_volt_per_q` times V.
    voltage : float
        [V peak].
    """

    frequency: object
    per_q: object
    voltage: float
    error = None
    """The beam model has no discretisation error to estimate (its model error is in docs/model.md)."""

    def deflection_at_q(self, q):
        """w = Q k V [m]."""
        return self.per_q * np.asarray(q)


def beam_response(plate: Plate, voltage) -> BeamResponse:
    """The beam model's response of ``plate`` driven at ``voltage`` [V peak]."""
    return BeamResponse(resonance_frequency(plate), deflection_per_volt_per_q(plate) * np.asarray(voltage), voltage)


def bending_stiffness(plate: Plate):
    """G_b = c11p^E int_0^h_p (z - z0)^2 dz + E_i int_h_p^(h_p+h_i) (z - z0)^2 dz [N m] per unit width."""
    z0 = neutral_axis(plate)
    h_p = np.asarray(plate.ceramic_thickness)
    top = h_p + np.asarray(plate.resonator_thickness)

    def second_moment(low, high):
        return ((high - z0) ** 3 - (low - z0) ** 3) / 3

    return plate.ceramic.youngs_modulus * second_moment(0.0, h_p) + plate.resonator.youngs_modulus * second_moment(
        h_p, top
    )


def mass_per_area(plate: Plate):
    """M_b = rho_p h_p + rho_i h_i [kg/m^2]."""
    return plate.ceramic.density * np.asarray(plate.ceramic_thickness) + plate.resonator.density * np.asarray(
        plate.resonator_thickness
    )


def resonance_frequency(plate: Plate):
    """Flexural resonance f_r = (2 pi / lambda^2) sqrt(G_b / M_b) [Hz]."""
    wavelength = np.asarray(plate.wavelength)
    return 2 * np.pi / wavelength**2 * np.sqrt(bending_stiffness(plate) / mass_per_area(plate))
