"""Design sensitivities of the FEM: derivatives of the probe modal model w.r.t. lambda and h_i.

Within the design space the mesh topology does not change with the wavelength lambda or the
resonator thickness h_i: the element counts stay, only the element sizes move, and the probes
stay at fixed positions of the morphing mesh.  K, M, F and the probe matrix P are therefore
smooth functions of the design on one discrete structure, and their derivatives dK, dM, dF, dP
are central differences of the element matrices, loads and probe matrices of two slightly
perturbed plates (checked to have the same topology).  The modal data then follow from the
one eigen-solve and its factorisation of K - sigma M, for mass-normalised modes phi_j of
K phi = lam M phi:

* eigenvalues: dlam_j = phi_j^T (dK - lam_j dM) phi_j (exact);
* mode shapes: (K - lam_j M) dphi_j = r_j = -(dK - lam_j dM) phi_j + dlam_j M phi_j with
  phi_j^T M dphi_j = -phi_j^T dM phi_j / 2.  Along the other computed modes the coefficients
  are exact, phi_i^T r_j / (lam_i - lam_j); the part M-orthogonal to them is solved in a block
  Krylov space of (K - sigma M)^-1 M on that complement (see :func:`complement_solve`);
* modal forces d(phi^T F), probe shapes d(P phi), and the shifted residual
  P (K - sigma M)^-1 (F - M Phi Phi^T F), differentiated with the shift sigma(p) of the
  analytical resonance that :func:`~workflow.models.fem.evaluate.evaluate_fem` uses.

The derivatives are tangent :class:`~workflow.models.fem.harmonic.ProbeModalModel` objects (fields hold
derivatives per metre), so any function of the probe model or of a :class:`FemResult` is
differentiated by a central difference along them in the reduced space (:func:`gradient`),
with the best mode's index held fixed (the one-sided derivative of the max).
"""

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from workflow.errors import TactileError
from workflow.models import analytical
from workflow.models.fem.assembly import PlateSystem, assemble_piezo_load, element_types, free_dofs, reduced_matrices
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.fem.evaluate import discretise, evaluate_fem, working_modes
from workflow.models.fem.result import FemResult, fem_result
from workflow.models.fem.harmonic import ProbeModalModel, probe_modal_model, shifted_residual
from workflow.models.fem.mesh import BrickMesh, quarter_plate_mesh
from workflow.models.fem.modes import ShiftedModes, mass_orthonormal
from workflow.models.fem.probes import antinode_probe_points, probe_matrix
from workflow.models.fem.settings import FemSettings
from workflow.models.plate import Plate

DESIGN_PARAMETERS = ("wavelength", "resonator_thickness")
"""The design parameters differentiated by default, as :class:`~workflow.models.plate.Plate` fields [m]."""
ASSEMBLY_STEP = 1e-5
"""Relative step of the central differences of the assembled system [-].

The entries are smooth rational functions of the element sizes: truncation ~1e-10 relative;
round-off is dominated by the assembly's grouping of element sizes rounded to 1e-15 m
(~1e-11 relative), ~1e-6 after division by the step.  Forward differences are not enough:
near two veering modes the mode coupling phi_i^T dK phi_j / (lam_j - lam_i) amplifies their
O(step) error by ~200 in the deflection's gradient."""
KRYLOV_BLOCKS = 5
"""Blocks of the Krylov space of the complement solve [-] (error of the probe-shape
derivatives ~1e-6 relative on the default mesh; each block gains about two digits)."""
ORTHONORMAL_RTOL = 1e-6
"""M-norm of a Krylov direction of the complement solve, relative to its block, below which it is dropped [-]."""
DIRECTIONAL_STEP = 1e-8
"""Step of the design parameter along a tangent for the central differences of :func:`gradient` [m].

Small against the scales on which the response bends (f_r / Q in frequency, the gap of two
veering modes), so truncation is negligible; round-off costs ~1e-16 p / step, below 1e-10
relative for p >= 0.2 mm."""


class TopologyError(TactileError):
    """The perturbed plate's mesh is not the same discrete structure as the plate's."""


@dataclass(frozen=True, eq=False)
class SystemTangent:
    """Derivative of the discretised plate with respect to one design parameter p.

    Attributes
    ----------
    stiffness, mass : scipy.sparse.csc_matrix
        dK/dp [N/m^2] and dM/dp [kg/m] on the free dofs.
    load : array
        dF/dp [N/m].
    probes : scipy.sparse.csr_matrix
        dP/dp of the probe matrix [1/m] (zero while the probes stay at fixed mesh positions).
    shift : float
        d sigma/dp of the eigen-solve's shift [rad^2 s^-2 m^-1].
    """

    stiffness: sp.csc_matrix
    mass: sp.csc_matrix
    load: np.ndarray
    probes: sp.csr_matrix
    shift: float


