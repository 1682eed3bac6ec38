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


class _Pardiso:
    """A PARDISO factorisation of a symmetric matrix kept for repeated solves.

    pypardiso factorises; the solves call MKL directly with the 1-based index arrays converted
    once (pypardiso's own ``solve`` converts them and compares the matrix on every call).
    """

    def __init__(self, matrix):
        upper = sp.triu(matrix, format="csr")
        upper.sort_indices()
        self._solver = PyPardisoSolver(mtype=SYMMETRIC_INDEFINITE)
        self._solver.set_iparm(8, 0)  # no iterative refinement: residuals ~1e-12 without it, solves 2x faster
        self._solver.factorize(upper)
        self._size = upper.shape[0]
        self._data = upper.data
        self._ia = upper.indptr.astype(np.int32) + 1
        self._ja = upper.indices.astype(np.int32) + 1
        weakref.finalize(self, self._solver.free_memory, True)

    def solve(self, rhs):
        rhs = np.asfortranarray(rhs, dtype=float)
        solution = np.zeros_like(rhs)
        solver, error = self._solver, ctypes.c_int32(0)
        int_pointer, float_pointer = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
        solver._mkl_pardiso(
            solver.pt.ctypes.data_as(ctypes.POINTER(solver._pt_type[0])),
            ctypes.byref(ctypes.c_int32(1)),  # maxfct
            ctypes.byref(ctypes.c_int32(1)),  # mnum
            ctypes.byref(ctypes.c_int32(SYMMETRIC_INDEFINITE)),
            ctypes.byref(ctypes.c_int32(33)),  # phase: solve and iterative refinement
            ctypes.byref(ctypes.c_int32(self._size)),
            self._data.ctypes.data_as(float_pointer),
            self._ia.ctypes.data_as(int_pointer),
            self._ja.ctypes.data_as(int_pointer),
            solver.perm.ctypes.data_as(int_pointer),
            ctypes.byref(ctypes.c_int32(1 if rhs.ndim == 1 else rhs.shape[1])),
            solver.iparm.ctypes.data_as(int_pointer),
            ctypes.byref(ctypes.c_int32(0)),  # no messages
            rhs.ctypes.data_as(float_pointer),
            solution.ctypes.data_as(float_pointer),
            ctypes.byref(error),
        )
        if error.value != 0:
            raise TactileError(f"PARDISO solve failed with error {error.value}; set {SOLVER_VARIABLE}=superlu")
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
