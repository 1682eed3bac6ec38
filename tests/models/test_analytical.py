"""The beam model (docs/model.md) against independent computations and the paper."""

import numpy as np
import pytest
from scipy.integrate import quad

from workflow.models import analytical
from workflow.models.plate import ORIGINAL_PLATE, Plate
from workflow.pipeline.paper import FIGURES

GEOMETRIES = [
    Plate(24e-3, 2.0e-3, 1.0e-3),
    Plate(18e-3, 0.5e-3, 1.0e-3),
    Plate(30e-3, 1.2e-3, 0.5e-3),
    Plate(35e-3, 3.0e-3, 2.0e-3),
]


def _modulus(plate, z):
    return plate.ceramic.youngs_modulus if z < plate.ceramic_thickness else plate.resonator.youngs_modulus


@pytest.mark.parametrize("plate", GEOMETRIES)
def test_neutral_axis_balances_the_axial_force(plate):
    z0 = analytical.neutral_axis(plate)
    top = plate.ceramic_thickness + plate.resonator_thickness
    force, _ = quad(lambda z: _modulus(plate, z) * (z - z0), 0, top, points=[plate.ceramic_thickness])
    scale = plate.resonator.youngs_modulus * top**2
    assert abs(force) < 1e-10 * scale


@pytest.mark.parametrize("plate", GEOMETRIES)
def test_bending_stiffness_matches_quadrature(plate):
    z0 = analytical.neutral_axis(plate)
    top = plate.ceramic_thickness + plate.resonator_thickness
    expected, _ = quad(lambda z: _modulus(plate, z) * (z - z0) ** 2, 0, top, points=[plate.ceramic_thickness])
    assert analytical.bending_stiffness(plate) == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("plate", GEOMETRIES)
def test_curvature_matches_laminate_theory(plate):
    """Free bilayer with the eigenstrain d31 E_z in the ceramic: zero force and moment."""
    voltage = 15.0
    e_p, e_i = plate.ceramic.youngs_modulus, plate.resonator.youngs_modulus
    h_p, h_i = plate.ceramic_thickness, plate.resonator_thickness
    eigenstrain = plate.ceramic.d31 * voltage / h_p
    a = e_p * h_p + e_i * h_i
    b = e_p * h_p**2 / 2 + e_i * ((h_p + h_i) ** 2 - h_p**2) / 2
    d = e_p * h_p**3 / 3 + e_i * ((h_p + h_i) ** 3 - h_p**3) / 3
    _, curvature = np.linalg.solve([[a, b], [b, d]], [e_p * eigenstrain * h_p, e_p * eigenstrain * h_p**2 / 2])
    assert analytical.curvature(plate, voltage) == pytest.approx(curvature, rel=1e-9)


@pytest.mark.parametrize("plate", GEOMETRIES)
def test_static_deflection_is_the_simply_supported_beam_under_uniform_curvature(plate):
    span = plate.wavelength / 2
    expected = analytical.curvature(plate, 10.0) * span**2 / 8
    assert abs(analytical.static_deflection(plate, 10.0)) == pytest.approx(abs(expected), rel=1e-12)


@pytest.mark.parametrize("plate", GEOMETRIES)
def test_dynamic_deflection_is_static_times_dynamic_amplification(plate):
    literal = analytical.dynamic_deflection(plate, 15.0, 54.0, calibration=1.0)
    expected = abs(analytical.static_deflection(plate, 15.0)) * abs(analytical.dynamic_amplification(plate, 54.0))
    assert literal == pytest.approx(expected, rel=1e-12)


def test_mass_per_area():
    plate = ORIGINAL_PLATE
    expected = 7410.0 * 1.0e-3 + 8250.0 * 2.0e-3
    assert analytical.mass_per_area(plate) == pytest.approx(expected)


def test_deflection_does_not_depend_on_width():
    widths = np.linspace(30e-3, 100e-3, 8)
    plates = ORIGINAL_PLATE.with_(width=widths)
    w = analytical.dynamic_deflection(plates, 15.0, 54.0)
    assert np.ptp(w) == 0.0
    assert np.ptp(np.broadcast_to(analytical.resonance_frequency(plates), widths.shape)) == 0.0


def test_frequency_scales_as_inverse_wavelength_squared():
    wavelengths = np.array([15e-3, 20e-3, 30e-3, 40e-3])
    f = analytical.resonance_frequency(ORIGINAL_PLATE.with_(wavelength=wavelengths))
    np.testing.assert_allclose(f * wavelengths**2, f[0] * wavelengths[0] ** 2, rtol=1e-12)


def test_deflection_scales_as_wavelength_squared_and_linearly_in_voltage_and_q():
    base = analytical.dynamic_deflection(ORIGINAL_PLATE, 15.0, 54.0)
    assert analytical.dynamic_deflection(ORIGINAL_PLATE.with_(wavelength=48e-3), 15.0, 54.0) == pytest.approx(4 * base)
    assert analytical.dynamic_deflection(ORIGINAL_PLATE, 30.0, 54.0) == pytest.approx(2 * base)
    assert analytical.dynamic_deflection(ORIGINAL_PLATE, 15.0, 27.0) == pytest.approx(base / 2)


def test_vectorised_evaluation_matches_scalar_evaluation():
    rng = np.random.default_rng(1)
    wavelength = rng.uniform(15e-3, 40e-3, 50)
    thickness = rng.uniform(0.5e-3, 3e-3, 50)
    batch = analytical.dynamic_deflection(Plate(wavelength, thickness, 1e-3), 15.0, 54.0)
    single = [analytical.dynamic_deflection(Plate(l, h, 1e-3), 15.0, 54.0) for l, h in zip(wavelength, thickness)]
    np.testing.assert_allclose(batch, single, rtol=1e-14)


def test_original_plate_reproduces_the_paper():
    """(paper) analytical model, Q = 54, 15 V: 1.070 um and 32.13 kHz (within 0.5 %)."""
    w_um = analytical.dynamic_deflection(ORIGINAL_PLATE, 15.0, 54.0) * 1e6
    assert w_um == pytest.approx(FIGURES["analytical_w"].value, rel=5e-3)
    f_khz = analytical.resonance_frequency(ORIGINAL_PLATE) / 1e3
    assert f_khz == pytest.approx(FIGURES["analytical_f"].value, rel=5e-3)


def test_literal_formula_gives_the_uncalibrated_value():
    """docs/model.md: taken literally with Q = 54 the formula gives 2.89 um."""
    literal = analytical.dynamic_deflection(ORIGINAL_PLATE, 15.0, 54.0, calibration=1.0)
    assert literal * 1e6 == pytest.approx(FIGURES["literal_w"].value, rel=5e-3)
    assert analytical.BEAM_CALIBRATION == pytest.approx(0.370, abs=1e-3)
