"""The FEM cost function: modes near the beam resonance and their driven deflection (docs/fem.md)."""

from dataclasses import replace

from workflow.models import analytical
from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.fem.assembly import PlateSystem, assemble_system
from workflow.models.fem.harmonic import ModalSolution, modal_solution
from workflow.models.fem.mesh import quarter_plate_mesh
from workflow.models.fem.modes import ShiftedModes, nearest_modes
from workflow.models.fem.piezoelectric import evaluate_fem_coupled
from workflow.models.fem.prolongation import start_block
from workflow.models.fem.probes import antinode_probe_points, probe_matrix
from workflow.models.fem.result import FemResult, fem_result
from workflow.models.fem.settings import FemSettings
from workflow.models.plate import Plate


def evaluate_fem(plate: Plate, q: float, voltage: float, settings: FemSettings | FemAccuracy = FemAccuracy(),
                 start: ModalSolution | None = None) -> FemResult:
    """Evaluate the quarter-plate FEM: modes nearest the beam resonance and their deflections.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    q : float
        Plate quality factor, structural loss factor 1/Q [-].
    voltage : float
        Drive amplitude across each ceramic [V].
    settings : FemAccuracy or FemSettings
        A target accuracy (the mesh follows the geometry and is refined until the estimated
        frequency error meets it; the result carries its ``error``), or a fixed mesh; either
        names the piezo model (the coupled one adds antiresonances and the admittance).
    start : ModalSolution, optional
        Modes of the same cells at a lower degree, to start the eigen solve (fixed meshes only).

    Returns
    -------
    FemResult
        On a fixed mesh with its :attr:`~FemResult.solution`; to an accuracy without it.
    """
    return settings.evaluated(plate, lambda mesh, lower: evaluate_on_mesh(plate, q, voltage, mesh, lower), start)


def evaluate_on_mesh(plate: Plate, q: float, voltage: float, settings: FemSettings, start: ModalSolution | None = None
                     ) -> FemResult:
    """:func:`evaluate_fem` on a fixed mesh, with the piezo model the settings name."""
    if settings.piezo == "coupled":
        return evaluate_fem_coupled(plate, q, voltage, settings, start)
    mesh, system, probes = discretise(plate, voltage, settings)
    modes = working_modes(plate, system, settings, start_block(start, mesh, system.free_dofs))
    solution = modal_solution(mesh, system, modes)
    return replace(fem_result(solution.probe_model(probes), q, voltage, system), solution=solution)


def working_modes(plate: Plate, system: PlateSystem, settings: FemSettings, start=None) -> ShiftedModes:
    """The ``settings.n_modes`` modes nearest the analytical beam resonance of the plate (``start``: the lower level's
    modes, :func:`~workflow.models.fem.prolongation.start_block`)."""
    return nearest_modes(system, float(analytical.resonance_frequency(plate)), settings.n_modes, start)


def discretise(plate: Plate, voltage: float, settings: FemSettings):
    """The mesh, the reduced system K, M, F and the probe matrix on the free dofs of a plate.

    Returns
    -------
    mesh : BrickMesh
    system : PlateSystem
    probes : scipy.sparse.csr_matrix
        Interpolation of w at the 44 antinode probes, shape (44, n_free) [-].
    """
    mesh = quarter_plate_mesh(plate, settings)
    system = assemble_system(mesh, plate, voltage)
    probes = probe_matrix(mesh, antinode_probe_points(plate))[:, system.free_dofs]
    return mesh, system, probes
