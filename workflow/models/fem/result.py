"""What an FEM evaluation returns: the modes of a plate, the best of them and the modal data behind them.

Shared by the eigenstrain (:mod:`workflow.models.fem.evaluate`) and coupled (:mod:`workflow.models.fem.piezoelectric`)
models, so neither imports the other's module for its result type.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from workflow.errors import TactileError
from workflow.models.fem.accuracy import ErrorEstimate
from workflow.models.fem.assembly import PlateSystem
from workflow.models.fem.harmonic import ModalSolution, ProbeModalModel
from workflow.models.fem.probes import mean_deflection, transverse_indicator

QUARTERS = 4
"""The model is a quarter of the plate; charges and capacitances are reported for the whole plate."""


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
    antiresonances : tuple of float or None
        Coupled model (:mod:`workflow.models.fem.piezoelectric`): the open-circuit frequency of each
        mode, whose ``frequency`` is then the short-circuit resonance [Hz]; None for the eigenstrain model.
    clamped_capacitance : float or None
        Coupled model: capacitance of the driven electrodes of the whole plate with u = 0, C_S [F].
    charge_residual : float or None
        Coupled model: charge per volt of the whole plate from the modes not computed [F].
    solution : ModalSolution or None
        The modes on every dof of their mesh, kept in memory only (never saved or sent: :meth:`stripped`), to
        start the next level's eigen solve and to sample the top face; None otherwise.
    """

    modes: tuple
    best_index: int
    probe_model: ProbeModalModel
    voltage: float
    n_dofs: int
    q: float | None = None
    tangents: dict[str, ProbeModalModel] | None = None
    error: ErrorEstimate | None = None
    antiresonances: tuple | None = None
    clamped_capacitance: float | None = None
    charge_residual: float | None = None
    solution: ModalSolution | None = field(default=None, repr=False)

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

    @property
    def antiresonance(self) -> float:
        """Open-circuit frequency of the best mode [Hz] (coupled model only)."""
        return self.antiresonances[self.best_index]

    @property
    def coupling_factor(self) -> float:
        """Effective coupling of the best mode, k_eff = sqrt((f_a^2 - f_r^2) / f_a^2) [-] (coupled model only)."""
        return float(np.sqrt(1 - (self.frequency / self.antiresonance) ** 2))

    def admittance(self, frequencies, q=None) -> np.ndarray:
        """Electrical admittance of the whole plate, Y = i omega Q_e / V [S] (coupled model only).

        Q_e / V = C_S + sum_m Gamma_m^2 / (omega_m^2 (1 + i/Q) - omega^2) + the other modes' charge,
        with Gamma_m = phi_m . Gamma the modal force per volt.

        Parameters
        ----------
        frequencies : float or array
            Drive frequency [Hz].
        q : float, optional
            Quality factor, structural loss 1/Q [-]; the result's own Q by default.
        """
        if self.antiresonances is None:
            raise TactileError("the admittance needs the coupled piezoelectric model (this result is the eigenstrain one)")
        q = self.q if q is None else q
        omega = 2 * np.pi * np.asarray(frequencies, dtype=float)
        model = self.probe_model
        per_volt = QUARTERS * (model.modal_forces / self.voltage) ** 2  # modal charges per volt, whole plate
        dynamic = per_volt / (model.eigenvalues * (1 + 1j / q) - omega[..., None] ** 2)
        return 1j * omega * (self.clamped_capacitance + self.charge_residual + dynamic.sum(axis=-1))

    def stripped(self) -> "FemResult":
        """The result without its in-memory :attr:`solution` (what is cached and sent between processes)."""
        return replace(self, solution=None) if self.solution is not None else self

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
        if self.antiresonances is not None:
            data["antiresonances"] = [None if np.isnan(f) else f for f in self.antiresonances]
            data["clamped_capacitance"] = self.clamped_capacitance
            data["charge_residual"] = self.charge_residual
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
            antiresonances=None
            if data.get("antiresonances") is None
            else tuple(np.nan if f is None else float(f) for f in data["antiresonances"]),
            clamped_capacitance=data.get("clamped_capacitance"),
            charge_residual=data.get("charge_residual"),
        )


def mode_results(probe_model: ProbeModalModel, q: float) -> tuple:
    """A :class:`ModeResult` per mode, driven at its own frequency with quality factor ``q``."""
    frequencies = probe_model.frequencies
    deflections = mean_deflection(probe_model.response(frequencies, q))
    indicators = transverse_indicator(probe_model.probe_shapes.T)
    return tuple(ModeResult(float(f), float(w), float(t)) for f, w, t in zip(frequencies, deflections, indicators))


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
