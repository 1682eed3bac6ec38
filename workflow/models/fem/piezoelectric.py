"""Coupled piezoelectric FEM: the electric potential as an unknown on the ceramics (docs/fem.md).

Each ceramic carries the potential phi on its nodes (quadratic, like u) with the stress-charge law
sigma = c^E eps - e^T E, D = e eps + eps^S E, E = -grad phi, e signed by the ceramic's poling.
Its face z = 0 is the driven electrode, its face bonded to the resonator the grounded one; the
driven electrodes of all ceramics are wired together (one conductor, potential V), so with the
alternate poling they pump the same standing wave as the eigenstrain model.

With phi_I the potentials inside the ceramics (neither electrode), the equations are

    [K_uu  K_uI ] [u    ]   [-k_uH V]          Q = k_HH V + k_HI phi_I - k_Hu u
    [K_Iu -K_II ] [phi_I] = [ k_IH V],

Q being the charge on the driven electrodes.  Eliminating phi_I gives the short-circuit stiffness
K_sc = K_uu + K_uI K_II^-1 K_Iu, the drive K_sc u = Gamma V and the charge Q = C_S V + Gamma^T u,
with Gamma = K_uI K_II^-1 k_IH - k_uH [N/V] and C_S = k_HH - k_IH^T K_II^-1 k_IH the clamped
capacitance [F].  The modes at short circuit (V = 0) are the resonances, computed by shift-invert
on one factorisation of the saddle-point matrix [[K_uu - sigma M, K_uI], [K_Iu, -K_II]] (its
u-part solve is (K_sc - sigma M)^-1).  The antiresonances are the open-circuit modes (driven
electrodes floating, Q = 0), K_oc = K_sc + Gamma Gamma^T / C_S: the zeros of Q / V between
resonances, found from the modal charges; :func:`open_circuit_modes` solves K_oc exactly (the
same factorisation with a rank-one correction) to check them.
"""

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.optimize import brentq

from workflow.models import analytical
from workflow.models.fem.assembly import PlateSystem, assemble_system, element_dofs, reduce_system
from workflow.models.fem.harmonic import ModalSolution, modal_solution
from workflow.models.fem.mesh import CERAMIC, BrickMesh, quarter_plate_mesh
from workflow.models.fem.modes import ShiftedModes, shift_invert_modes
from workflow.models.fem.probes import antinode_probe_points, probe_matrix
from workflow.models.fem.prolongation import start_block
from workflow.models.fem.result import QUARTERS, FemResult, fem_result
from workflow.models.fem.solvers import factorise
from workflow.models.fem.structures import shared_block_matrix
from workflow.models.fem.settings import DEFAULT_SETTINGS, FemSettings
from workflow.models.materials import PiezoMaterial
from workflow.models.plate import Plate

@dataclass(frozen=True, eq=False)
class PiezoSystem:
    """The electromechanical system on the free displacements and the inner potentials.

    Attributes
    ----------
    mechanical : PlateSystem
        K_uu (short-circuit elastic stiffness c^E) and M on the free displacement dofs, with the
        voltage drive Gamma V as its load [N].
    coupling : scipy.sparse.csc_matrix
        K_uI, shape (n_u, n_I) [C/m].
    permittivity : scipy.sparse.csc_matrix
        K_II, shape (n_I, n_I) [F].
    drive : (n_u,) array
        Gamma, the force per volt on the driven electrodes [N/V].
    clamped_capacitance : float
        C_S of the modelled part (u held at 0) [F].
    """

    mechanical: PlateSystem
    coupling: sp.csc_matrix
    permittivity: sp.csc_matrix
    drive: np.ndarray
    clamped_capacitance: float


