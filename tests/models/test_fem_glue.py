"""The glue layer of the FEM: only under the ceramics, continuous at zero thickness, softening the plate."""

from dataclasses import replace

import numpy as np
import pytest

from workflow.errors import GeometryError
from workflow.models import materials
from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.mesh import CERAMIC, GLUE, quarter_plate_mesh, top_face
from workflow.models.plate import ORIGINAL_PLATE

COARSE = FemSettings(elements_per_ceramic=4, elements_per_layer=2, elements_across_half_width=3)


def test_glue_lies_only_under_the_ceramics_and_the_probes_stay_on_top():
    plate = ORIGINAL_PLATE.with_(glue_thickness=30e-6)
    mesh = quarter_plate_mesh(plate, COARSE)
    glue, ceramic = mesh.cells[mesh.material == GLUE], mesh.cells[mesh.material == CERAMIC]
    # one glue cell above every ceramic cell's column, none elsewhere
    assert {(i, j) for i, j, _ in glue} == {(i, j) for i, j, _ in ceramic}
    z = mesh.edges[2]
    assert z[COARSE.elements_per_layer + 1] - z[COARSE.elements_per_layer] == pytest.approx(30e-6)
    assert z[-1] == pytest.approx(top_face(plate)) == pytest.approx(float(plate.total_thickness) + 30e-6)


def test_a_thin_bond_tends_to_the_bonded_plate_and_a_thicker_one_lowers_the_frequency():
    bare = evaluate_fem(ORIGINAL_PLATE, 54.0, 15.0, COARSE)
    glued = {t: evaluate_fem(ORIGINAL_PLATE.with_(glue_thickness=t), 54.0, 15.0, COARSE) for t in (1e-7, 20e-6, 50e-6)}
    assert glued[1e-7].frequency == pytest.approx(bare.frequency, rel=2e-4)
    assert bare.frequency > glued[20e-6].frequency > glued[50e-6].frequency
    assert 0.005 < 1 - glued[20e-6].frequency / bare.frequency < 0.04  # a 3 GPa epoxy layer of 20 um: ~1.5 %


def test_a_stiff_bond_as_stiff_as_the_resonator_adds_its_thickness():
    """A 'glue' of the resonator's own material behaves like a thicker resonator under the ceramics: stiffer."""
    metal = ORIGINAL_PLATE.resonator
    like_metal = replace(
        materials.EPOXY, youngs_modulus=metal.youngs_modulus, density=metal.density, poisson_ratio=metal.poisson_ratio
    )
    stiff = ORIGINAL_PLATE.with_(glue_thickness=50e-6, glue=like_metal)
    soft = ORIGINAL_PLATE.with_(glue_thickness=50e-6)
    assert evaluate_fem(stiff, 54.0, 15.0, COARSE).frequency > evaluate_fem(soft, 54.0, 15.0, COARSE).frequency


@pytest.mark.parametrize("thickness", [-1e-6, np.nan, np.inf])
def test_a_bad_glue_thickness_is_refused(thickness):
    with pytest.raises(GeometryError, match="glue_thickness"):
        ORIGINAL_PLATE.with_(glue_thickness=thickness)
