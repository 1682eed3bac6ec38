"""Eigenmodes nearest a target frequency by shift-invert Lanczos on one factorisation."""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from threadpoolctl import threadpool_limits

from workflow.models.fem.assembly import PlateSystem
from workflow.models.fem.solvers import factorise


@dataclass(frozen=True, eq=False)
class ShiftedModes:
    """Modes nearest the shift, mass-normalised, and the solver of (K - sigma M) x = b.

    Attributes
    ----------
    eigenvalues : array
        omega_m^2, ascending [rad^2/s^2].
    vectors : (n_free, n_modes) array
        Mass-normalised mode shapes [kg^-1/2].
    shift : float
        sigma = (2 pi f_shift)^2 [rad^2/s^2].
    solve_shifted : callable
        b -> (K - sigma M)^-1 b, reusing the factorisation.
    """

    eigenvalues: np.ndarray
    vectors: np.ndarray
    shift: float
    solve_shifted: Callable

    @property
    def frequencies(self) -> np.ndarray:
        """f_m = sqrt(omega_m^2) / (2 pi) [Hz]."""
        return np.sqrt(np.abs(self.eigenvalues)) / (2 * np.pi)


EIGEN_TOLERANCE = 1e-10
"""Relative accuracy asked of ARPACK's Ritz values (the frequencies come out ~1e-15 exact; 25 % fewer solves than 0)."""


def rigid_translation(system: PlateSystem) -> np.ndarray:
    """The free plate's one rigid-body motion left by the symmetry planes: unit-mass translation along z."""
    translation = np.zeros(system.stiffness.shape[0])
    translation[system.free_dofs % 3 == 2] = 1.0
    return translation / np.sqrt(translation @ (system.mass @ translation))


def nearest_modes(system: PlateSystem, frequency: float, n_modes: int, start: np.ndarray | None = None) -> ShiftedModes:
    """The ``n_modes`` elastic eigenpairs of K phi = omega^2 M phi with omega^2 nearest (2 pi frequency)^2.

    The rigid translation along z is projected out of the shift-invert operator, so it is never
    returned even when the shift is low.  ``start``: ARPACK's first vector (default all ones), e.g.
    the modes of a lower level (:func:`~workflow.models.fem.prolongation.start_vector`).
    """
    shift = (2 * np.pi * frequency) ** 2
    factor = factorise(system.shifted(shift))
    return shift_invert_modes(system, shift, factor.solve, n_modes, start)


def shift_invert_modes(system: PlateSystem, shift: float, solve_shifted: Callable, n_modes: int,
                       start: np.ndarray | None = None) -> ShiftedModes:
    """The ``n_modes`` elastic eigenpairs nearest ``shift`` of the operator whose shifted inverse is given.

    Parameters
    ----------
    system : PlateSystem
        For its mass matrix and free dofs (the stiffness is only reached through ``solve_shifted``).
    shift : float
        sigma [rad^2/s^2].
    solve_shifted : callable
        b -> (K - sigma M)^-1 b for the stiffness K whose modes are wanted.
    n_modes : int
    start : array, optional
        ARPACK's first vector (default all ones).
    """
    rigid = rigid_translation(system)
    rigid_mass = system.mass @ rigid

    def solve_elastic(rhs):
        solution = solve_shifted(rhs)
        return solution - rigid * (rigid_mass @ solution)

    operator = sla.LinearOperator(system.mass.shape, matvec=solve_elastic, dtype=float)
    start = np.ones(system.mass.shape[0]) if start is None else start
    mass = system.mass.tocsc()
    mass_rows = sp.csr_matrix((mass.data, mass.indices, mass.indptr), shape=mass.shape)  # M = M^T: row-wise products are faster
    with threadpool_limits(limits=1, user_api="blas"):
        # ARPACK's small dense steps only lose from threads; PARDISO's solves (MKL) with two threads are
        # not bitwise reproducible, and repeated evaluations of one plate must be equal
        # in shift-invert mode ARPACK uses only OPinv and M; the first argument gives shape and type
        eigenvalues, vectors = sla.eigsh(
            system.stiffness, k=n_modes, M=mass_rows, sigma=shift, which="LM", OPinv=operator, v0=start, tol=EIGEN_TOLERANCE
        )
    order = np.argsort(eigenvalues)
    vectors = vectors[:, order]
    vectors /= np.sqrt(np.einsum("im,im->m", vectors, system.mass @ vectors))
    return ShiftedModes(eigenvalues[order], vectors, shift, solve_shifted)
