"""Plain reference path: scikit-fem generic assembly and direct harmonic solves.

Slow on purpose (default quadrature, one complex factorisation per response); it checks
the fast path (:func:`evaluate_fem`) and is timed against it in ``bench/bench_fem.py``.
The mesh, materials and load are the same as the fast path's.
"""

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from skfem import (
    Basis,
    BilinearForm,
    ElementHex2,
    ElementHexS2,
    ElementVector,
    LinearForm,
    MeshHex,
    asm,
)
from skfem.helpers import ddot, dot, sym_grad

from workflow.models import analytical
from workflow.models.fem.assembly import PlateSystem
from workflow.models.fem.elements import VOIGT
from workflow.models.fem.result import FemResult, ModeResult
from workflow.models.fem.mesh import CERAMIC, BrickMesh, quarter_plate_mesh
from workflow.models.fem.probes import antinode_probe_points, mean_deflection, transverse_indicator
from workflow.models.fem.settings import DEFAULT_SETTINGS, FemSettings
from workflow.models.plate import Plate

SKFEM_ELEMENTS = {"lagrange27": ElementHex2, "serendipity20": ElementHexS2}
"""scikit-fem's counterpart of each brick type."""


def skfem_basis(mesh: BrickMesh, quadrature_order=None) -> Basis:
    """A scikit-fem vector basis on the kept cells of ``mesh`` (same cell order).

    ``quadrature_order`` None keeps scikit-fem's default (exact for the element's maximum degree).
    """
    full = MeshHex.init_tensor(*mesh.edges)
    shape = tuple(len(edges) - 1 for edges in mesh.edges)
    centres = full.p[:, full.t].mean(axis=1)
    cell_of_element = np.stack(
        [np.searchsorted(mesh.edges[axis], centres[axis]) - 1 for axis in range(3)], axis=1
    )
    flat_full = np.ravel_multi_index(tuple(cell_of_element.T), shape)
    flat_kept = np.ravel_multi_index(tuple(mesh.cells.T), shape)
    order = np.argsort(flat_full)
    kept = order[np.searchsorted(flat_full[order], flat_kept)]
    used, cells = np.unique(full.t[:, kept], return_inverse=True)
    skmesh = MeshHex(full.p[:, used], cells.reshape(8, -1))
    return Basis(skmesh, ElementVector(SKFEM_ELEMENTS[mesh.brick.name]()), intorder=quadrature_order)


def _mass_form(density):
    @BilinearForm
    def mass(u, v, w):
        return density * dot(u, v)

    return mass


def _elasticity_form(stiffness):
    tensor = np.asarray(stiffness)[VOIGT[:, :, None, None], VOIGT[None, None, :, :]]  # C_ijkl

    @BilinearForm
    def elasticity(u, v, w):
        return ddot(np.einsum("ijkl,kl...->ij...", tensor, sym_grad(u)), sym_grad(v))

    return elasticity


def _eigenstress_form(stress):
    tensor = np.asarray(stress)[VOIGT]

    @LinearForm
    def load(v, w):
        return ddot(tensor[:, :, None, None], v.grad)

    return load


def reference_system(mesh: BrickMesh, plate: Plate, voltage: float, quadrature_order=None):
    """K, M, F assembled by scikit-fem, reduced by the symmetry constraints, and its basis."""
    basis = skfem_basis(mesh, quadrature_order)
    stiffness, mass = 0, 0
    for material_id, material in ((0, plate.resonator), (CERAMIC, plate.ceramic)):
        sub = basis.with_elements(np.flatnonzero(mesh.material == material_id))
        stiffness = stiffness + asm(_elasticity_form(material.stiffness_matrix()), sub)
        mass = mass + asm(_mass_form(material.density), sub)
    load = 0
    for sign in (1.0, -1.0):
        sub = basis.with_elements(np.flatnonzero((mesh.material == CERAMIC) & (mesh.polarity == sign)))
        field = sign * voltage / float(plate.ceramic_thickness)
        load = load + asm(_eigenstress_form(field * plate.ceramic.piezo_matrix()[2]), sub)
    constrained = np.concatenate(
        [
            basis.get_dofs(lambda x: np.isclose(x[0], 0.0)).all("u^1"),
            basis.get_dofs(lambda x: np.isclose(x[1], 0.0)).all("u^2"),
        ]
    )
    free = basis.complement_dofs(constrained)
    system = PlateSystem(
        stiffness=sp.csc_matrix(stiffness)[free][:, free].tocsc(),
        mass=sp.csc_matrix(mass)[free][:, free].tocsc(),
        load=np.asarray(load)[free],
        free_dofs=free,
    )
    return system, basis


def evaluate_fem_reference(
    plate: Plate, q: float, voltage: float, settings: FemSettings = DEFAULT_SETTINGS, quadrature_order=None
) -> FemResult:
    """Same cost as :func:`evaluate_fem` with scikit-fem assembly and a direct solve per mode.

    The returned result has no probe modal model (``probe_model`` is None).  ``quadrature_order``
    5 (3 Gauss points per axis) is already exact for these boxes and much faster than the default.
    """
    mesh = quarter_plate_mesh(plate, settings)
    system, basis = reference_system(mesh, plate, voltage, quadrature_order)
    shift = (2 * np.pi * float(analytical.resonance_frequency(plate))) ** 2
    eigenvalues, vectors = sla.eigsh(system.stiffness, k=settings.n_modes, M=system.mass, sigma=shift, which="LM")
    order = np.argsort(eigenvalues)
    eigenvalues, vectors = eigenvalues[order], vectors[:, order]
    points = antinode_probe_points(plate)
    probes = basis.probes(points.T).tocsr()[2 * len(points) : 3 * len(points)][:, system.free_dofs]
    modes = []
    for eigenvalue, vector in zip(eigenvalues, vectors.T):
        dynamic = (1 + 1j / q) * system.stiffness - eigenvalue * system.mass
        response = sla.spsolve(dynamic.tocsc(), system.load.astype(complex))
        modes.append(
            ModeResult(
                frequency=float(np.sqrt(eigenvalue) / (2 * np.pi)),
                deflection=float(mean_deflection(probes @ response)),
                transverse_indicator=float(transverse_indicator(probes @ vector)),
            )
        )
    best = int(np.argmax([mode.deflection for mode in modes]))
    return FemResult(tuple(modes), best, None, float(voltage), int(system.stiffness.shape[0]))
