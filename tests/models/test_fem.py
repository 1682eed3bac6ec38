"""The quarter-plate FEM: elements, assembly against scikit-fem, drive symmetry, beam theory, paper."""

import dataclasses

import numpy as np
import pytest

from workflow.models import analytical
from workflow.models.materials import isotropic_stiffness
from workflow.models.fem import FemResult, FemSettings, ModeResult, evaluate_fem
from workflow.models.fem.assembly import assemble_matrices, assemble_piezo_load, reduce_system
from workflow.models.fem.elements import BRICKS
from workflow.models.fem.mesh import CERAMIC, quarter_plate_mesh
from workflow.models.fem import modes as modes_module
from workflow.models.fem.accuracy import mesh_for_level
from workflow.models.fem.evaluate import discretise, evaluate_on_mesh
from workflow.models.fem.modes import nearest_modes
from workflow.models.fem.prolongation import start_block
from workflow.models.fem.solvers import factorise
from workflow.models.fem.probes import antinode_probe_points, mean_deflection, probe_matrix
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.plate import ORIGINAL_PLATE

COARSE = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=3)
"""A mesh for fast structural tests (not for accuracy)."""
CLEAN_WIDTH = 55e-3
"""A width whose working mode is free of transverse interference (docs/fem.md) [m]."""


@pytest.fixture(scope="module")
def original_default():
    return evaluate_fem(ORIGINAL_PLATE, q=54.0, voltage=15.0)


@pytest.mark.parametrize("name", sorted(BRICKS))
def test_brick_has_exactly_six_rigid_body_modes_and_partition_of_unity(name):
    brick = BRICKS[name]
    stiffness = brick.box_stiffness(np.array([[1.0e-3, 2.0e-3, 0.5e-3]]), isotropic_stiffness(8e10, 0.3))[0]
    eigenvalues = np.linalg.eigvalsh(stiffness)
    assert np.sum(np.abs(eigenvalues) < 1e-9 * eigenvalues.max()) == 6
    points = np.random.default_rng(0).random((20, 3))
    assert np.allclose(brick.shape(points).sum(axis=1), 1.0)
    assert np.allclose(brick.shape(brick.local_nodes / 2), np.eye(brick.n_nodes))


@pytest.mark.parametrize("element", ["lagrange27", "serendipity20"])
def test_fast_path_matches_scikit_fem_assembly_and_direct_solves(element):
    from workflow.models.fem.reference import evaluate_fem_reference

    settings = dataclasses.replace(COARSE, element=element)
    fast = evaluate_fem(ORIGINAL_PLATE, 54.0, 15.0, settings)
    reference = evaluate_fem_reference(ORIGINAL_PLATE, 54.0, 15.0, settings, quadrature_order=5)
    assert fast.n_dofs == reference.n_dofs
    for mine, theirs in zip(fast.modes, reference.modes):
        assert mine.frequency == pytest.approx(theirs.frequency, rel=1e-9)
        assert mine.transverse_indicator == pytest.approx(theirs.transverse_indicator, abs=1e-8)
    # modal superposition with the shifted residual against a direct complex solve
    assert fast.deflection == pytest.approx(reference.deflection, rel=1e-3)


def test_mesh_leaves_the_gaps_empty_and_alternates_polarity():
    mesh = quarter_plate_mesh(ORIGINAL_PLATE, COARSE)
    centres = np.array([(mesh.edges[0][i] + mesh.edges[0][i + 1]) / 2 for i in mesh.cells[:, 0]])
    ceramic = mesh.material == CERAMIC
    half = float(ORIGINAL_PLATE.ceramic_length) / 2
    nearest = np.round(centres / (ORIGINAL_PLATE.wavelength / 2))
    assert np.all(np.abs(centres[ceramic] - nearest[ceramic] * ORIGINAL_PLATE.wavelength / 2) < half)
    assert np.all(mesh.polarity[ceramic] == np.where(nearest[ceramic] % 2 == 0, 1, -1))
    volume = np.prod(mesh.sizes, axis=1)
    expected = 3.5 * float(ORIGINAL_PLATE.ceramic_length) * ORIGINAL_PLATE.width / 2 * ORIGINAL_PLATE.ceramic_thickness
    assert volume[ceramic].sum() == pytest.approx(expected, rel=1e-12)


def _centreline_shapes(plate, settings, polarity=None):
    """Best-mode data: probe deflections of every mode and w along the top centreline."""
    mesh = quarter_plate_mesh(plate, settings)
    if polarity is not None:
        mesh = dataclasses.replace(mesh, polarity=polarity(mesh))
    stiffness, mass = assemble_matrices(mesh, plate)
    system = reduce_system(mesh, stiffness, mass, assemble_piezo_load(mesh, plate, 15.0))
    modes = nearest_modes(system, float(analytical.resonance_frequency(plate)), settings.n_modes)
    x = np.linspace(0, float(plate.length) / 2, 400)
    line = np.column_stack([x, np.zeros_like(x), np.full_like(x, float(plate.total_thickness))])
    centreline = probe_matrix(mesh, line)[:, system.free_dofs] @ modes.vectors
    return system, modes, centreline


