"""Eigenmodes nearest a target frequency by shift-invert Lanczos on one factorisation."""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
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
    returned even when the shift is low.  ``start``: the modes of a lower level
    (:func:`~workflow.models.fem.prolongation.start_block`), or ARPACK's first vector (default all ones).
    """
    shift = (2 * np.pi * frequency) ** 2
    factor = factorise(system.shifted(shift))
    return shift_invert_modes(system, shift, factor.solve, n_modes, start)


def shift_invert_modes(system: PlateSystem, shift: float, solve_shifted: Callable, n_modes: int,
                       start: np.ndarray | None = None) -> ShiftedModes:
    """The ``n_modes`` elastic eigenpairs nearest ``shift`` of the operator whose shifted inverse is given.

    From a block of start vectors (the lower level's modes), a block Krylov space of the shifted operator
    (:func:`block_krylov_modes`); from one vector or none, ARPACK's shift-invert Lanczos (also where the block
    method has not converged in :data:`MAX_BLOCKS` blocks).

    Parameters
    ----------
    system : PlateSystem
        For its mass matrix and free dofs (the stiffness is only reached through ``solve_shifted``).
    shift : float
        sigma [rad^2/s^2].
    solve_shifted : callable
        b -> (K - sigma M)^-1 b for the stiffness K whose modes are wanted; b a vector or an (n, k) block.
    n_modes : int
    start : array, optional
        (n_free,) ARPACK's first vector (default all ones), or (n_free, k) start block of the block method.
    """
    rigid = rigid_translation(system)
    rigid_mass = system.mass @ rigid

    def elastic(vectors):  # without the rigid translation: a vector or the columns of a block
        return vectors - np.multiply.outer(rigid, rigid_mass @ vectors)

    def solve_elastic(rhs):
        return elastic(solve_shifted(rhs))

    mass = system.mass.tocsc()
    mass_rows = sp.csr_matrix((mass.data, mass.indices, mass.indptr), shape=mass.shape)  # M = M^T: row-wise products are faster
    with threadpool_limits(limits=1, user_api="blas"):
        # the small dense steps of both methods only lose from threads on a shared machine (PARDISO's calls keep the
        # MKL threads of their analysis: workflow.models.fem.solvers)
        if start is not None and start.ndim == 2:
            found = block_krylov_modes(mass_rows, shift, solve_elastic, n_modes, elastic(start))
            if found is not None:
                return _mass_normalised(system, *found, shift, solve_shifted)
            start = start @ np.linspace(1.0, 2.0, start.shape[1])  # one vector in which no mode cancels
        operator = sla.LinearOperator(system.mass.shape, matvec=solve_elastic, dtype=float)
        start = np.ones(system.mass.shape[0]) if start is None else start
        # in shift-invert mode ARPACK uses only OPinv and M; the first argument gives shape and type
        eigenvalues, vectors = sla.eigsh(
            system.stiffness, k=n_modes, M=mass_rows, sigma=shift, which="LM", OPinv=operator, v0=start, tol=EIGEN_TOLERANCE
        )
    return _mass_normalised(system, eigenvalues, vectors, shift, solve_shifted)


def _mass_normalised(system: PlateSystem, eigenvalues, vectors, shift: float, solve_shifted: Callable) -> ShiftedModes:
    order = np.argsort(eigenvalues)
    vectors = vectors[:, order]
    vectors /= np.sqrt(np.einsum("im,im->m", vectors, system.mass @ vectors))
    return ShiftedModes(eigenvalues[order], vectors, shift, solve_shifted)


MAX_BLOCKS = 8
"""Most blocks of the block Krylov space before ARPACK takes over [-]."""
RESIDUAL_TOLERANCE = 1e-6
"""Relative residual ||T x - mu x||_M / |mu| at which a Ritz pair of the shifted operator T is converged [-]: its
eigenvalue is then exact to about the square, far below ARPACK's :data:`EIGEN_TOLERANCE`."""


def block_krylov_modes(mass, shift: float, solve_elastic: Callable, n_modes: int, start: np.ndarray):
    """(eigenvalues, vectors) of the ``n_modes`` pairs nearest ``shift`` by Rayleigh-Ritz on a block Krylov space,
    or None if they have not converged in :data:`MAX_BLOCKS` blocks.

    The space span{X, T X, T^2 X, ...} of T = (K - sigma M)^-1 M (the rigid translation projected out) is built
    one block at a time with a mass-orthonormal basis Q; as T Q is kept, the Ritz values mu of T (eigenvalues
    sigma + 1 / mu) and their residuals come without further solves.  One block solve costs about two single
    ones, and from the lower level's modes five to seven blocks reach the tolerance where ARPACK needs 20-30
    single solves (docs/fem.md, "Speed").

    Parameters
    ----------
    mass : sparse matrix
        M [kg].
    shift : float
        sigma [rad^2/s^2].
    solve_elastic : callable
        Block b -> (K - sigma M)^-1 b without the rigid translation.
    n_modes : int
    start : (n, k) array
        Start block, k >= n_modes, free of the rigid translation.
    """
    basis, mass_basis, images = [], [], []  # Q_j, M Q_j, T Q_j
    projected = np.zeros((0, 0))  # Q^T M T Q
    block = start
    for _ in range(MAX_BLOCKS):
        block, mass_block = mass_orthonormal(block, basis, mass_basis, mass, DEPENDENT)
        if block.shape[1] == 0:
            return None
        image = solve_elastic(mass_block)
        basis.append(block), mass_basis.append(mass_block), images.append(image)
        column = np.vstack([held.T @ image for held in mass_basis])  # (M Q)^T T Q_new; its transpose is the new row
        projected = np.block([[projected, column[:-block.shape[1]]], [column.T]])
        mu, ritz = la.eigh((projected + projected.T) / 2)
        wanted = np.argsort(-np.abs(mu))[:n_modes]
        mu, ritz = mu[wanted], ritz[:, wanted]
        vectors = np.hstack(basis) @ ritz
        residual = np.hstack(images) @ ritz - vectors * mu
        norms = np.sqrt(np.einsum("im,im->m", residual, mass @ residual))
        if len(mu) == n_modes and np.all(norms <= RESIDUAL_TOLERANCE * np.abs(mu)):
            return shift + 1 / mu, vectors
        block = image
    return None


def mass_orthonormal(block: np.ndarray, basis: list, mass_basis: list, mass, rtol: float) -> tuple:
    """(V, M V): ``block`` orthonormalised in the M inner product against the blocks of ``basis`` (``mass_basis``:
    their products with M; projected out twice) and within itself; directions whose M-norm falls below ``rtol``
    times the largest column's are dropped as dependent."""
    scale = np.sqrt(np.max(np.einsum("ik,ik->k", block, mass @ block), initial=0.0))
    for _ in range(2):
        for held, mass_held in zip(basis, mass_basis):
            block = block - held @ (mass_held.T @ block)
    mass_block = mass @ block
    values, vectors = la.eigh(block.T @ mass_block)
    kept = values > (rtol * scale) ** 2
    scaling = vectors[:, kept] / np.sqrt(values[kept])
    return block @ scaling, mass_block @ scaling


DEPENDENT = 1e-10
"""M-norm of a Krylov direction, relative to the block it comes from, below which it is dropped as dependent [-]
(far below :data:`RESIDUAL_TOLERANCE`, the size of the directions still needed)."""

