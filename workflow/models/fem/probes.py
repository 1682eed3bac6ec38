"""The 44 deflection probes on the top face and the transverse-mode indicator (docs/fem.md)."""

import numpy as np
import scipy.sparse as sp

from workflow.models.fem.mesh import BrickMesh, top_face
from workflow.models.plate import Plate

N_ANTINODE_LINES = 4
"""Antinode lines of the quarter plate: x = 0, lambda/2, lambda, 3 lambda/2."""
POINTS_PER_LINE = 11
"""Probe points per antinode line across y in [0, b/2]."""


def antinode_probe_points(plate: Plate) -> np.ndarray:
    """Probe points on the top face, shape (4 * 11, 3), line-major [m]."""
    x = np.arange(N_ANTINODE_LINES) * float(plate.wavelength) / 2
    y = np.linspace(0.0, float(plate.width) / 2, POINTS_PER_LINE)
    z = top_face(plate)
    xx, yy = np.meshgrid(x, y, indexing="ij")
    return np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)])


def _locate(edges, values):
    """Element index along one axis and the reference coordinate in [0, 1]."""
    index = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
    return index, (values - edges[index]) / (edges[index + 1] - edges[index])


def probe_matrix(mesh: BrickMesh, points: np.ndarray, component: int = 2) -> sp.csr_matrix:
    """Sparse interpolation matrix P with (P u)_p = u_component(point p), shape (n_points, n_dofs) [-].

    The points must lie in the resonator layer (present everywhere along x).
    """
    located = [_locate(mesh.edges[axis], points[:, axis]) for axis in range(3)]
    cells = np.column_stack([index for index, _ in located])
    reference = np.column_stack([xi for _, xi in located])
    grid_nodes = np.asarray(mesh.brick.degrees) * cells[:, None, :] + mesh.brick.local_nodes[None]
    nodes = mesh.node_number[tuple(np.moveaxis(grid_nodes, -1, 0))]
    rows = np.repeat(np.arange(len(points)), mesh.brick.n_nodes)
    return sp.csr_matrix(
        (mesh.brick.shape(reference).ravel(), (rows, (3 * nodes + component).ravel())),
        shape=(len(points), mesh.n_dofs),
    )


def mean_deflection(probe_values) -> np.ndarray:
    """Mean |w| over the probes (last axis) [m]."""
    return np.mean(np.abs(probe_values), axis=-1)


def transverse_indicator(probe_values) -> np.ndarray:
    """Share of the variance of w along y at the antinode lines [-] (0: purely longitudinal).

    sum over lines of sum_y |w - mean_y w|^2 divided by sum over lines of sum_y |w|^2.
    """
    lines = np.asarray(probe_values).reshape(np.shape(probe_values)[:-1] + (N_ANTINODE_LINES, POINTS_PER_LINE))
    variation = np.abs(lines - lines.mean(axis=-1, keepdims=True)) ** 2
    return variation.sum(axis=(-2, -1)) / (np.abs(lines) ** 2).sum(axis=(-2, -1))