@dataclass(frozen=True, eq=False)
class CoupledModes:
    """Short-circuit modes near a shift and what the driven electrodes see of them.

    Attributes
    ----------
    short_circuit : ShiftedModes
        Resonances (both electrodes grounded); its solver is (K_sc - sigma M)^-1.
    modal_drive : (n_modes,) array
        Gamma_m = phi_m . Gamma, force per volt of each mode; also its charge per unit modal amplitude
        [N/V kg^-1/2].
    charge_residual : float
        Charge per volt of all other modes, Gamma^T (K_sc - sigma M)^-1 Gamma minus the computed
        modes' part [F].
    clamped_capacitance : float
        C_S [F].
    solve_open : callable
        b -> (K_oc - sigma M)^-1 b, the same factorisation with the open-circuit rank-one correction.
    """

    short_circuit: ShiftedModes
    modal_drive: np.ndarray
    charge_residual: float
    clamped_capacitance: float
    solve_open: object

    def charge_per_volt(self, omega2) -> np.ndarray:
        """Lossless Q_e / V = C_S + residual + sum_m Gamma_m^2 / (omega_m^2 - omega^2) [F]."""
        omega2 = np.asarray(omega2, dtype=float)
        poles = self.modal_drive**2 / (self.short_circuit.eigenvalues - omega2[..., None])
        return self.clamped_capacitance + self.charge_residual + poles.sum(axis=-1)

    def antiresonance_eigenvalues(self) -> np.ndarray:
        """omega_a^2 of each mode: the zero of Q_e / V above its resonance (Q_e = 0: open circuit) [rad^2/s^2].

        Q_e / V increases with omega^2 between resonances, so it has one zero between a resonance
        and the next (none, NaN, above the last if C_S + residual <= 0 there); a mode without charge
        keeps its resonance.
        """
        eigenvalues = self.short_circuit.eigenvalues
        uppers = np.append(eigenvalues[1:], 4 * eigenvalues[-1])
        zeros = np.empty(len(eigenvalues))
        for index, (low, high) in enumerate(zip(eigenvalues, uppers)):
            low, high = low * (1 + 1e-12), high * (1 - 1e-12)
            if self.charge_per_volt(low) >= 0:
                zeros[index] = eigenvalues[index]
            elif self.charge_per_volt(high) <= 0:
                zeros[index] = np.nan
            else:
                zeros[index] = brentq(self.charge_per_volt, low, high, xtol=1e-12 * low, rtol=1e-14)
        return zeros


def electrode_nodes(mesh: BrickMesh):
    """Nodes of the ceramics: driven electrode (z = 0), grounded electrode (top face), inner ones.

    Returns
    -------
    driven, grounded, inner : int arrays
        Node numbers.
    """
    nodes = np.unique(mesh.connectivity[mesh.material == CERAMIC])
    z = mesh.coordinates[nodes, 2]
    tolerance = 1e-9 * (z.max() - z.min())
    driven = z <= z.min() + tolerance
    grounded = z >= z.max() - tolerance
    return nodes[driven], nodes[grounded], nodes[~driven & ~grounded]


def assemble_piezo_matrices(mesh: BrickMesh, ceramic: PiezoMaterial):
    """K_u phi [C/m] and K_phi phi [F] on all dofs and nodes, e signed by each ceramic's poling.

    Returns
    -------
    coupling : scipy.sparse.csr_matrix
        Shape (n_dofs, n_nodes).
    permittivity : scipy.sparse.csr_matrix
        Shape (n_nodes, n_nodes).
    """
    cells = mesh.material == CERAMIC
    sizes = mesh.sizes[cells]
    coupling = mesh.brick.box_piezo_coupling(sizes, ceramic.piezo_matrix()) * mesh.polarity[cells, None, None]
    permittivity = mesh.brick.box_permittivity(sizes, ceramic.permittivity_matrix())
    dofs, nodes = element_dofs(mesh)[cells], mesh.connectivity[cells]
    n_local = nodes.shape[1]
    coupling_matrix = sp.coo_matrix(
        (coupling.ravel(), (np.repeat(dofs, n_local, axis=1).ravel(), np.tile(nodes, (1, dofs.shape[1])).ravel())),
        shape=(mesh.n_dofs, mesh.n_nodes),
    )
    permittivity_matrix = sp.coo_matrix(
        (permittivity.ravel(), (np.repeat(nodes, n_local, axis=1).ravel(), np.tile(nodes, (1, n_local)).ravel())),
        shape=(mesh.n_nodes, mesh.n_nodes),
    )
    return coupling_matrix.tocsr(), permittivity_matrix.tocsr()


def assemble_piezo_system(mesh: BrickMesh, stiffness, mass, ceramic: PiezoMaterial, voltage: float) -> PiezoSystem:
    """The electromechanical system of a mesh whose CERAMIC elements are ``ceramic``.

    Parameters
    ----------
    mesh : BrickMesh
    stiffness, mass : sparse matrices
        K_uu [N/m] and M [kg] on all dofs (c^E for the ceramics).
    ceramic : PiezoMaterial
    voltage : float
        Drive amplitude across each ceramic [V].
    """
    mechanical = reduce_system(mesh, stiffness, mass, np.zeros(stiffness.shape[0]))
    return electromechanical_system(mesh, mechanical, ceramic, voltage)


def electromechanical_system(mesh: BrickMesh, mechanical: PlateSystem, ceramic: PiezoMaterial, voltage: float) -> PiezoSystem:
    """The electromechanical system on a reduced mechanical one (its load is replaced by the voltage drive).

    Parameters
    ----------
    mesh : BrickMesh
    mechanical : PlateSystem
        K_uu (c^E for the ceramics) and M on the free dofs.
    ceramic : PiezoMaterial
    voltage : float
        Drive amplitude across each ceramic [V].
    """
    coupling, permittivity = assemble_piezo_matrices(mesh, ceramic)
    driven, _, inner = electrode_nodes(mesh)
    coupling = coupling[mechanical.free_dofs]
    coupling_inner = coupling[:, inner].tocsc()
    permittivity_inner = permittivity[inner][:, inner].tocsc()
    coupling_driven = np.asarray(coupling[:, driven].sum(axis=1)).ravel()
    permittivity_inner_driven = np.asarray(permittivity[inner][:, driven].sum(axis=1)).ravel()
    inner_potential = factorise(permittivity_inner).solve(permittivity_inner_driven)  # K_II^-1 k_IH
    drive = coupling_inner @ inner_potential - coupling_driven
    capacitance = float(permittivity[driven][:, driven].sum() - permittivity_inner_driven @ inner_potential)
    return PiezoSystem(replace(mechanical, load=drive * voltage), coupling_inner, permittivity_inner, drive, capacitance)


