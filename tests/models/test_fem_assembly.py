"""The fast, pattern-cached assembly of the reduced FEM system against the plain COO assembly."""

import numpy as np
import pytest

from workflow.models.fem import FemSettings
from workflow.models.fem.assembly import (
    assemble_matrices,
    assemble_piezo_load,
    assemble_system,
    free_dofs,
    node_pairs,
    reduce_system,
    reduced_pattern,
)
from workflow.models.fem.mesh import quarter_plate_mesh
from workflow.models.plate import ORIGINAL_PLATE

SMALL = FemSettings(elements_per_ceramic=4, elements_per_gap=2, elements_per_layer=2, elements_across_half_width=3, grading=0.6)
"""A small graded mesh with several distinct element boxes [-]."""


def _plain(mesh, plate):
    stiffness, mass = assemble_matrices(mesh, plate)
    return reduce_system(mesh, stiffness, mass, assemble_piezo_load(mesh, plate, 15.0))


@pytest.mark.parametrize("element", ["lagrange27", "serendipity20"])
@pytest.mark.parametrize("glue", [0.0, 30e-6])
def test_pattern_assembly_equals_the_plain_one(element, glue):
    plate = ORIGINAL_PLATE.with_(glue_thickness=glue)
    mesh = quarter_plate_mesh(plate, FemSettings(**{**SMALL.as_dict(), "element": element}))
    fast, plain = assemble_system(mesh, plate, 15.0), _plain(mesh, plate)
    assert np.array_equal(fast.free_dofs, plain.free_dofs)
    assert np.array_equal(fast.load, plain.load)
    # the stiffness has the plain pattern (rows sorted) and its values to rounding
    assert np.array_equal(fast.stiffness.indptr, plain.stiffness.indptr)
    assert np.array_equal(fast.stiffness.indices, plain.stiffness.indices)
    assert fast.stiffness.has_sorted_indices and fast.mass.has_sorted_indices
    columns = np.repeat(np.arange(fast.stiffness.shape[1]), np.diff(fast.stiffness.indptr))
    assert np.array_equal(reduced_pattern(mesh, fast.free_dofs).diagonal_entries,
                          np.flatnonzero(fast.stiffness.indices == columns))
    scale = abs(plain.stiffness).max()
    assert abs(fast.stiffness - plain.stiffness).max() <= 1e-14 * scale
    # the mass keeps only the couplings of equal components (the plain one stores the others as zeros)
    assert abs(fast.mass - plain.mass).max() <= 1e-14 * abs(plain.mass).max()
    assert fast.mass.nnz == np.count_nonzero(plain.mass.data)


def test_pattern_depends_on_the_topology_only():
    mesh = quarter_plate_mesh(ORIGINAL_PLATE, SMALL)
    thinner = ORIGINAL_PLATE.with_(resonator_thickness=1.2e-3, wavelength=22e-3)
    other = quarter_plate_mesh(thinner, SMALL)
    assert np.array_equal(mesh.connectivity, other.connectivity)
    assert reduced_pattern(other, free_dofs(other)) is reduced_pattern(mesh, free_dofs(mesh))
    fast, plain = assemble_system(other, thinner, 15.0), _plain(other, thinner)
    assert abs(fast.stiffness - plain.stiffness).max() <= 1e-14 * abs(plain.stiffness).max()
    finer = quarter_plate_mesh(ORIGINAL_PLATE, SMALL.refined(2))
    assert reduced_pattern(finer, free_dofs(finer)) is not reduced_pattern(mesh, free_dofs(mesh))


def _sorted_pairs(connectivity, n_nodes):
    """The element node pairs by sorting them all (the slower way :func:`node_pairs` replaces)."""
    pairs, slots = np.unique((connectivity[:, :, None] * n_nodes + connectivity[:, None, :]).ravel(),
                             return_inverse=True)
    rows, cols = np.divmod(pairs, n_nodes)
    return rows, cols, slots.reshape(connectivity.shape + connectivity.shape[1:]), np.searchsorted(pairs, cols * n_nodes + rows)


@pytest.mark.parametrize("element", ["spectral-3-3-3", "spectral-4-3-2", "serendipity20"])
@pytest.mark.parametrize("renumbered", [False, True])
def test_node_pairs_are_those_of_sorting_every_element_pair(element, renumbered):
    mesh = quarter_plate_mesh(ORIGINAL_PLATE.with_(glue_thickness=30e-6), FemSettings(**{**SMALL.as_dict(), "element": element}))
    connectivity = mesh.connectivity
    if renumbered:  # nodes not numbered along the grid: the slots are sorted afterwards
        connectivity = np.random.default_rng(3).permutation(mesh.n_nodes)[connectivity]
    found = node_pairs(connectivity, mesh.brick.local_nodes, mesh.n_nodes)
    for got, expected in zip(found, _sorted_pairs(connectivity, mesh.n_nodes)):
        assert np.array_equal(got, expected)
