"""Time-harmonic response at the probes by modal superposition with a shifted residual.

With structural damping (loss factor eta = 1/Q) the response at angular frequency omega is

    u = sum_j phi_j (phi_j . F) / (omega_j^2 (1 + i eta) - omega^2).

The computed modes are summed exactly; all other modes are far from resonance and enter
through the residual r = (K - sigma M)^-1 F - sum_m phi_m (phi_m . F) / (omega_m^2 - sigma),
computed once with the factorisation of the eigen solve (their damping and the small
difference between omega^2 and sigma are neglected there).
"""

from dataclasses import dataclass

import numpy as np

from workflow.models.fem.assembly import PlateSystem
from workflow.models.fem.mesh import BrickMesh
from workflow.models.fem.modes import ShiftedModes


@dataclass(frozen=True, eq=False)
class ProbeModalModel:
    """What the probes see of the modes: enough to evaluate the response at any f and Q.

    Attributes
    ----------
    eigenvalues : (n_modes,) array
        omega_m^2 [rad^2/s^2].
    modal_forces : (n_modes,) array
        phi_m . F [N kg^-1/2].
    probe_shapes : (n_probes, n_modes) array
        phi_m at the probes (w component) [kg^-1/2].
    residual : (n_probes,) array
        Deflection at the probes from all other modes [m].
    """

    eigenvalues: np.ndarray
    modal_forces: np.ndarray
    probe_shapes: np.ndarray
    residual: np.ndarray

    @property
    def frequencies(self) -> np.ndarray:
        """Modal frequencies [Hz]."""
        return np.sqrt(self.eigenvalues) / (2 * np.pi)

    def response(self, frequency, q) -> np.ndarray:
        """Complex w at the probes, shape broadcast(frequency, q) + (n_probes,) [m].

        Parameters
        ----------
        frequency : float or array
            Drive frequency [Hz].
        q : float or array
            Quality factor, loss factor 1/Q on the stiffness [-].
        """
        omega2 = (2 * np.pi * np.asarray(frequency, dtype=float))[..., None] ** 2
        loss = 1.0 / np.asarray(q, dtype=float)[..., None]
        coefficients = self.modal_forces / (self.eigenvalues * (1 + 1j * loss) - omega2)
        return coefficients @ self.probe_shapes.T + self.residual

    def moved(self, tangent: "ProbeModalModel", step: float) -> "ProbeModalModel":
        """The model a step along a tangent: every field x becomes x + step dx.

        Parameters
        ----------
        tangent : ProbeModalModel
            Derivative of each field with respect to a design parameter p (units of the field per
            unit of p; see :mod:`workflow.models.fem.sensitivity`).
        step : float
            Change of p [unit of p].
        """
        fields = self.__dataclass_fields__
        return type(self)(**{name: getattr(self, name) + step * getattr(tangent, name) for name in fields})

    def to_dict(self) -> dict:
        return {name: getattr(self, name).tolist() for name in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, data: dict) -> "ProbeModalModel":
        return cls(**{name: np.asarray(data[name], dtype=float) for name in cls.__dataclass_fields__})


@dataclass(frozen=True, eq=False)
class ModalSolution:
    """What the responses need, on every free dof of a mesh: sampled at any points without a new solve.

    Kept in memory only (:attr:`~workflow.models.fem.evaluate.FemResult.solution`), to sample the top face
    (:mod:`workflow.models.fem.surface`) and to start the eigen solve of the next level
    (:mod:`workflow.models.fem.prolongation`).

    Attributes
    ----------
    mesh : BrickMesh or None
        The mesh (None where only the projections are wanted).
    free_dofs : int array
        Global dof of each row of ``vectors`` and ``residual``.
    eigenvalues : (n_modes,) array
        omega_m^2 [rad^2/s^2].
    vectors : (n_free, n_modes) array
        Mass-normalised mode shapes [kg^-1/2].
    modal_forces : (n_modes,) array
        phi_m . F [N kg^-1/2].
    residual : (n_free,) array
        Displacement from all other modes [m] (:func:`shifted_residual`).
    """

    mesh: BrickMesh | None
    free_dofs: np.ndarray
    eigenvalues: np.ndarray
    vectors: np.ndarray
    modal_forces: np.ndarray
    residual: np.ndarray

    def probe_model(self, probes) -> "ProbeModalModel":
        """The modal data seen by ``probes``, a sparse interpolation on the free dofs (n_probes, n_free)."""
        return ProbeModalModel(
            eigenvalues=self.eigenvalues,
            modal_forces=self.modal_forces,
            probe_shapes=np.asarray(probes @ self.vectors),
            residual=np.asarray(probes @ self.residual),
        )


def modal_solution(mesh: BrickMesh | None, system: PlateSystem, modes: ShiftedModes) -> ModalSolution:
    """The modes of ``system`` on ``mesh`` with their forces and the residual of the others (one more solve)."""
    return ModalSolution(mesh, system.free_dofs, modes.eigenvalues, modes.vectors, modes.vectors.T @ system.load,
                         shifted_residual(system, modes))


def shifted_residual(system: PlateSystem, modes: ShiftedModes) -> np.ndarray:
    """(K - sigma M)^-1 F without the computed modes' part, on all free dofs [m]."""
    modal_forces = modes.vectors.T @ system.load
    return modes.solve_shifted(system.load) - modes.vectors @ (modal_forces / (modes.eigenvalues - modes.shift))


def probe_modal_model(system: PlateSystem, modes: ShiftedModes, probes) -> ProbeModalModel:
    """Project the modes, the load and the residual on the probes.

    Parameters
    ----------
    probes : sparse matrix
        Interpolation matrix on the free dofs, shape (n_probes, n_free).
    """
    return modal_solution(None, system, modes).probe_model(probes)