def coupled_modes(system: PiezoSystem, frequency: float, n_modes: int, start: np.ndarray | None = None) -> CoupledModes:
    """Short-circuit modes nearest ``frequency`` [Hz] and their charges, from one saddle-point factorisation
    (``start``: the lower level's modes, :func:`~workflow.models.fem.prolongation.start_block`)."""
    mechanical = system.mechanical
    shift = (2 * np.pi * frequency) ** 2
    n_u = mechanical.stiffness.shape[0]
    # a symmetric scaling of the potentials brings both blocks to one magnitude (exact: only u is read)
    scale = np.sqrt(np.abs(mechanical.stiffness.diagonal()).mean() / np.abs(system.permittivity.diagonal()).mean())
    saddle = shared_block_matrix(
        [
            [mechanical.shifted(shift), scale * system.coupling],
            [scale * system.coupling.T, -(scale**2) * system.permittivity],
        ]
    )
    factor = factorise(saddle)
    n_potentials = saddle.shape[0] - n_u

    def solve_short(rhs):
        return factor.solve(np.concatenate([rhs, np.zeros((n_potentials,) + rhs.shape[1:])]))[:n_u]

    response = solve_short(system.drive)  # (K_sc - sigma M)^-1 Gamma
    static_charge = system.drive @ response

    def solve_open(rhs):
        solution = solve_short(rhs)
        return solution - response * (system.drive @ solution) / (system.clamped_capacitance + static_charge)

    short = shift_invert_modes(mechanical, shift, solve_short, n_modes, start)
    modal_drive = short.vectors.T @ system.drive
    residual = static_charge - np.sum(modal_drive**2 / (short.eigenvalues - shift))
    return CoupledModes(short, modal_drive, float(residual), system.clamped_capacitance, solve_open)


def open_circuit_modes(system: PiezoSystem, modes: CoupledModes, n_modes: int) -> ShiftedModes:
    """The open-circuit modes (driven electrodes floating, no net charge) nearest the same shift.

    An eigen solve of K_oc = K_sc + Gamma Gamma^T / C_S on the factorisation of :func:`coupled_modes`:
    the exact antiresonances of the discrete model, against which the zeros of the charge of
    :meth:`CoupledModes.antiresonance_eigenvalues` (modal, with a quasi-static residual) are checked.
    """
    return shift_invert_modes(system.mechanical, modes.short_circuit.shift, modes.solve_open, n_modes)


def evaluate_fem_coupled(
    plate: Plate, q: float, voltage: float, settings: FemSettings = DEFAULT_SETTINGS, start: ModalSolution | None = None
) -> FemResult:
    """Evaluate the coupled piezoelectric quarter-plate FEM: resonances, antiresonances, deflections.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m]; its ceramic's full constants are used.
    q : float
        Plate quality factor, structural loss factor 1/Q [-].
    voltage : float
        Drive amplitude across each ceramic [V].
    settings : FemSettings
        Mesh resolution and number of modes.
    start : ModalSolution, optional
        Short-circuit modes of the same cells at a lower degree, to start the eigen solve.

    Returns
    -------
    FemResult
        Modes at short circuit (resonances) driven by the voltage, with the antiresonance of each,
        the clamped capacitance and the charge residual of the whole plate (for the admittance).
    """
    mesh = quarter_plate_mesh(plate, settings)
    system = electromechanical_system(mesh, assemble_system(mesh, plate, voltage), plate.ceramic, voltage)
    free = system.mechanical.free_dofs
    modes = coupled_modes(system, float(analytical.resonance_frequency(plate)), settings.n_modes,
                          start_block(start, mesh, free))
    probes = probe_matrix(mesh, antinode_probe_points(plate))[:, free]
    solution = modal_solution(mesh, system.mechanical, modes.short_circuit)
    result = fem_result(solution.probe_model(probes), q, voltage, system.mechanical)
    return replace(
        result,
        solution=solution,
        antiresonances=tuple(float(f) for f in np.sqrt(modes.antiresonance_eigenvalues()) / (2 * np.pi)),
        clamped_capacitance=QUARTERS * system.clamped_capacitance,
        charge_residual=QUARTERS * modes.charge_residual,
    )