def check_same_topology(mesh: BrickMesh, other: BrickMesh) -> None:
    """Raise :class:`TopologyError` unless two meshes have the same elements, nodes and materials."""
    counts, other_counts = [len(e) for e in mesh.edges], [len(e) for e in other.edges]
    if counts != other_counts:
        raise TopologyError(f"the mesh changes from {counts} to {other_counts} element edges along x, y, z")
    for name in ("cells", "material", "polarity", "node_number", "connectivity"):
        if not np.array_equal(getattr(mesh, name), getattr(other, name)):
            raise TopologyError(f"the mesh's {name} changes with the design parameter")


def _shift(plate: Plate) -> float:
    """The shift sigma = (2 pi f_beam)^2 of :func:`~workflow.models.fem.evaluate.working_modes` [rad^2/s^2]."""
    return (2 * np.pi * float(analytical.resonance_frequency(plate))) ** 2


def system_tangent(
    plate: Plate,
    parameter: str,
    voltage: float,
    settings: FemSettings,
    mesh: BrickMesh,
    relative_step: float = ASSEMBLY_STEP,
) -> SystemTangent:
    """Central-difference derivative of K, M, F, P and sigma with respect to one plate field.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    parameter : str
        The :class:`~workflow.models.plate.Plate` field differentiated.
    voltage : float
        Drive amplitude [V].
    settings : FemSettings
    mesh : BrickMesh
        The plate's mesh, whose topology the perturbed plates must share.
    relative_step : float
        Step as a fraction of the parameter's value [-].

    Raises
    ------
    TopologyError
        When a perturbed plate's mesh has another topology (a parameter at a mesh-count threshold).
    """
    value = float(getattr(plate, parameter))
    plates = [plate.with_(**{parameter: value * (1 + sign * relative_step)}) for sign in (1, -1)]
    step = float(getattr(plates[0], parameter)) - float(getattr(plates[1], parameter))  # as taken in floating point
    meshes = [quarter_plate_mesh(moved, settings) for moved in plates]
    for moved_mesh in meshes:
        check_same_topology(mesh, moved_mesh)
    # differences of the distinct element matrices (a type per pair of types of the two plates), summed once
    # through the topology's pattern (cheaper than differencing two assemblies)
    (stiffness_plus, mass_plus, which_plus), (stiffness_minus, mass_minus, which_minus) = map(element_types, meshes, plates)
    pairs, which = np.unique(np.column_stack([which_plus, which_minus]), axis=0, return_inverse=True)
    plus, minus = pairs[:, 0], pairs[:, 1]
    free = free_dofs(mesh)
    stiffness, mass = reduced_matrices(mesh, free, (stiffness_plus[plus] - stiffness_minus[minus]) / step,
                                       (mass_plus[plus] - mass_minus[minus]) / step, which.ravel())
    load_plus, load_minus = (assemble_piezo_load(m, moved, voltage) for m, moved in zip(meshes, plates))
    probes_plus, probes_minus = (probe_matrix(m, antinode_probe_points(moved)) for m, moved in zip(meshes, plates))
    return SystemTangent(
        stiffness=stiffness,
        mass=mass,
        load=((load_plus - load_minus) / step)[free],
        probes=((probes_plus - probes_minus) / step)[:, free].tocsr(),
        shift=(_shift(plates[0]) - _shift(plates[1])) / step,
    )


def complement_solve(
    system: PlateSystem, modes: ShiftedModes, rhs: np.ndarray, eigenvalues: np.ndarray, n_blocks: int = KRYLOV_BLOCKS
) -> np.ndarray:
    """Solve (K - lam_k M) v_k = r_k for v_k M-orthogonal to the computed modes, column by column.

    The right-hand sides must be orthogonal to the computed modes (Phi^T r_k = 0).  With
    A = K - sigma M (factorised by the eigen-solve) the system is (I - (lam_k - sigma) A^-1 M) v_k
    = A^-1 r_k; on the complement of the computed modes A^-1 M has the eigenvalues
    1/(lam_m - sigma) of the other modes, all smaller than 1/|lam_k - sigma| since the computed
    modes are the ones nearest sigma, so this is a well-posed, shift-invariant system: one
    block Krylov space span{B, A^-1 M B, ...} of B = A^-1 R serves every column, and the
    Galerkin solution in the M inner product never meets a singular projected matrix.  Its
    error falls fast because only the few modes just outside the computed window need their
    own Krylov directions (a Neumann series would converge at the rate
    |lam_k - sigma| / min_m |lam_m - sigma|, close to 1 for the outermost computed modes).

    Parameters
    ----------
    system : PlateSystem
    modes : ShiftedModes
        The computed modes and the factorisation.
    rhs : (n_free, n_rhs) array
        Right-hand sides r_k [N].
    eigenvalues : (n_rhs,) array
        lam_k of each column [rad^2/s^2].
    n_blocks : int
        Krylov blocks (each costs one solve and one mass product of n_rhs columns) [-].

    Returns
    -------
    (n_free, n_rhs) array
        v_k [m].
    """
    mass, vectors = system.mass, modes.vectors
    mass_vectors = mass @ vectors

    def complement(block):
        return block - vectors @ (mass_vectors.T @ block)

    start = complement(modes.solve_shifted(rhs))
    basis, mass_basis, images = [], [], []
    block = start
    for _ in range(n_blocks):
        block, mass_block = mass_orthonormal(block, basis, mass_basis, mass, ORTHONORMAL_RTOL)
        if block.shape[1] == 0:
            break
        basis.append(block)
        mass_basis.append(mass_block)
        images.append(modes.solve_shifted(mass_block))
        block = complement(images[-1])
    basis, mass_basis, images = (np.hstack(blocks) for blocks in (basis, mass_basis, images))
    projected = mass_basis.T @ images  # V^T M A^-1 M V
    projected = (projected + projected.T) / 2
    coordinates = mass_basis.T @ start
    identity = np.eye(len(projected))
    solutions = np.column_stack(
        [
            np.linalg.solve(identity - (eigenvalue - modes.shift) * projected, coordinates[:, k])
            for k, eigenvalue in enumerate(eigenvalues)
        ]
    )
    return basis @ solutions


