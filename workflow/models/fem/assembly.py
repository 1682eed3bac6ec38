"""Vectorised assembly of stiffness, mass and piezo load on a :class:`BrickMesh`.

Element matrices depend only on the element's box size and material, so they are computed
once per distinct (size, material) and scattered with one COO assembly.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from workflow.models.fem.mesh import CERAMIC, GLUE, RESONATOR, BrickMesh, symmetry_dofs
from workflow.models.plate import Plate


@dataclass(frozen=True, eq=False)
class PlateSystem:
    """Reduced (symmetry-constrained) system K u = F, mass M, and the map back to all dofs.

    Attributes
    ----------
    stiffness, mass : scipy.sparse.csc_matrix
        K [N/m] and M [kg] on the free dofs.
    load : array
        Piezo load F for the drive voltage [N].
    free_dofs : int array
        Global dof number of each free dof.
    """

    stiffness: sp.csc_matrix
    mass: sp.csc_matrix
    load: np.ndarray
    free_dofs: np.ndarray


def _materials(plate: Plate):
    return {RESONATOR: plate.resonator, CERAMIC: plate.ceramic, GLUE: plate.glue}


def element_dofs(mesh: BrickMesh) -> np.ndarray:
    """Global dofs of each element, shape (n, 3 n_local), local dof 3 a + component."""
    return (3 * mesh.connectivity[:, :, None] + np.arange(3)).reshape(len(mesh.cells), -1)


def element_matrices(mesh: BrickMesh, plate: Plate):
    """Stiffness and mass of every element, each of shape (n, 3 n_local, 3 n_local) [N/m], [kg]."""
    sizes = mesh.sizes
    keys = np.column_stack([sizes, mesh.material])
    unique_keys, which = np.unique(np.round(keys, 15), axis=0, return_inverse=True)
    n_local = 3 * mesh.brick.n_nodes
    stiffness = np.empty((len(unique_keys), n_local, n_local))
    mass = np.empty_like(stiffness)
    for material_id, material in _materials(plate).items():
        rows = unique_keys[:, 3] == material_id
        stiffness[rows] = mesh.brick.box_stiffness(unique_keys[rows, :3], material.stiffness_matrix())
        mass[rows] = mesh.brick.box_mass(unique_keys[rows, :3], material.density)
    return stiffness[which.ravel()], mass[which.ravel()]


def scatter_matrices(mesh: BrickMesh, *locals_) -> tuple:
    """Global matrices (all dofs) summed from element matrices, each of shape (n, 3 n_local, 3 n_local)."""
    dofs = element_dofs(mesh)
    n_local = dofs.shape[1]
    rows = np.repeat(dofs, n_local, axis=1).ravel()
    cols = np.tile(dofs, (1, n_local)).ravel()
    shape = (mesh.n_dofs, mesh.n_dofs)
    return tuple(sp.coo_matrix((local.ravel(), (rows, cols)), shape=shape).tocsc() for local in locals_)


def assemble_matrices(mesh: BrickMesh, plate: Plate):
    """Global stiffness and mass (all dofs), shape (n_dofs, n_dofs) [N/m], [kg]."""
    return scatter_matrices(mesh, *element_matrices(mesh, plate))


def assemble_piezo_load(mesh: BrickMesh, plate: Plate, voltage: float) -> np.ndarray:
    """Load of the converse effect of a uniform field E_z = polarity V / h_p in each ceramic [N].

    The eigenstress is sigma* = e^T E (e the ceramic's piezo stress constants); for the paper's
    record, e = c^E d, it is the in-plane isotropic eigenstrain d31 V / h_p.
    """
    ceramic = mesh.material == CERAMIC
    field = voltage / float(plate.ceramic_thickness) * mesh.polarity[ceramic]
    stress = field[:, None] * plate.ceramic.piezo_matrix()[2][None, :]
    local = mesh.brick.box_prestress_load(mesh.sizes[ceramic], stress)
    return np.bincount(element_dofs(mesh)[ceramic].ravel(), weights=local.ravel(), minlength=mesh.n_dofs)


def reduce_system(mesh: BrickMesh, stiffness, mass, load) -> PlateSystem:
    """Apply the symmetry constraints by removing the constrained dofs."""
    free = np.setdiff1d(np.arange(mesh.n_dofs), symmetry_dofs(mesh))
    return PlateSystem(
        stiffness=stiffness[free][:, free].tocsc(),
        mass=mass[free][:, free].tocsc(),
        load=load[free],
        free_dofs=free,
    )


def assemble_system(mesh: BrickMesh, plate: Plate, voltage: float) -> PlateSystem:
    """K, M and F of the quarter plate with its symmetry constraints."""
    stiffness, mass = assemble_matrices(mesh, plate)
    return reduce_system(mesh, stiffness, mass, assemble_piezo_load(mesh, plate, voltage))
