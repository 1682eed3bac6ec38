"""Structures shared between evaluations: a block matrix laid out once per structure of its blocks."""

import numpy as np
import pytest
import scipy.sparse as sp

from workflow.models.fem import solvers
from workflow.models.fem.structures import shared, shared_block_matrix


def _blocks(seed: int, shared_structure: sp.csc_matrix):
    rng = np.random.default_rng(seed)
    top_left = sp.csc_matrix((rng.standard_normal(shared_structure.nnz), shared_structure.indices,
                              shared_structure.indptr), shape=shared_structure.shape)
    coupling = sp.random(shared_structure.shape[0], 7, density=0.3, random_state=1, format="csc")
    coupling.data = rng.standard_normal(coupling.nnz)
    inner = sp.random(7, 7, density=0.5, random_state=2, format="csc")
    inner = (inner + inner.T + 7 * sp.eye(7)).tocsc()
    return [[top_left, coupling], [coupling.T, -inner]]


def test_a_block_matrix_is_bmat_on_one_read_only_layout_per_structure():
    structure = sp.random(30, 30, density=0.2, random_state=0, format="csc")
    structure = (structure + structure.T).tocsc()
    structure.sort_indices()
    for array in (structure.indices, structure.indptr):
        array.flags.writeable = False  # as the assembly's patterns
    first_blocks, second_blocks = _blocks(0, structure), _blocks(1, structure)
    first, second = shared_block_matrix(first_blocks), shared_block_matrix(second_blocks)
    for blocks, matrix in ((first_blocks, first), (second_blocks, second)):
        assert abs(matrix - sp.bmat(blocks, format="csc")).max() == 0
    assert shared(first) and shared(second)  # read-only: the solvers remember what they derive from it
    assert np.shares_memory(first.indices, second.indices) and np.shares_memory(first.indptr, second.indptr)


def test_the_factorisations_of_a_shared_block_layout_share_their_analysis():
    if "pardiso" not in solvers.available_solvers():
        pytest.skip("pypardiso is not installed")
    structure = sp.random(40, 40, density=0.2, random_state=3, format="csc")
    structure = (structure + structure.T + 40 * sp.eye(40)).tocsc()
    first = shared_block_matrix([[structure, None], [None, sp.eye(3, format="csc")]])  # its own arrays: by content
    second = shared_block_matrix([[2 * structure, None], [None, 3 * sp.eye(3, format="csc")]])
    factor_1, factor_2 = solvers.factorise(first), solvers.factorise(second)
    assert factor_1._analysis is factor_2._analysis
    rhs = np.ones(first.shape[0])
    for factor, matrix in ((factor_1, first), (factor_2, second)):
        assert np.linalg.norm(matrix @ factor.solve(rhs) - rhs) <= 1e-10 * np.linalg.norm(rhs)
