"""Table 1 of the paper: materials, design bounds and fixed design choices.

This module is the single source of truth for these numbers.  SI units.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """An isotropic elastic layer.

    Attributes
    ----------
    name : str
    youngs_modulus : float
        Young's modulus [Pa] (for the ceramic: c11p^E, short circuit).
    density : float
        Mass density [kg/m^3].
    poisson_ratio : float
        Poisson's ratio [-].
    """

    name: str
    youngs_modulus: float
    density: float
    poisson_ratio: float


@dataclass(frozen=True)
class PiezoMaterial(Material):
    """A poled piezo-ceramic driven through the transverse (31) effect.

    Attributes
    ----------
    d31 : float
        Piezoelectric charge constant [m/V].
    e31 : float
        Piezoelectric stress constant [C/m^2].
    mechanical_q : float
        Mechanical quality factor of the material [-].
    """

    d31: float = 0.0
    e31: float = 0.0
    mechanical_q: float = 0.0


COPPER_BERYLLIUM = Material("CuBe", youngs_modulus=123e9, density=8250.0, poisson_ratio=0.31)
"""The resonator (Table 1)."""

PZT = PiezoMaterial(
    "PZT",
    youngs_modulus=67.9e9,
    density=7410.0,
    poisson_ratio=0.33,
    d31=-247e-12,
    e31=-4.9,
    mechanical_q=60.0,
)
"""The piezo-ceramic strips (Table 1)."""

EPOXY = Material("epoxy", youngs_modulus=3.0e9, density=1150.0, poisson_ratio=0.35)
"""A structural epoxy bond (typical values of cured bisphenol-A epoxies, 2-4 GPa; docs/model.md)."""

N_CERAMICS = 7
"""Ceramics along x [-]."""
CERAMIC_GAP = 1.0e-3
"""Gap between neighbouring ceramics, delta [m]."""

WAVELENGTH_RANGE = (15e-3, 40e-3)
"""Bounds on the flexural wavelength lambda [m]."""
RESONATOR_THICKNESS_RANGE = (0.2e-3, 3e-3)
"""Bounds on the resonator thickness h_i [m]."""
PRACTICAL_MIN_RESONATOR_THICKNESS = 0.5e-3
"""Practical lower limit on h_i [m] (the optimiser's default lower bound)."""
WIDTH_RANGE = (30e-3, 100e-3)
"""Bounds on the width b [m] (resonator = ceramics)."""
CERAMIC_THICKNESSES = (0.5e-3, 1.0e-3, 2.0e-3)
"""Commercial ceramic thicknesses h_p [m] (discrete)."""

PLATE_Q = 54.0
"""Quality factor measured on the original plate [-], used for design with constant Q."""
MIN_FREQUENCY = 25e3
"""Lowest acceptable working frequency [Hz] (above hearing, squeeze film works)."""
DESIGN_VOLTAGE = 15.0
"""Safe design drive amplitude across the ceramics [V peak]."""
TARGET_DEFLECTION = 1.15e-6
"""Nominal antinode deflection amplitude [m]."""
MIN_USEFUL_DEFLECTION = 0.3e-6
"""Deflection amplitude below which friction reduction is not useful [m]."""
