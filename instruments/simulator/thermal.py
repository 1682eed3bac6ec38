"""The simulated plate warms with the power it dissipates and cools towards the ambient; its resonance follows.

One lumped heat capacity C and one conductance G to the ambient (docs/instruments.md#thermal-model):

    C dT/dt = P(t) - G (T - T_amb),        tau_th = C / G,
    P = omega E / Q(v) = pi f m_eff v^2 / Q(v),   E = m_eff v^2 / 2,
    f_r(T) = f_r(T_amb) (1 + beta (T - T_amb)),

with v the peak velocity at the antinodes, m_eff the modal mass of the cosine mode (the plate's and
the ceramics' mass weighted by the mode shape squared) and beta the relative frequency coefficient.
Between two changes of the drive P is constant and the rise is integrated exactly.

Literature values (the defaults):

* specific heat 420 J/(kg K) for CuBe (material-properties.org, "Beryllium Copper") and 350 J/(kg K)
  for PZT (PZT-5H measured up to 150 K: Yarlagadda et al., J. Intell. Mater. Syst. Struct. 1995; room
  temperature is somewhat higher, so this errs towards more heating);
* natural convection in still air, h = 10 W/(m^2 K) (textbook range 2 to 25) on both faces;
* beta = -1.75e-4 /K: CuBe's Young's modulus falls about 3.5e-4 per kelvin and f_r ~ sqrt(E) follows
  at half the rate (thermal expansion adds +0.5 x 17e-6 /K: negligible).

For the original plate this gives C = 40 J/K, G = 0.088 W/K, tau_th = 7.6 min and, at the working
point (0.216 m/s, Q = 54), P = 4.3 W: the plate would settle 49 K above the ambient.
"""

from dataclasses import dataclass, replace

import numpy as np

from workflow.models.plate import Plate

AMBIENT_TEMPERATURE = 22.0
"""Plate temperature when the bench starts [deg C]."""
RESONATOR_SPECIFIC_HEAT = 420.0
"""Specific heat of CuBe [J/(kg K)]."""
CERAMIC_SPECIFIC_HEAT = 350.0
"""Specific heat of PZT [J/(kg K)]."""
CONVECTION_COEFFICIENT = 10.0
"""Natural convection in still air on each face [W/(m^2 K)]."""
FREQUENCY_COEFFICIENT = -1.75e-4
"""Relative change of f_r per kelvin, (df_r / dT) / f_r [1/K]: half CuBe's modulus coefficient."""


def _cos2_integral(length, wavelength):
    """Integral of cos^2(2 pi x / lambda) over a segment of ``length`` [m] centred on an antinode [m]."""
    return length / 2 + wavelength / (4 * np.pi) * np.sin(2 * np.pi * length / wavelength)


@dataclass(frozen=True)
class ThermalModel:
    """The plate's lumped thermal parameters.

    Attributes
    ----------
    heat_capacity : float
        C [J/K].
    conductance : float
        G to the ambient [W/K].
    modal_mass : float
        m_eff of the working mode, normalised at the antinode [kg].
    frequency_coefficient : float
        beta = (df_r / dT) / f_r [1/K].
    """

    heat_capacity: float
    conductance: float
    modal_mass: float
    frequency_coefficient: float = FREQUENCY_COEFFICIENT

    @property
    def time_constant(self) -> float:
        """tau_th = C / G [s]."""
        return self.heat_capacity / self.conductance

    def dissipated_power(self, frequency, velocity, q):
        """P = pi f m_eff v^2 / Q [W] at drive ``frequency`` [Hz], antinode ``velocity`` [m/s], quality factor ``q``."""
        return np.pi * frequency * self.modal_mass * np.asarray(velocity) ** 2 / q

    def scaled(self, frequency_factor: float) -> "ThermalModel":
        """The same plate with ``frequency_factor`` times its frequency coefficient (a stress case of the hold)."""
        return replace(self, frequency_coefficient=self.frequency_coefficient * frequency_factor)

    def metadata(self) -> dict:
        return {"thermal_heat_capacity_j_k": self.heat_capacity, "thermal_conductance_w_k": self.conductance,
                "thermal_time_constant_s": self.time_constant, "thermal_modal_mass_kg": self.modal_mass,
                "thermal_frequency_coefficient_per_k": self.frequency_coefficient}


def thermal_model(plate: Plate) -> ThermalModel:
    """The literature-value :class:`ThermalModel` of ``plate`` (module docstring)."""
    length, width, wavelength = float(plate.length), float(plate.width), float(plate.wavelength)
    ceramic_length = float(plate.ceramic_length)
    resonator_area_density = plate.resonator.density * float(plate.resonator_thickness)
    ceramic_area_density = plate.ceramic.density * float(plate.ceramic_thickness)
    resonator_mass = resonator_area_density * length * width
    ceramic_mass = ceramic_area_density * plate.n_ceramics * ceramic_length * width
    modal_mass = width * (resonator_area_density * _cos2_integral(length, wavelength)
                          + ceramic_area_density * plate.n_ceramics * _cos2_integral(ceramic_length, wavelength))
    return ThermalModel(
        heat_capacity=resonator_mass * RESONATOR_SPECIFIC_HEAT + ceramic_mass * CERAMIC_SPECIFIC_HEAT,
        conductance=CONVECTION_COEFFICIENT * 2 * length * width,
        modal_mass=float(modal_mass),
    )


class ThermalState:
    """The plate's temperature rise over the ambient, integrated exactly for a power held between updates."""

    def __init__(self, model: ThermalModel | None):
        self.model = model
        self.rise = 0.0
        """T - T_amb at :attr:`time` [K]."""
        self.time = 0.0
        self.power = 0.0
        """Power dissipated since :attr:`time` [W]."""

    def advance(self, time: float) -> float:
        """Integrate to ``time`` [s] with the power held; the rise then [K]."""
        if self.model is not None and time > self.time:
            steady = self.power / self.model.conductance
            self.rise = steady + (self.rise - steady) * np.exp(-(time - self.time) / self.model.time_constant)
        self.time = max(self.time, time)
        return self.rise

    def set_power(self, time: float, power: float) -> None:
        """From ``time`` [s] on, the plate dissipates ``power`` [W]."""
        self.advance(time)
        self.power = float(power)