def test_drive_excites_the_seven_antinode_mode_not_its_neighbours():
    plate = ORIGINAL_PLATE.with_(width=CLEAN_WIDTH)
    settings = FemSettings(elements_per_ceramic=4, elements_per_layer=1, elements_across_half_width=4)
    result = evaluate_fem(plate, 54.0, 15.0, settings)
    _, _, centreline = _centreline_shapes(plate, settings)
    shape = centreline[:, result.best_index]
    # 7 antinodes on the full plate: 4 sign changes on the half length (nodes at lambda/4 + k lambda/2)
    assert np.count_nonzero(np.diff(np.sign(shape)) != 0) == 4
    x = np.linspace(0, float(plate.length) / 2, 400)
    at_antinodes = np.interp(np.arange(4) * plate.wavelength / 2, x, shape)
    assert np.all(at_antinodes[:-1] * at_antinodes[1:] < 0)  # antiphase like the ceramics
    assert result.best.transverse_indicator < 0.1
    others = [m.deflection for i, m in enumerate(result.modes) if i != result.best_index]
    assert max(others) < 0.5 * result.deflection


def test_drive_is_symmetric_in_x_and_same_polarity_drive_fails():
    """Symmetric BCs at x = 0 fit the drive; ceramics all poled alike barely excite the mode."""
    plate = ORIGINAL_PLATE.with_(width=CLEAN_WIDTH)
    settings = FemSettings(elements_per_ceramic=4, elements_per_layer=1, elements_across_half_width=4)
    proper = evaluate_fem(plate, 54.0, 15.0, settings)
    system, modes, _ = _centreline_shapes(plate, settings, polarity=lambda mesh: np.abs(mesh.polarity))
    working = np.argmin(np.abs(modes.frequencies - proper.frequency))
    proper_system, proper_modes, _ = _centreline_shapes(plate, settings)
    same_force = abs(modes.vectors[:, working] @ system.load)
    alternating_force = abs(proper_modes.vectors[:, working] @ proper_system.load)
    # alike poling: the ceramics' moments on cos(2 pi x / lambda) cancel but for one in seven
    assert same_force < 0.25 * alternating_force
    assert np.all(np.diff(ORIGINAL_PLATE.polarities[: len(ORIGINAL_PLATE.polarities) // 2 + 1]) != 0)
    assert np.array_equal(ORIGINAL_PLATE.polarities, ORIGINAL_PLATE.polarities[::-1])


def test_rigid_translation_is_never_returned_at_low_frequency():
    plate = ORIGINAL_PLATE.with_(width=6e-3, wavelength=30e-3, resonator_thickness=1e-3, ceramic_thickness=0.5e-3)
    result = evaluate_fem(plate, 54.0, 15.0, COARSE)
    assert all(m.frequency > 100.0 for m in result.modes)
    assert np.all(np.isfinite([m.deflection for m in result.modes]))


def _beam_modal_deflection(plate, voltage, q):
    """Single-mode beam estimate: Q times the modal response to the ceramics' bending moment [m].

    For w = cos(2 pi x / lambda) on L = (2n+1) lambda/4 and the free curvature kappa of the
    bilayer under the field, w = Q kappa lambda^2 16 n cos(pi delta / lambda) / ((2n+1) 8 pi^3).
    """
    n = plate.n_ceramics
    kappa = abs(float(analytical.curvature(plate, voltage)))
    gap_factor = np.cos(np.pi * plate.gap / plate.wavelength)
    return q * kappa * plate.wavelength**2 * 16 * n * gap_factor / ((2 * n + 1) * 8 * np.pi**3)


def test_narrow_thin_beam_matches_beam_theory():
    """Where Bernoulli-Euler holds (b and h small against lambda) frequency and deflection agree."""
    plate = ORIGINAL_PLATE.with_(width=6e-3, wavelength=30e-3, resonator_thickness=1e-3, ceramic_thickness=0.5e-3)
    result = evaluate_fem(plate, 54.0, 15.0, FemAccuracy(target=0.01))
    assert result.frequency == pytest.approx(float(analytical.resonance_frequency(plate)), rel=0.02)
    assert result.deflection == pytest.approx(_beam_modal_deflection(plate, 15.0, 54.0), rel=0.03)
    # the calibrated beam model (BEAM_CALIBRATION) is the paper's fit, below the single-mode estimate
    calibrated = float(analytical.dynamic_deflection(plate, 15.0, 54.0))
    assert 1.1 < result.deflection / calibrated < 1.4


def test_clean_wide_plate_lies_between_beam_and_plate_bending():
    """A wide plate bends like a plate: beam estimate <= w <= (1 + nu) beam estimate."""
    plate = ORIGINAL_PLATE.with_(width=CLEAN_WIDTH)
    result = evaluate_fem(plate, 54.0, 15.0, FemAccuracy(target=0.01))
    beam = _beam_modal_deflection(plate, 15.0, 54.0)
    assert result.best.transverse_indicator < 0.1
    assert beam < result.deflection < (1 + plate.ceramic.poisson_ratio) * beam


def test_original_plate_frequency_near_beam_and_paper(original_default):
    """Validation at the default accuracy (0.2 %): paper FEM (COMSOL) 31.17 kHz, 1.151 um; tolerance 2 % in f,
    10 % in w (mode mixing at 49 mm)."""
    assert original_default.error.met
    beam = float(analytical.resonance_frequency(ORIGINAL_PLATE))
    assert original_default.frequency == pytest.approx(beam, rel=0.05)
    assert original_default.frequency == pytest.approx(31.17e3, rel=0.02)
    assert original_default.deflection == pytest.approx(1.151e-6, rel=0.10)


def test_result_api_and_round_trip(original_default):
    result = original_default
    assert len(result.modes) == 6 and all(isinstance(m, ModeResult) for m in result.modes)
    assert result.best is max(result.modes, key=lambda m: m.deflection)
    frequencies = [m.frequency for m in result.modes]
    assert frequencies == sorted(frequencies)
    assert result.deflection_at_q(54.0) == pytest.approx(result.deflection, rel=1e-12)
    q = np.array([20.0, 54.0, 108.0])
    scaled = result.deflection_at_q(q)
    assert scaled.shape == (3,)
    # w ~ Q for the resonant part; at 49 mm the mixed-in neighbour mode adds a part that is not
    assert np.all(np.diff(scaled) > 0) and 1.5 < scaled[2] / scaled[1] <= 2.0 + 1e-9
    again = FemResult.from_dict(result.to_dict())
    assert again.deflection == result.deflection and again.error == result.error
    assert np.allclose(again.deflection_at_q(q), scaled)
    settings = FemSettings()
    assert hash(settings) == hash(FemSettings(**settings.as_dict()))


def test_deflection_scales_linearly_with_voltage():
    low = evaluate_fem(ORIGINAL_PLATE, 54.0, 5.0, COARSE)
    high = evaluate_fem(ORIGINAL_PLATE, 54.0, 15.0, COARSE)
    assert high.deflection == pytest.approx(3 * low.deflection, rel=1e-9)
    assert high.frequency == pytest.approx(low.frequency, rel=1e-12)


def test_probe_points_are_the_44_antinode_points():
    points = antinode_probe_points(ORIGINAL_PLATE)
    assert points.shape == (44, 3)
    assert np.allclose(np.unique(points[:, 0]), np.arange(4) * ORIGINAL_PLATE.wavelength / 2)
    assert np.allclose(np.unique(points[:, 1]), np.linspace(0, ORIGINAL_PLATE.width / 2, 11))
    assert mean_deflection(np.array([1.0, -3.0])) == 2.0


def test_bad_settings_are_refused():
    from workflow.errors import TactileError

    with pytest.raises(TactileError, match="even"):
        FemSettings(elements_per_ceramic=3)
    with pytest.raises(TactileError, match="element"):
        FemSettings(element="tet4")


def test_block_krylov_from_the_lower_level_finds_arpacks_modes(monkeypatch):
    """The block method started from the degree-2 modes gives ARPACK's six degree-3 eigenpairs, without falling back."""
    plate = ORIGINAL_PLATE
    lower = evaluate_on_mesh(plate, 54.0, 15.0, mesh_for_level(plate, 2)).solution
    mesh, system, _ = discretise(plate, 15.0, mesh_for_level(plate, 3))
    shift = (2 * np.pi * float(analytical.resonance_frequency(plate))) ** 2
    solve = factorise(system.shifted(shift)).solve
    start = start_block(lower, mesh, system.free_dofs)
    arpack = modes_module.shift_invert_modes(system, shift, solve, 6, start @ np.linspace(1, 2, 6))
    monkeypatch.setattr(modes_module.sla, "eigsh", None)  # no fallback to ARPACK
    block = modes_module.shift_invert_modes(system, shift, solve, 6, start)
    np.testing.assert_allclose(block.eigenvalues, arpack.eigenvalues, rtol=1e-12)
    match = np.abs(np.einsum("im,im->m", block.vectors, system.mass @ arpack.vectors))  # both mass-normalised
    np.testing.assert_allclose(match, 1.0, atol=1e-10)
