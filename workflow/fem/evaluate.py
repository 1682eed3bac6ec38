"""The FEM cost function: modes near the beam resonance and their driven deflection (SPEC section 4)."""

from dataclasses import dataclass

import numpy as np

from .. import analytical
from ..plate import Plate
from .assembly import assemble_system
from .harmonic import ProbeModalModel, probe_modal_model
from .mesh import quarter_plate_mesh
from .modes import nearest_modes
from .probes import (
    antinode_probe_points,
    mean_deflection,
    probe_matrix,
    transverse_indicator,
)
from .settings import DEFAULT_SETTINGS, FemSettings


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
    """

    modes: tuple
    best_index: int
    probe_model: ProbeModalModel
    voltage: float
    n_dofs: int

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

    def to_dict(self) -> dict:
        """Plain-data form (JSON-able), inverse of :meth:`from_dict`."""
        return {
            "modes": [vars(mode) for mode in self.modes],
            "best_index": self.best_index,
            "probe_model": self.probe_model.to_dict(),
            "voltage": self.voltage,
            "n_dofs": self.n_dofs,
        }

    @classmethod
    def from_dict(cls, data: dict) -> "FemResult":
        return cls(
            modes=tuple(ModeResult(**mode) for mode in data["modes"]),
            best_index=int(data["best_index"]),
            probe_model=ProbeModalModel.from_dict(data["probe_model"]),
            voltage=float(data["voltage"]),
            n_dofs=int(data["n_dofs"]),
        )


def mode_results(probe_model: ProbeModalModel, q: float) -> tuple:
    """A :class:`ModeResult` per mode, driven at its own frequency with quality factor ``q``."""
    frequencies = probe_model.frequencies
    deflections = mean_deflection(probe_model.response(frequencies, q))
    indicators = transverse_indicator(probe_model.probe_shapes.T)
    return tuple(ModeResult(float(f), float(w), float(t)) for f, w, t in zip(frequencies, deflections, indicators))


def evaluate_fem(plate: Plate, q: float, voltage: float, settings: FemSettings = DEFAULT_SETTINGS) -> FemResult:
    """Evaluate the quarter-plate FEM: modes nearest the beam resonance and their deflections.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    q : float
        Plate quality factor, structural loss factor 1/Q [-].
    voltage : float
        Drive amplitude across each ceramic [V].
    settings : FemSettings
        Mesh resolution and number of modes.
    """
    mesh = quarter_plate_mesh(plate, settings)
    system = assemble_system(mesh, plate, voltage)
    modes = nearest_modes(system, float(analytical.resonance_frequency(plate)), settings.n_modes)
    probes = probe_matrix(mesh, antinode_probe_points(plate))[:, system.free_dofs]
    probe_model = probe_modal_model(system, modes, probes)
    results = mode_results(probe_model, q)
    best = int(np.argmax([mode.deflection for mode in results]))
    return FemResult(results, best, probe_model, float(voltage), int(system.stiffness.shape[0]))
