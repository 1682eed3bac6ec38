"""Plate geometry: derived quantities and refusal of bad input."""

import numpy as np
import pytest

from workflow.errors import GeometryError
from workflow.models import materials
from workflow.models.plate import ORIGINAL_PLATE, check_design_space


def test_derived_geometry_of_the_original_plate():
    plate = ORIGINAL_PLATE
    assert plate.length == pytest.approx(15 * 24e-3 / 4)
    assert plate.ceramic_length == pytest.approx(12e-3 - 1e-3)
    centres = plate.ceramic_centres.ravel()
    np.testing.assert_allclose(centres, np.arange(-6, 7, 2) * 24e-3 / 4)
    # Neighbouring ceramics are separated by the gap delta.
    gaps = np.diff(centres) - plate.ceramic_length
    np.testing.assert_allclose(gaps, materials.CERAMIC_GAP)
    # The resonator extends beyond the outermost ceramic (lambda/8 plus half a gap).
    overhang = plate.length / 2 - (centres[-1] + plate.ceramic_length / 2)
    assert overhang == pytest.approx(24e-3 / 8 + materials.CERAMIC_GAP / 2)


def test_neighbouring_ceramics_are_driven_in_antiphase():
    signs = ORIGINAL_PLATE.polarities
    assert len(signs) == materials.N_CERAMICS
    assert np.all(signs[1:] == -signs[:-1])
    assert signs[len(signs) // 2] == 1


@pytest.mark.parametrize(
    "changes",
    [
        {"wavelength": -24e-3},
        {"resonator_thickness": 0.0},
        {"ceramic_thickness": float("nan")},
        {"width": float("inf")},
        {"wavelength": 1.5e-3},  # lambda/2 smaller than the gap
        {"n_ceramics": 4},
    ],
)
def test_non_physical_plates_are_refused(changes):
    with pytest.raises(GeometryError):
        ORIGINAL_PLATE.with_(**changes)


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"wavelength": 50e-3}, "wavelength"),
        ({"resonator_thickness": 0.1e-3}, "resonator thickness"),
        ({"width": 20e-3}, "width"),
        ({"ceramic_thickness": 0.7e-3}, "commercial"),
    ],
)
def test_out_of_range_plates_are_refused_with_the_quantity_named(changes, words):
    with pytest.raises(GeometryError, match=words):
        check_design_space(ORIGINAL_PLATE.with_(**changes))


def test_practical_minimum_thickness_is_an_option():
    thin = ORIGINAL_PLATE.with_(resonator_thickness=0.3e-3)
    assert check_design_space(thin) is thin
    with pytest.raises(GeometryError, match="0.5"):
        check_design_space(thin, min_resonator_thickness=materials.PRACTICAL_MIN_RESONATOR_THICKNESS)
