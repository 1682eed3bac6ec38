"""The coupled piezoelectric FEM: limits, the k31 bar of IEEE Std 176, antiresonances and admittance."""

import dataclasses

import numpy as np
import pytest

from workflow.models import analytical, materials
from workflow.models.fem import FemResult, FemSettings, evaluate_fem
from workflow.models.fem.assembly import assemble_matrices, assemble_system, scatter_matrices
from workflow.models.fem.elements import LAGRANGE_27
from workflow.models.fem.mesh import CERAMIC, brick_mesh, quarter_plate_mesh
from workflow.models.fem.piezoelectric import (
    assemble_piezo_system,
    coupled_modes,
    evaluate_fem_coupled,
    open_circuit_modes,
)
from workflow.models.plate import ORIGINAL_PLATE

COARSE = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=3)
"""A mesh for fast tests (not for accuracy)."""


@pytest.fixture(scope="module")
def coupled():
    return evaluate_fem_coupled(ORIGINAL_PLATE, 54.0, 15.0, COARSE)


@pytest.fixture(scope="module")
def eigenstrain():
    return evaluate_fem(ORIGINAL_PLATE, 54.0, 15.0, COARSE)


def _frequencies(result):
    return np.array([mode.frequency for mode in result.modes])


def test_without_coupling_the_coupled_model_is_the_eigenstrain_model(eigenstrain):
    # a huge permittivity makes the field uniform (V/h_p) and the e^2/eps stiffening vanish
    pzt = materials.PZT
    huge = dataclasses.replace(pzt, clamped_permittivity=tuple(tuple(1e6 * x for x in row) for row in pzt.clamped_permittivity))
    decoupled = evaluate_fem_coupled(ORIGINAL_PLATE.with_(ceramic=huge), 54.0, 15.0, COARSE)
    assert _frequencies(decoupled) == pytest.approx(_frequencies(eigenstrain), rel=1e-5)
    deflections = [mode.deflection for mode in decoupled.modes]
    assert deflections == pytest.approx([mode.deflection for mode in eigenstrain.modes], rel=1e-5)
    assert decoupled.coupling_factor < 1e-2


@pytest.mark.parametrize("name", ["paper", "PZT-4"])
def test_the_voltage_drive_is_the_eigenstress_of_the_uniform_field(name):
    # with u held, the potential between the electrodes is linear in z: Gamma V = int e^T E : grad v,
    # sign included (the coupled model drives the plate the same way as the eigenstrain model)
    plate = ORIGINAL_PLATE.with_(ceramic=materials.ceramic(name))
    mesh = quarter_plate_mesh(plate, COARSE)
    stiffness, mass = assemble_matrices(mesh, plate)
    coupled_load = assemble_piezo_system(mesh, stiffness, mass, plate.ceramic, 15.0).mechanical.load
    eigenstrain_load = assemble_system(mesh, plate, 15.0).load
    assert np.allclose(coupled_load, eigenstrain_load, rtol=0, atol=1e-12 * np.abs(eigenstrain_load).max())


def test_the_field_stiffens_every_mode_and_the_working_mode_couples(coupled, eigenstrain):
    # K_sc = K_uu + K_uI K_II^-1 K_Iu adds a positive semi-definite term: no mode can drop
    assert eigenstrain.frequency < coupled.frequency < 1.03 * eigenstrain.frequency
    assert coupled.antiresonance > coupled.frequency
    assert 0.05 < coupled.coupling_factor < 0.4
    assert np.all(np.asarray(coupled.antiresonances) >= _frequencies(coupled))


def test_antiresonances_from_the_charges_are_the_open_circuit_modes():
    mesh = quarter_plate_mesh(ORIGINAL_PLATE, COARSE)
    stiffness, mass = assemble_matrices(mesh, ORIGINAL_PLATE)
    system = assemble_piezo_system(mesh, stiffness, mass, ORIGINAL_PLATE.ceramic, 15.0)
    modes = coupled_modes(system, float(analytical.resonance_frequency(ORIGINAL_PLATE)), 6)
    exact = open_circuit_modes(system, modes, 6).eigenvalues
    from_charges = modes.antiresonance_eigenvalues()
    # interlacing of a rank-one update: each zero lies between its resonance and the next
    assert np.all(from_charges[:-1] <= modes.short_circuit.eigenvalues[1:])
    nearest = exact[np.argmin(np.abs(exact[:, None] - from_charges[None]), axis=0)]
    assert np.sqrt(from_charges) == pytest.approx(np.sqrt(nearest), rel=2e-4)


def test_admittance_peaks_at_resonance_dips_at_antiresonance_and_is_passive(coupled):
    f_r, f_a = coupled.frequency, coupled.antiresonance
    frequencies = np.linspace(f_r - 0.3 * (f_a - f_r), f_a + 0.3 * (f_a - f_r), 4001)
    admittance = coupled.admittance(frequencies)
    width = f_r / coupled.q
    assert frequencies[np.argmax(np.abs(admittance))] == pytest.approx(f_r, abs=width)
    assert frequencies[np.argmin(np.abs(admittance))] == pytest.approx(f_a, abs=2 * width)
    assert np.all(admittance.real > 0)  # a passive load absorbs power
    # far below the working modes the plate is a capacitor larger than the clamped one
    low = coupled.admittance(1e3)
    assert low.imag / (2 * np.pi * 1e3) > coupled.clamped_capacitance


def test_the_coupled_result_round_trips_through_plain_data(coupled):
    again = FemResult.from_dict(coupled.to_dict())
    assert again.antiresonances == coupled.antiresonances
    assert again.admittance(30e3) == pytest.approx(coupled.admittance(30e3), rel=1e-12)