def _mode_tangent(system: PlateSystem, modes: ShiftedModes, tangent: SystemTangent):
    """dlam, the in-span coefficients C (dPhi = Phi C + complement part) and the complement's right-hand sides."""
    vectors, eigenvalues = modes.vectors, modes.eigenvalues
    stiffness_vectors = tangent.stiffness @ vectors
    mass_vectors = tangent.mass @ vectors
    stiffness_modal = vectors.T @ stiffness_vectors
    mass_modal = vectors.T @ mass_vectors
    eigenvalue_tangent = np.diag(stiffness_modal) - eigenvalues * np.diag(mass_modal)
    coupling = stiffness_modal - mass_modal * eigenvalues  # phi_i^T (dK - lam_j dM) phi_j
    gaps = eigenvalues[None, :] - eigenvalues[:, None]  # lam_j - lam_i
    np.fill_diagonal(gaps, 1.0)
    coefficients = coupling / gaps
    np.fill_diagonal(coefficients, -np.diag(mass_modal) / 2)
    rhs = -(stiffness_vectors - mass_vectors * eigenvalues) + (system.mass @ vectors) * eigenvalue_tangent
    rhs -= system.mass @ (vectors @ (vectors.T @ rhs))
    return eigenvalue_tangent, coefficients, rhs


def probe_model_tangents(
    system: PlateSystem, modes: ShiftedModes, probes, tangents: list, n_blocks: int = KRYLOV_BLOCKS
) -> list:
    """Derivatives of the probe modal model of ``system`` along each system tangent.

    Parameters
    ----------
    system : PlateSystem
    modes : ShiftedModes
    probes : sparse matrix
        Probe matrix on the free dofs, shape (n_probes, n_free) [-].
    tangents : list of SystemTangent
    n_blocks : int
        Krylov blocks of the complement solve [-].

    Returns
    -------
    list of ProbeModalModel
        Per tangent, the derivative of every field of :func:`~workflow.models.fem.harmonic.probe_modal_model` [per m].
    """
    with threadpool_limits(limits=1, user_api="blas"):  # threaded BLAS makes SuperLU's multi-column solves ~20x slower
        return _probe_model_tangents(system, modes, probes, tangents, n_blocks)


def _probe_model_tangents(system, modes, probes, tangents, n_blocks):
    vectors, eigenvalues = modes.vectors, modes.eigenvalues
    parts = [_mode_tangent(system, modes, tangent) for tangent in tangents]
    rhs = np.hstack([part_rhs for _, _, part_rhs in parts])
    outside = complement_solve(system, modes, rhs, np.tile(eigenvalues, len(tangents)), n_blocks)
    outside = np.split(outside, len(tangents), axis=1)
    vector_tangents = [vectors @ coefficients + part for (_, coefficients, _), part in zip(parts, outside)]
    force_tangents = [dphi.T @ system.load + vectors.T @ t.load for dphi, t in zip(vector_tangents, tangents)]
    residual = shifted_residual(system, modes)
    residual_rhs = [
        _residual_tangent_rhs(system, modes, residual, *arguments)
        for arguments in zip(tangents, vector_tangents, force_tangents)
    ]
    residual_tangents = modes.solve_shifted(np.column_stack(residual_rhs)).T
    return [
        ProbeModalModel(
            eigenvalues=eigenvalue_tangent,
            modal_forces=force_tangent,
            probe_shapes=np.asarray(tangent.probes @ vectors + probes @ vector_tangent),
            residual=np.asarray(tangent.probes @ residual + probes @ residual_tangent),
        )
        for tangent, (eigenvalue_tangent, _, _), vector_tangent, force_tangent, residual_tangent in zip(
            tangents, parts, vector_tangents, force_tangents, residual_tangents
        )
    ]


