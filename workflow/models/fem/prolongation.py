"""Modes of one level as the start of the eigen solve of the next (same cells, higher degree).

The levels of the accuracy control share their cells (:mod:`workflow.models.fem.accuracy`), so a mode
shape of degree k is exactly a function of degree k + 1: interpolating it at the higher level's nodes
loses nothing.  The lower level's modes start a block Krylov space already close to the modes asked for
(:func:`~workflow.models.fem.modes.block_krylov_modes`; docs/fem.md, "Speed").
"""

import numpy as np
import scipy.sparse as sp

from workflow.models.fem.harmonic import ModalSolution
from workflow.models.fem.mesh import BrickMesh


def same_cells(coarse: BrickMesh, fine: BrickMesh) -> bool:
    """Whether two meshes have the same element boundaries and the same kept cells (only degrees may differ)."""
    return (
        all(len(a) == len(b) and np.array_equal(a, b) for a, b in zip(coarse.edges, fine.edges))
        and np.array_equal(coarse.cells, fine.cells)
    )


def node_interpolation(coarse: BrickMesh, fine: BrickMesh) -> sp.csr_matrix:
    """Values at the fine mesh's nodes of functions given at the coarse mesh's nodes, shape (n_fine, n_coarse) [-].

    Both meshes have the same cells (:func:`same_cells`); element by element, the coarse shape functions are
    evaluated at the fine element's reference nodes (one local matrix for every element).
    """
    grids = np.meshgrid(*(fine.brick.node_coordinates(axis) for axis in range(3)), indexing="ij")
    reference = np.stack([grid.ravel() for grid in grids], axis=1)[_local_order(fine)]
    local = coarse.brick.shape(reference)  # (n_local fine, n_local coarse)
    rows = np.repeat(fine.connectivity[:, :, None], coarse.brick.n_nodes, axis=2).ravel()
    cols = np.repeat(coarse.connectivity[:, None, :], fine.brick.n_nodes, axis=1).ravel()
    values = np.broadcast_to(local, (len(fine.cells),) + local.shape).ravel()
    _, first = np.unique(rows.astype(np.int64) * coarse.n_nodes + cols, return_index=True)  # shared nodes: once
    return sp.csr_matrix((values[first], (rows[first], cols[first])), shape=(fine.n_nodes, coarse.n_nodes))


def _local_order(mesh: BrickMesh) -> np.ndarray:
    """Index into the C-ordered node grid of the reference brick of each local node of ``mesh.brick``."""
    shape = tuple(p + 1 for p in mesh.brick.degrees)
    return np.ravel_multi_index(tuple(mesh.brick.local_nodes.T), shape)


def start_block(lower: ModalSolution | None, mesh: BrickMesh, free_dofs: np.ndarray) -> np.ndarray | None:
    """A start for the eigen solve on ``mesh``: the modes of the ``lower`` level interpolated there, shape
    (n_free, n_modes); None without a lower level or when its cells differ."""
    if lower is None or not same_cells(lower.mesh, mesh):
        return None
    full = np.zeros((lower.mesh.n_dofs, lower.vectors.shape[1]))
    full[lower.free_dofs] = lower.vectors
    nodal = full.reshape(lower.mesh.n_nodes, 3, -1)
    interpolation = node_interpolation(lower.mesh, mesh)
    fine = np.stack([interpolation @ nodal[:, component] for component in range(3)], axis=1).reshape(mesh.n_dofs, -1)
    return fine[free_dofs]
