"""Sparse direct factorisation of the shifted FEM matrices, with the fastest solver that is installed.

The shifted matrices K - sigma M are symmetric and indefinite.  PARDISO (Intel MKL, through the
``pypardiso`` package from PyPI, x86-64 only) factorises them as symmetric indefinite about 5-7 times
faster than SuperLU (scipy) on the plate's 10^4-10^5 dof systems (docs/fem.md, ``bench/bench_fem.py``);
SuperLU is the fallback wherever pypardiso does not install.  ``$TACTILE_SPARSE_SOLVER`` set to
``superlu`` or ``pardiso`` forces one (benchmarks, tests).
"""

import ctypes
import os
import weakref
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from workflow.errors import TactileError

SOLVER_VARIABLE = "TACTILE_SPARSE_SOLVER"
"""Environment variable that forces a solver: ``superlu`` or ``pardiso``."""

try:  # pragma: no cover - depends on the platform
    from pypardiso.pardiso_wrapper import PyPardisoSolver
except ImportError:  # pragma: no cover
    PyPardisoSolver = None

SYMMETRIC_INDEFINITE = -2
"""PARDISO matrix type of real symmetric indefinite matrices (upper triangle given)."""


def available_solvers() -> tuple:
    """Names of the installed solvers, fastest first."""
    return ("pardiso", "superlu") if PyPardisoSolver is not None else ("superlu",)


def solver_name() -> str:
    """The solver used: ``$TACTILE_SPARSE_SOLVER`` if set, else the fastest installed."""
    name = os.environ.get(SOLVER_VARIABLE, "").strip().lower() or available_solvers()[0]
    if name not in ("pardiso", "superlu"):
        raise TactileError(f"{SOLVER_VARIABLE}={name!r} is not a solver; use superlu or pardiso")
    if name not in available_solvers():
        raise TactileError(f"{SOLVER_VARIABLE}=pardiso but pypardiso is not installed; pip install pypardiso")
    return name


@lru_cache(maxsize=1)
def _mkl_pardiso():
    """MKL's ``pardiso`` with its argument types, found once (pypardiso searches the file system, ~0.1 s)."""
    return PyPardisoSolver()._mkl_pardiso


UPPER_STRUCTURES = 4
"""Upper-triangle selections kept, one per sparsity structure (the assembly shares its structures) [-]."""
_upper_structures: list = []


def _upper_selection(matrix: sp.csc_matrix):
    """(entries kept, CSR indices, CSR indptr) of the upper triangle of a canonical CSC structure, remembered for
    structures that are shared and read-only (those of :mod:`~workflow.models.fem.assembly`'s patterns)."""
    indptr, indices = matrix.indptr, matrix.indices
    for held_indptr, held_indices, selection in _upper_structures:
        if held_indptr() is indptr and held_indices() is indices:
            return selection
    rows = np.repeat(np.arange(matrix.shape[0], dtype=indices.dtype), np.diff(indptr))
    keep = np.flatnonzero(indices >= rows)
    upper_indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=matrix.shape[0]))])
    selection = (keep, indices[keep], upper_indptr)
    if not indices.flags.writeable and not indptr.flags.writeable:
        _upper_structures.insert(0, (weakref.ref(indptr), weakref.ref(indices), selection))
        del _upper_structures[UPPER_STRUCTURES:]
    return selection


def upper_triangle(matrix) -> sp.csr_matrix:
    """Upper triangle of a symmetric sparse matrix as CSR with sorted indices (its CSC structure read as CSR)."""
    matrix = sp.csc_matrix(matrix)
    if not matrix.has_canonical_format:
        matrix.sum_duplicates()
    keep, indices, indptr = _upper_selection(matrix)
    return sp.csr_matrix((matrix.data[keep], indices, indptr), shape=matrix.shape)


def _pardiso(handle, phase: int, matrix: tuple, iparm, rhs, solution) -> None:
    """One call of MKL's ``pardiso`` on a real symmetric indefinite matrix (1-based CSR upper triangle).

    Parameters
    ----------
    handle : (64,) int64 array
        PARDISO's internal pointer array of this factorisation.
    phase : int
        12 analysis and factorisation, 33 solve, -1 release.
    matrix : tuple
        (size, data, ia, ja) of the upper triangle.
    iparm : (64,) int32 array
    rhs, solution : float arrays
        Fortran-ordered, shape (size,) or (size, k).
    """
    size, data, ia, ja = matrix
    error = ctypes.c_int32(0)
    int_pointer, float_pointer = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
    _mkl_pardiso()(
        handle.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
        ctypes.byref(ctypes.c_int32(1)),  # maxfct
        ctypes.byref(ctypes.c_int32(1)),  # mnum
        ctypes.byref(ctypes.c_int32(SYMMETRIC_INDEFINITE)),
        ctypes.byref(ctypes.c_int32(phase)),
        ctypes.byref(ctypes.c_int32(size)),
        data.ctypes.data_as(float_pointer),
        ia.ctypes.data_as(int_pointer),
        ja.ctypes.data_as(int_pointer),
        np.zeros(0, dtype=np.int32).ctypes.data_as(int_pointer),  # perm: PARDISO's own ordering
        ctypes.byref(ctypes.c_int32(1 if rhs.ndim == 1 else rhs.shape[1])),
        iparm.ctypes.data_as(int_pointer),
        ctypes.byref(ctypes.c_int32(0)),  # no messages
        rhs.ctypes.data_as(float_pointer),
        solution.ctypes.data_as(float_pointer),
        ctypes.byref(error),
    )
    if error.value != 0:
        raise TactileError(f"PARDISO phase {phase} failed with error {error.value}; set {SOLVER_VARIABLE}=superlu")


class _Pardiso:
    """A PARDISO factorisation of a symmetric matrix kept for repeated solves (MKL called directly).

    PARDISO's defaults, but without iterative refinement in the solves: residuals stay ~1e-12 and a
    solve costs a third.
    """

    def __init__(self, matrix):
        upper = upper_triangle(matrix)
        self._matrix = (
            upper.shape[0],
            np.ascontiguousarray(upper.data, dtype=float),
            upper.indptr.astype(np.int32) + 1,
            upper.indices.astype(np.int32) + 1,
        )
        self._handle = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)  # iparm(1) = 0: PARDISO fills in its defaults
        empty = np.zeros(upper.shape[0])
        _pardiso(self._handle, 12, self._matrix, self._iparm, empty, empty.copy())
        self._iparm[7] = 0  # iparm(8): no iterative refinement in the solves (the default does 2 steps)
        weakref.finalize(self, _pardiso, self._handle, -1, self._matrix, self._iparm, empty, empty)

    def solve(self, rhs):
        rhs = np.asfortranarray(rhs, dtype=float)
        solution = np.zeros_like(rhs)
        _pardiso(self._handle, 33, self._matrix, self._iparm, rhs, solution)
        return np.ascontiguousarray(solution)


class _SuperLU:
    """A SuperLU factorisation (scipy), the fallback."""

    def __init__(self, matrix):
        self._factor = sla.splu(sp.csc_matrix(matrix), permc_spec="MMD_AT_PLUS_A")

    def solve(self, rhs):
        return self._factor.solve(np.asarray(rhs, dtype=float))


def factorise(matrix):
    """Factorise a symmetric sparse matrix once; the result's ``solve(b)`` takes vectors or (n, k) blocks.

    Parameters
    ----------
    matrix : scipy.sparse matrix
        Symmetric (K - sigma M, any units).
    """
    return _Pardiso(matrix) if solver_name() == "pardiso" else _SuperLU(matrix)