def _residual_tangent_rhs(system, modes, residual, tangent, vector_tangent, force_tangent):
    """A d(residual) for residual = A^-1 (F - M Phi a), A = K - sigma M, a = Phi^T F [N/m].

    A d(residual) = d(F - M Phi a) - dA residual with dA = dK - sigma dM - dsigma M.
    """
    vectors, modal_forces = modes.vectors, modes.vectors.T @ system.load
    load_tangent = (
        tangent.load
        - tangent.mass @ (vectors @ modal_forces)
        - system.mass @ (vector_tangent @ modal_forces + vectors @ force_tangent)
    )
    operator_tangent = tangent.stiffness @ residual - modes.shift * (tangent.mass @ residual)
    return load_tangent - operator_tangent + tangent.shift * (system.mass @ residual)


def evaluate_fem_with_tangents(
    plate: Plate,
    q: float,
    voltage: float,
    settings: FemSettings | FemAccuracy = FemAccuracy(),
    parameters: Iterable[str] = DESIGN_PARAMETERS,
    n_blocks: int = KRYLOV_BLOCKS,
) -> FemResult:
    """:func:`~workflow.models.fem.evaluate_fem` and the derivatives of its probe model, from one eigen-solve.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    q : float
        Quality factor [-].
    voltage : float
        Drive amplitude [V].
    settings : FemSettings or FemAccuracy
        A fixed mesh, or an accuracy: the mesh is chosen by :func:`evaluate_fem` (whose error
        estimate the result keeps) and the tangents are computed on it.
    parameters : iterable of str
        Plate fields to differentiate (lengths [m]); default lambda and h_i.
    n_blocks : int
        Krylov blocks of the eigenvector derivatives' complement solve [-].

    Returns
    -------
    FemResult
        The same numbers as ``evaluate_fem``, with ``tangents`` {parameter: d probe_model / d parameter}.
    """
    settings, error = settings.resolved(plate, lambda asked=settings: evaluate_fem(plate, q, voltage, asked))
    mesh, system, probes = discretise(plate, voltage, settings)
    modes = working_modes(plate, system, settings)
    parameters = tuple(parameters)
    system_tangents = [system_tangent(plate, name, voltage, settings, mesh) for name in parameters]
    tangents = probe_model_tangents(system, modes, probes, system_tangents, n_blocks)
    result = fem_result(probe_modal_model(system, modes, probes), q, voltage, system, dict(zip(parameters, tangents)))
    return result if error is None else replace(result, error=error)


def gradient(function: Callable, model, tangents: Iterable, step: float = DIRECTIONAL_STEP) -> np.ndarray:
    """Derivatives of ``function(model)`` along each tangent by central differences in the reduced space.

    Parameters
    ----------
    function : callable
        model -> float or array.
    model : ProbeModalModel or FemResult
        Anything with ``moved(tangent, step)``.
    tangents : iterable of ProbeModalModel
        d probe_model / d p for each parameter p.
    step : float
        Step of each parameter [m].

    Returns
    -------
    array
        Shape (n_tangents,) + shape of the function's value [unit of the function per m].
    """
    return np.array(
        [
            (np.asarray(function(model.moved(tangent, step))) - function(model.moved(tangent, -step))) / (2 * step)
            for tangent in tangents
        ]
    )


def result_gradient(function: Callable, result: FemResult, step: float = DIRECTIONAL_STEP) -> np.ndarray:
    """Gradient of a function of a FEM result over its tangents' parameters, shape (n_parameters,) + value shape.

    The best mode's index is held fixed; the modes are re-driven at the result's Q.
    """
    if result.tangents is None:
        raise TactileError("this FEM result has no tangents; evaluate it with evaluate_fem_with_tangents")
    return gradient(function, result, result.tangents.values(), step)


def best_mode_gradients(result: FemResult, q=None):
    """Gradients of the best mode's frequency and deflection over the result's tangent parameters.

    Parameters
    ----------
    result : FemResult
        With tangents (default parameters: (lambda, h_i)).
    q : float or array, optional
        Quality factor of the deflection (``FemResult.deflection_at_q``) [-]; default the result's own Q.

    Returns
    -------
    frequency_gradient : (n_parameters,) array
        [Hz/m].
    deflection_gradient : (n_parameters,) + shape of q array
        [m/m].
    """
    q = result.q if q is None else q
    frequency = result_gradient(lambda moved: moved.frequency, result)
    deflection = result_gradient(lambda moved: moved.deflection_at_q(q), result)
    return frequency, deflection
