"""The FEM cost function: modes near the beam resonance and their driven deflection (docs/fem.md)."""

from dataclasses import dataclass, replace

import numpy as np

from workflow.errors import TactileError
from workflow.models import analytical
from workflow.models.fem.accuracy import ErrorEstimate, FemAccuracy, evaluate_to_accuracy
from workflow.models.fem.assembly import PlateSystem, assemble_system
from workflow.models.fem.harmonic import ProbeModalModel, probe_modal_model
from workflow.models.fem.mesh import quarter_plate_mesh
from workflow.models.fem.modes import ShiftedModes, nearest_modes
from workflow.models.fem.probes import (
    antinode_probe_points,
    mean_deflection,
    probe_matrix,
    transverse_indicator,
)
from workflow.models.fem.settings import FemSettings
from workflow.models.plate import Plate


@dataclass(frozen=True)
class ModeResult:
    """One eigenmode and the plate's response when driven at its frequency.

    Attributes
    ----------
    frequency : float
        Eigenfrequency [Hz].
    deflection : float
        Mean |w| over the 44 antinode probes when driven at ``frequency`` [m].
    transverse_indicator : float
        Share of the variance of the mode's w along y at the antinode lines [-] (0: longitudinal).
    """

    frequency: float
    deflection: float
    transverse_indicator: float


@dataclass(frozen=True, eq=False)
class FemResult:
    """All evaluated modes of one plate, the best one and the modal data behind them.

    Attributes
    ----------
    modes : tuple of ModeResult
        Ascending in frequency.
    best_index : int
        Index of the mode with the largest deflection.
    probe_model : ProbeModalModel
        Modal data at the probes, for responses at other frequencies and Q without a new solve.
    voltage : float
        Drive amplitude across each ceramic [V].
    n_dofs : int
        Free degrees of freedom of the quarter model [-].
    q : float or None
        Quality factor the modes were driven with [-] (None in results older than this field).
    tangents : dict or None
        Design parameter name (a :class:`~workflow.models.plate.Plate` field) -> derivative of
        ``probe_model`` with respect to it (a :class:`ProbeModalModel` whose fields hold the
        derivatives, per metre), from :func:`workflow.models.fem.sensitivity.evaluate_fem_with_tangents`;
        None when not computed.
    error : ErrorEstimate or None
        Estimated discretisation error of the best mode (evaluations to an accuracy); None on a fixed mesh.
    """

    modes: tuple
    best_index: int
    probe_model: ProbeModalModel
    voltage: float
    n_dofs: int
    q: float | None = None
    tangents: dict[str, ProbeModalModel] | None = None
    error: ErrorEstimate | None = None

    @property
    def best(self) -> ModeResult:
        return self.modes[self.best_index]

    @property
    def frequency(self) -> float:
        """Frequency of the best mode [Hz]."""
        return self.best.frequency

    @property
    def deflection(self) -> float:
        """Deflection of the best mode [m]."""
        return self.best.deflection

    def deflection_at_q(self, q):
        """Best mode's mean probe deflection at its frequency for other quality factors [m] (vectorised)."""
        return mean_deflection(self.probe_model.response(self.frequency, q))

    def moved(self, tangent: ProbeModalModel, step: float) -> "FemResult":
        """The result with its probe model a step along a tangent, the best mode's index kept.

        The modes are re-evaluated from the moved probe model at the result's Q, so any
        function of a result (frequency, deflection, ``deflection_at_q``...) can be
        differentiated along the tangent without a new solve.

        Parameters
        ----------
        tangent : ProbeModalModel
            Derivative of ``probe_model`` with respect to a design parameter p [per unit of p].
        step : float
            Change of p [unit of p].
        """
        if self.q is None:
            raise TactileError("this FEM result does not record its Q; evaluate it again to move it")
        probe_model = self.probe_model.moved(tangent, step)
        return replace(self, modes=mode_results(probe_model, self.q), probe_model=probe_model, tangents=None)

    def to_dict(self) -> dict:
        """Plain-data form (JSON-able), inverse of :meth:`from_dict`."""
        data = {
            "modes": [vars(mode) for mode in self.modes],
            "best_index": self.best_index,
            "probe_model": self.probe_model.to_dict(),
            "voltage": self.voltage,
            "n_dofs": self.n_dofs,
            "q": self.q,
        }
        if self.tangents is not None:
            data["tangents"] = {name: tangent.to_dict() for name, tangent in self.tangents.items()}
        if self.error is not None:
            data["error"] = self.error.to_dict()
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "FemResult":
        tangents, error = data.get("tangents"), data.get("error")
        return cls(
            modes=tuple(ModeResult(**mode) for mode in data["modes"]),
            best_index=int(data["best_index"]),
            probe_model=ProbeModalModel.from_dict(data["probe_model"]),
            voltage=float(data["voltage"]),
            n_dofs=int(data["n_dofs"]),
            q=None if data.get("q") is None else float(data["q"]),
            tangents=None if tangents is None else {k: ProbeModalModel.from_dict(v) for k, v in tangents.items()},
            error=None if error is None else ErrorEstimate.from_dict(error),
        )


def mode_results(probe_model: ProbeModalModel, q: float) -> tuple:
    """A :class:`ModeResult` per mode, driven at its own frequency with quality factor ``q``."""
    frequencies = probe_model.frequencies
    deflections = mean_deflection(probe_model.response(frequencies, q))
    indicators = transverse_indicator(probe_model.probe_shapes.T)
    return tuple(ModeResult(float(f), float(w), float(t)) for f, w, t in zip(frequencies, deflections, indicators))


def evaluate_fem(plate: Plate, q: float, voltage: float, settings: FemSettings | FemAccuracy = FemAccuracy()) -> FemResult:
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
        frequency error meets it; the result carries its ``error``), or a fixed mesh.
    """
    if isinstance(settings, FemAccuracy):
        return evaluate_to_accuracy(plate, settings, lambda mesh: evaluate_fem(plate, q, voltage, mesh))
    _, system, probes = discretise(plate, voltage, settings)
    modes = working_modes(plate, system, settings)
    return fem_result(probe_modal_model(system, modes, probes), q, voltage, system)


def working_modes(plate: Plate, system: PlateSystem, settings: FemSettings) -> ShiftedModes:
    """The ``settings.n_modes`` modes nearest the analytical beam resonance of the plate."""
    return nearest_modes(system, float(analytical.resonance_frequency(plate)), settings.n_modes)


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


def fem_result(probe_model: ProbeModalModel, q: float, voltage: float, system: PlateSystem, tangents=None) -> FemResult:
    """The result of a probe model: its modes driven at Q ``q`` and the best of them.

    Parameters
    ----------
    probe_model : ProbeModalModel
    q : float
        Quality factor [-].
    voltage : float
        Drive amplitude [V].
    system : PlateSystem
        The system the model was computed from (for its size).
    tangents : dict, optional
        See :attr:`FemResult.tangents`.
    """
    results = mode_results(probe_model, q)
    best = int(np.argmax([mode.deflection for mode in results]))
    n_dofs = int(system.stiffness.shape[0])
    return FemResult(results, best, probe_model, float(voltage), n_dofs, float(q), tangents)
