"""Material records as data: the paper's Table 1 unchanged, commercial PZTs consistent with their tables."""

import numpy as np
import pytest

from workflow.errors import InputFileError, TactileError
from workflow.models import materials
from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.elements import BRICKS
from workflow.models.plate import ORIGINAL_PLATE

PUBLISHED_STRAIN_CONSTANTS = {
    # s11^E [pm^2/N], d31, d33, d15 [pm/V], eps^T11/eps0, eps^T33/eps0: Berlincourt's tables (the
    # strain-charge form of the same data set, independent of the stress-charge constants on file)
    "PZT-5H": (16.5, -274, 593, 741, 3130, 3400),
    "PZT-5A": (16.4, -171, 374, 584, 1730, 1700),
    "PZT-4": (12.3, -123, 289, 496, 1475, 1300),
    "PZT-8": (11.5, -97, 225, 330, 1290, 1000),
}


def test_paper_records_are_table_1():
    pzt, cube = materials.PZT, materials.COPPER_BERYLLIUM
    assert (pzt.youngs_modulus, pzt.poisson_ratio, pzt.density) == (67.9e9, 0.33, 7410.0)
    assert (pzt.d31, pzt.e31, pzt.mechanical_q) == (-247e-12, -4.9, 60.0)
    assert (cube.youngs_modulus, cube.density, cube.poisson_ratio) == (123e9, 8250.0, 0.31)
    assert pzt is materials.ceramic("paper") and cube is materials.resonator("paper")
    assert all(record.source for kind in ("ceramic", "resonator", "glue") for record in materials.records()[kind].values())


def test_paper_tensors_give_the_isotropic_in_plane_eigenstrain():
    pzt = materials.PZT
    strain_per_field = np.linalg.solve(pzt.stiffness_matrix(), pzt.piezo_matrix()[2])  # s^E e^T for E_z
    assert strain_per_field == pytest.approx([pzt.d31, pzt.d31, 0, 0, 0, 0], abs=1e-9 * abs(pzt.d31))
    # the permittivity is borrowed from the named soft PZT (the paper gives none)
    assert np.array_equal(pzt.permittivity_matrix(), materials.ceramic("PZT-5H").permittivity_matrix())


@pytest.mark.parametrize("name", sorted(PUBLISHED_STRAIN_CONSTANTS))
def test_commercial_constants_reproduce_their_published_strain_form(name):
    s11, d31, d33, d15, eps11, eps33 = PUBLISHED_STRAIN_CONSTANTS[name]
    ceramic = materials.ceramic(name)
    compliance = np.linalg.inv(ceramic.stiffness_matrix())
    charge = ceramic.piezo_matrix() @ compliance
    free = (ceramic.permittivity_matrix() + charge @ ceramic.piezo_matrix().T) / materials.VACUUM_PERMITTIVITY
    assert compliance[0, 0] * 1e12 == pytest.approx(s11, rel=0.03)
    assert charge[2, [0, 2]] * 1e12 == pytest.approx([d31, d33], rel=0.02)
    assert charge[0, 4] * 1e12 == pytest.approx(d15, rel=0.02)
    assert [free[0, 0], free[2, 2]] == pytest.approx([eps11, eps33], rel=0.04)
    stiffness = ceramic.stiffness_matrix()
    assert stiffness[5, 5] == pytest.approx((stiffness[0, 0] - stiffness[0, 1]) / 2, rel=0.01)  # transverse isotropy
    # the beam model's constants are those of the tensors
    assert ceramic.youngs_modulus == pytest.approx(1 / compliance[0, 0], rel=1e-12)
    assert ceramic.d31 == pytest.approx(charge[2, 0], rel=1e-12)


def test_soft_and_hard_grades_are_ordered_as_expected():
    soft = [materials.ceramic(name) for name in ("PZT-5H", "PZT-5A")]
    hard = [materials.ceramic(name) for name in ("PZT-4", "PZT-8")]
    assert min(abs(c.d31) for c in soft) > max(abs(c.d31) for c in hard)
    assert max(c.mechanical_q for c in soft) < min(c.mechanical_q for c in hard)