def test_the_eigenstrain_result_has_no_admittance(eigenstrain):
    with pytest.raises(Exception, match="coupled piezoelectric model"):
        eigenstrain.admittance(30e3)


def _quarter_bar(length, width, thickness, n_x, n_y, n_z):
    edges = (
        np.linspace(0, length / 2, n_x + 1),
        np.linspace(0, width / 2, n_y + 1),
        np.linspace(0, thickness, n_z + 1),
    )
    cells = np.stack(np.meshgrid(np.arange(n_x), np.arange(n_y), np.arange(n_z), indexing="ij"), -1).reshape(-1, 3)
    return brick_mesh(LAGRANGE_27, edges, cells, np.full(len(cells), CERAMIC), np.ones(len(cells)))


def _bar_length_mode(ceramic, length, width, thickness):
    """f_r, f_a of the length-extensional mode of a free bar poled and electroded through its thickness."""
    mesh = _quarter_bar(length, width, thickness, 12, 1, 1)
    sizes = mesh.sizes
    stiffness, mass = scatter_matrices(
        mesh, LAGRANGE_27.box_stiffness(sizes, ceramic.stiffness_matrix()), LAGRANGE_27.box_mass(sizes, ceramic.density)
    )
    system = assemble_piezo_system(mesh, stiffness, mass, ceramic, 1.0)
    compliance = np.linalg.inv(ceramic.stiffness_matrix())
    modes = coupled_modes(system, 1 / (2 * length * np.sqrt(ceramic.density * compliance[0, 0])), 4)
    length_mode = int(np.argmax(modes.modal_drive**2))
    # the clamped capacitance of the quarter bar's electrodes is eps33^S A / t
    assert system.clamped_capacitance == pytest.approx(
        ceramic.permittivity_matrix()[2, 2] * length * width / 4 / thickness, rel=1e-9
    )
    return modes.short_circuit.frequencies[length_mode], np.sqrt(modes.antiresonance_eigenvalues()[length_mode]) / (
        2 * np.pi
    )


@pytest.mark.parametrize("name", ["PZT-5H", "PZT-4"])
def test_a_free_thin_bar_in_its_length_mode_follows_the_k31_relations(name):
    """IEEE Std 176 / EN 50324-2: f_r = 1 / (2 L sqrt(rho s11^E)), k31^2 = d31^2 / (s11^E eps33^T) and
    k31^2 / (1 - k31^2) = (pi/2) (f_a/f_r) tan((pi/2) (f_a - f_r) / f_r), for a bar much longer than wide."""
    ceramic = materials.ceramic(name)
    compliance = np.linalg.inv(ceramic.stiffness_matrix())
    charge = ceramic.piezo_matrix() @ compliance
    free_permittivity = ceramic.permittivity_matrix()[2, 2] + charge[2] @ ceramic.piezo_matrix()[2]
    k31_squared = charge[2, 0] ** 2 / (compliance[0, 0] * free_permittivity)
    length = 30e-3
    errors = []
    for width in (3e-3, 1.5e-3, 0.75e-3):
        f_r, f_a = _bar_length_mode(ceramic, length, width, 0.25e-3)
        ratio = (np.pi / 2) * (f_a / f_r) * np.tan((np.pi / 2) * (f_a - f_r) / f_r)
        errors.append(ratio / (k31_squared / (1 - k31_squared)) - 1)
    assert f_r == pytest.approx(1 / (2 * length * np.sqrt(ceramic.density * compliance[0, 0])), rel=1e-4)
    assert abs(errors[-1]) < 1e-3
    # what remains is the bar's finite width (the relations are one-dimensional): it goes as (b / L)^2
    assert 3 < errors[0] / errors[1] < 5.5


@pytest.mark.parametrize("name", ["PZT-5H", "PZT-8"])
def test_element_matrices_give_the_energies_of_uniform_fields_with_full_anisotropy(name):
    # u = eps x and phi = -E . x are in the element's space: u^T K u = V gamma^T c gamma,
    # u^T K_u phi phi = -V E . (e gamma) and phi^T K_phi phi phi = V E . eps^S E (gamma: Voigt, engineering shears)
    ceramic, brick = materials.ceramic(name), LAGRANGE_27
    sizes = np.array([[1.0e-3, 2.0e-3, 0.5e-3]])
    volume = np.prod(sizes)
    points = brick.local_nodes / 2 * sizes[0]
    rng = np.random.default_rng(1)
    strain = rng.normal(size=(3, 3)) * 1e-4
    strain = (strain + strain.T) / 2
    field = rng.normal(size=3) * 1e4
    u = (points @ strain.T).ravel()
    phi = -points @ field
    gamma = np.array([strain[0, 0], strain[1, 1], strain[2, 2], 2 * strain[1, 2], 2 * strain[0, 2], 2 * strain[0, 1]])
    stiffness = brick.box_stiffness(sizes, ceramic.stiffness_matrix())[0]
    coupling = brick.box_piezo_coupling(sizes, ceramic.piezo_matrix())[0]
    permittivity = brick.box_permittivity(sizes, ceramic.permittivity_matrix())[0]
    assert u @ stiffness @ u == pytest.approx(volume * gamma @ ceramic.stiffness_matrix() @ gamma, rel=1e-10)
    assert u @ coupling @ phi == pytest.approx(-volume * field @ (ceramic.piezo_matrix() @ gamma), rel=1e-10)
    assert phi @ permittivity @ phi == pytest.approx(volume * field @ ceramic.permittivity_matrix() @ field, rel=1e-10)
    # and the eigenstress load does the work of sigma* on the strain: u^T f = V sigma* . gamma
    stress = rng.normal(size=(1, 6)) * 1e6
    assert u @ brick.box_prestress_load(sizes, stress)[0] == pytest.approx(volume * stress[0] @ gamma, rel=1e-10)
