"""The deflection over the whole top face: the FEM's modes on a grid, and the modal assurance criterion.

A deflection scan measures w over the plate; this module gives the FEM's prediction anywhere on
the top face.  The quarter model's modes are sampled on a regular grid of the quarter top face
(x in [0, L/2], y in [0, b/2]) and interpolated bilinearly; the model is symmetric in x and y,
so w(x, y) = w(|x|, |y|) over the whole plate (modes antisymmetric in x or y are not in the
model: the centred, symmetric drive does not excite them).  The response at a drive frequency
is the full modal superposition with the residual of the other modes
(:class:`~workflow.models.fem.harmonic.ProbeModalModel`), transverse modes included.
"""

import math
from dataclasses import dataclass, replace

import numpy as np

from workflow.models.fem.accuracy import FemAccuracy
from workflow.models.fem.evaluate import evaluate_on_mesh
from workflow.models.fem.result import FemResult
from workflow.models.fem.harmonic import ProbeModalModel
from workflow.models.fem.mesh import top_face
from workflow.models.fem.probes import probe_matrix
from workflow.models.fem.settings import FemSettings
from workflow.models.plate import Plate

GRID_POINTS_PER_WAVELENGTH = 32
"""Grid spacing along x: lambda / 32 (bilinear interpolation of a sinusoid then errs by < 0.5 %) [-]."""
GRID_POINTS_ACROSS_HALF_WIDTH = 25
"""Grid points along y over [0, b/2] [-]."""


@dataclass(frozen=True, eq=False)
class SurfaceModes:
    """The modes of a plate sampled on a grid of its quarter top face.

    Attributes
    ----------
    x, y : array
        Grid coordinates from the plate's centre, ascending from 0 to L/2 and b/2 [m].
    model : ProbeModalModel
        The modal data at the grid points, x-major (point i * len(y) + j is (x[i], y[j])).
    working_mode : int
        Index of the working mode (the FEM's best mode: largest mean deflection at the probes) [-].
    """

    x: np.ndarray
    y: np.ndarray
    model: ProbeModalModel
    working_mode: int

    @property
    def half_length(self) -> float:
        """L/2 [m]."""
        return float(self.x[-1])

    @property
    def half_width(self) -> float:
        """b/2 [m]."""
        return float(self.y[-1])

    def on_plate(self, x, y) -> np.ndarray:
        """Whether points (``x``, ``y``) [m] from the centre lie on the top face (edges included)."""
        tolerance = 1e-9
        return (np.abs(x) <= self.half_length + tolerance) & (np.abs(y) <= self.half_width + tolerance)

    def at(self, x, y) -> ProbeModalModel:
        """The modal data at points (``x``, ``y``) [m] from the centre (arrays of equal length), interpolated.

        Points off the plate are clipped to its edge; check :meth:`on_plate` first.
        """
        x = np.clip(np.abs(np.atleast_1d(np.asarray(x, dtype=float))), 0, self.half_length)
        y = np.clip(np.abs(np.atleast_1d(np.asarray(y, dtype=float))), 0, self.half_width)
        i, s = _cell(self.x, x)
        j, t = _cell(self.y, y)
        ny = len(self.y)
        corners = ((i, j, (1 - s) * (1 - t)), (i + 1, j, s * (1 - t)), (i, j + 1, (1 - s) * t), (i + 1, j + 1, s * t))
        shapes = sum(weight[:, None] * self.model.probe_shapes[a * ny + b] for a, b, weight in corners)
        residual = sum(weight * self.model.residual[a * ny + b] for a, b, weight in corners)
        return replace(self.model, probe_shapes=shapes, residual=residual)

    def deflection(self, x, y, frequency: float, q: float) -> np.ndarray:
        """Complex w [m] at points (``x``, ``y``) [m] when driven at ``frequency`` [Hz] with quality factor ``q`` [-]."""
        return self.at(x, y).response(frequency, q)

    def working_deflection(self, x, y, frequency: float, q: float) -> np.ndarray:
        """Complex w [m] of the working mode alone (no other mode, no residual) at points (``x``, ``y``) [m]."""
        model = self.at(x, y)
        m = self.working_mode
        omega2 = (2 * np.pi * frequency) ** 2
        coefficient = model.modal_forces[m] / (model.eigenvalues[m] * (1 + 1j / q) - omega2)
        return coefficient * model.probe_shapes[:, m]


def _cell(edges: np.ndarray, values: np.ndarray):
    """Grid cell index and the position in it, in [0, 1]."""
    index = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
    return index, (values - edges[index]) / (edges[index + 1] - edges[index])


def surface_grid(plate: Plate) -> tuple[np.ndarray, np.ndarray]:
    """The grid (x, y) [m] of the quarter top face of ``plate`` on which the modes are sampled."""
    half_length = float(plate.length) / 2
    nx = math.ceil(half_length / (float(plate.wavelength) / GRID_POINTS_PER_WAVELENGTH)) + 1
    return np.linspace(0.0, half_length, nx), np.linspace(0.0, float(plate.width) / 2, GRID_POINTS_ACROSS_HALF_WIDTH)


def evaluate_surface(plate: Plate, q: float, voltage: float, settings: FemSettings | FemAccuracy) -> tuple[FemResult, SurfaceModes]:
    """The FEM result of ``plate`` and its modes over the top face (eigenstrain drive).

    The surface is sampled from the modes of the evaluation itself (with an accuracy, of the level that met
    it: no further solve); the returned result is the evaluation, with its error estimate if it has one.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    q : float
        Quality factor [-].
    voltage : float
        Drive amplitude across each ceramic [V].
    settings : FemSettings or FemAccuracy
    """
    settings = replace(settings, piezo="eigenstrain")
    result = settings.evaluated(plate, lambda mesh, lower: evaluate_on_mesh(plate, q, voltage, mesh, lower),
                                keep_solution=True)
    solution = result.solution
    x, y = surface_grid(plate)
    xx, yy = np.meshgrid(x, y, indexing="ij")
    points = np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, top_face(plate))])
    grid = probe_matrix(solution.mesh, points)[:, solution.free_dofs]
    return result.stripped(), SurfaceModes(x, y, solution.probe_model(grid), result.best_index)


def modal_assurance_criterion(measured, predicted) -> float:
    """MAC = |a^H b|^2 / ((a^H a)(b^H b)) of two complex shapes sampled at the same points [-].

    1 for shapes equal up to a complex factor (amplitude and phase), 0 for orthogonal ones.
    """
    a = np.ravel(np.asarray(measured, dtype=complex))
    b = np.ravel(np.asarray(predicted, dtype=complex))
    return float(np.abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real))