def test_general_stiffness_and_eigenstress_equal_the_isotropic_forms():
    brick, sizes = BRICKS["lagrange27"], np.array([[1.0e-3, 2.0e-3, 0.5e-3], [3.0e-3, 1.0e-3, 1.0e-3]])
    pzt = materials.PZT
    e, nu = pzt.youngs_modulus, pzt.poisson_ratio
    lam, mu = e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))
    general = brick.box_stiffness(sizes, pzt.stiffness_matrix())
    # the isotropic form a(u, v) = int lambda div u div v + mu (d_j u_i + d_i u_j) d_j v_i
    gradients = brick.gradient_products
    volume = np.prod(sizes, axis=1)
    for box, size in enumerate(sizes):
        expected = np.zeros_like(general[box])
        for k in range(3):
            for m in range(3):
                coupling = np.zeros((3, 3))
                coupling[k, m] += lam
                coupling[m, k] += mu
                coupling += mu * np.eye(3) * (k == m)
                expected += volume[box] / (size[k] * size[m]) * np.kron(gradients[k, m], coupling)
        assert np.allclose(general[box], expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    field = np.array([2.0e4, -2.0e4])
    load = brick.box_prestress_load(sizes, field[:, None] * pzt.piezo_matrix()[2][None])
    strain = pzt.d31 * field
    stress = np.array([2 * (lam + mu), 2 * (lam + mu), 2 * lam])
    per_axis = (volume[:, None] / sizes)[:, None, :] * brick.gradient_means.T[None]
    expected = (strain[:, None, None] * stress * per_axis).reshape(len(sizes), -1)
    assert np.allclose(load, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_fast_path_matches_scikit_fem_with_full_anisotropic_constants():
    from workflow.models.fem.reference import evaluate_fem_reference

    settings = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=3, n_modes=4)
    plate = ORIGINAL_PLATE.with_(ceramic=materials.ceramic("PZT-8"), resonator=materials.resonator("C17200"))
    fast = evaluate_fem(plate, 54.0, 15.0, settings)
    reference = evaluate_fem_reference(plate, 54.0, 15.0, settings, quadrature_order=5)
    for mine, theirs in zip(fast.modes, reference.modes):
        assert mine.frequency == pytest.approx(theirs.frequency, rel=1e-9)
    assert fast.deflection == pytest.approx(reference.deflection, rel=1e-3)


def test_a_commercial_ceramic_drives_the_plate_like_its_beam_model():
    settings = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=3, n_modes=4)
    paper = evaluate_fem(ORIGINAL_PLATE, 54.0, 15.0, settings)
    hard = evaluate_fem(ORIGINAL_PLATE.with_(ceramic=materials.ceramic("PZT-8")), 54.0, 15.0, settings)
    # stiffer ceramic: higher frequency; smaller d31: smaller deflection (beam model: about |d31| ratio)
    assert hard.frequency > paper.frequency
    assert hard.deflection / paper.deflection == pytest.approx(97 / 247, rel=0.15)


RECORD = """
[ceramic."X"]
source = "a table"
c11 = 12.6e10
c12 = 7.95e10
c13 = 8.41e10
c33 = 11.7e10
c44 = 2.30e10
c66 = 2.325e10
e31 = -6.5
e33 = 23.3
e15 = 17.0
relative_eps_s11 = 1700.0
relative_eps_s33 = 1470.0
density = 7500.0
mechanical_q = 65.0

[resonator.R]
source = "a sheet"
youngs_modulus = 1e11
density = 8000.0
poisson_ratio = 0.3

[glue.G]
source = "a default"
youngs_modulus = 3e9
density = 1150.0
poisson_ratio = 0.35
typical_thickness = 20e-6
"""


def test_a_valid_records_file_parses():
    records = materials.parse_records(RECORD, "mine.toml")
    assert records["ceramic"]["X"].density == 7500.0
    assert records["glue"]["G"].typical_thickness == 20e-6


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("c33 = 11.7e10\n", "", "ceramic 'X': field 'c33' must be a positive number, got None"),
        ("density = 8000.0", "density = -1.0", "resonator 'R': field 'density' must be a positive number, got -1.0"),
        ('source = "a default"', 'source = ""', "glue 'G': field 'source' must be a non-empty string"),
        ("poisson_ratio = 0.35", "poisson_ratio = 0.6", "glue 'G': field 'poisson_ratio' must lie in (-1, 0.5)"),
        ("e15 = 17.0", 'e15 = "17"', "ceramic 'X': field 'e15' must be a number"),
        ("c66 = 2.325e10", "c66 = 2.325e10\nd33 = 5e-10", "ceramic 'X': unknown field 'd33'"),
        ("[glue.G]", "[glues.G]", "unknown section 'glues'"),
        ("c11 = 12.6e10", "c11 = 12.6e10 12", "not valid TOML"),
    ],
)
def test_a_bad_record_is_refused_naming_it_and_its_field(old, new, message):
    with pytest.raises(InputFileError, match="^mine.toml: .*" + message.replace("(", r"\(").replace(")", r"\)")):
        materials.parse_records(RECORD.replace(old, new, 1), "mine.toml")


def test_the_paper_record_must_borrow_a_permittivity_from_a_full_record():
    paper = '\n[ceramic.P]\nsource = "s"\nyoungs_modulus = 6e10\npoisson_ratio = 0.3\ndensity = 7000.0\n'
    paper += 'd31 = -2e-10\ne31 = -5.0\nmechanical_q = 60.0\npermittivity_from = "nothing"\n'
    with pytest.raises(InputFileError, match="ceramic 'P': field 'permittivity_from' must name a ceramic record"):
        materials.parse_records(RECORD + paper, "mine.toml")
    borrowed = materials.parse_records(RECORD + paper.replace("nothing", "X"), "mine.toml")["ceramic"]["P"]
    assert borrowed.d31 == -2e-10


def test_unknown_names_list_the_choices():
    with pytest.raises(TactileError, match="unknown ceramic 'PZT-9'; choose one of paper, PZT-5H"):
        materials.ceramic("PZT-9")
    assert materials.resonator_names() == ("paper", "C17200")
    assert materials.glue_names() == ("epoxy",)
    assert "PZT-4" in materials.ceramic_names()
