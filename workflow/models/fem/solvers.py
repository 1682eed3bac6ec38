"""Sparse direct factorisation of the shifted FEM matrices, with the fastest solver that is installed.

The shifted matrices K - sigma M are symmetric and indefinite.  PARDISO (Intel MKL, through the
``pypardiso`` package from PyPI, x86-64 only) factorises them as symmetric indefinite about 5-7 times
faster than SuperLU (scipy) on the plate's 10^4-10^5 dof systems (docs/fem.md, ``bench/bench_fem.py``);
SuperLU is the fallback wherever pypardiso does not install.  ``$TACTILE_SPARSE_SOLVER`` set to
``superlu`` or ``pardiso`` forces one (benchmarks, tests).
"""

import ctypes
import os
import threading
import weakref
from dataclasses import dataclass
from importlib import metadata
from functools import lru_cache

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from workflow.errors import TactileError
from workflow.models.fem.structures import StructureCache, canonical, describe, shared

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


MKL_VARIABLE = "PYPARDISO_MKL_RT"
"""Environment variable through which pypardiso takes the path of MKL's runtime library."""


def _installed_mkl_runtime() -> str | None:
    """The runtime library the ``mkl`` package installed, from the package's record of its files (None if absent)."""
    try:
        files = metadata.files("mkl") or []
    except metadata.PackageNotFoundError:
        return None
    found = sorted((str(f.locate()) for f in files if f.name.startswith("libmkl_rt")), key=len)
    return next((path for path in found if os.path.exists(path)), None)


@lru_cache(maxsize=1)
def _pypardiso():
    """One pypardiso solver object, for the MKL library it loaded.  Without ``$PYPARDISO_MKL_RT`` pypardiso asks
    the linker and then searches every folder under the environment's ``lib`` (0.4 s, each time it is made); the
    ``mkl`` package's own record names the library directly."""
    runtime = None if os.environ.get(MKL_VARIABLE) else _installed_mkl_runtime()
    if runtime is None:
        return PyPardisoSolver()
    os.environ[MKL_VARIABLE] = runtime
    try:
        return PyPardisoSolver()
    finally:
        del os.environ[MKL_VARIABLE]


def _mkl_pardiso():
    """MKL's ``pardiso`` with its argument types."""
    return _pypardiso()._mkl_pardiso


@lru_cache(maxsize=1)
def _mkl_threads():
    """MKL's (``mkl_get_max_threads``, ``mkl_set_num_threads_local``) of the library pypardiso loaded."""
    library = _pypardiso().libmkl
    get, set_local = library.MKL_Get_Max_Threads, library.MKL_Set_Num_Threads_Local
    get.restype, set_local.restype, set_local.argtypes = ctypes.c_int, ctypes.c_int, [ctypes.c_int]
    return get, set_local


UPPER_STRUCTURES = 4
"""Upper-triangle structures kept with their PARDISO analyses, one per sparsity structure (the assembly shares its
structures between evaluations of one mesh topology) [-]."""
_upper_structures = StructureCache(UPPER_STRUCTURES)


@dataclass(eq=False)
class _UpperStructure:
    """The upper triangle of a symmetric CSC structure: which entries it keeps and its CSR arrays (0-based), and the
    PARDISO analysis of it once made (kept for shared structures only)."""

    keep: np.ndarray
    indices: np.ndarray
    indptr: np.ndarray
    analysis: "_Analysis | None" = None


def _upper_selection(matrix: sp.csc_matrix) -> _UpperStructure:
    """The upper triangle of a canonical CSC structure, remembered for structures that are shared and read-only
    (those of :mod:`~workflow.models.fem.assembly`'s patterns; a matrix built on them holds views of their arrays,
    recognised by the array that owns the memory)."""
    key = (describe(matrix),) if shared(matrix) else None
    structure = _upper_structures.get(key) if key else None
    if structure is None:
        indptr, indices = matrix.indptr, matrix.indices
        rows = np.repeat(np.arange(matrix.shape[0], dtype=indices.dtype), np.diff(indptr))
        keep = np.flatnonzero(indices >= rows)
        upper_indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[keep], minlength=matrix.shape[0]))])
        structure = _UpperStructure(keep, indices[keep], upper_indptr)
        if key:
            _upper_structures.put(key, structure)
    return structure


def upper_triangle(matrix) -> sp.csr_matrix:
    """Upper triangle of a symmetric sparse matrix as CSR with sorted indices (its CSC structure read as CSR)."""
    matrix = canonical(matrix)
    structure = _upper_selection(matrix)
    return sp.csr_matrix((matrix.data[structure.keep], structure.indices, structure.indptr), shape=matrix.shape)


def _pardiso(handle, phase: int, matrix: tuple, iparm, rhs, solution) -> None:
    """One call of MKL's ``pardiso`` on a real symmetric indefinite matrix (1-based CSR upper triangle).

    Parameters
    ----------
    handle : (64,) int64 array
        PARDISO's internal pointer array of this factorisation.
    phase : int
        11 analysis, 22 numeric factorisation, 33 solve, 0 release of the factorisation, -1 release of all.
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


def _with_threads(threads: int, handle, phase: int, matrix: tuple, iparm, rhs, solution=None) -> None:
    """:func:`_pardiso` with ``threads`` MKL threads, those of the handle's analysis: a phase run with other threads
    than the analysis's (e.g. a solve under a one-thread limit) makes the next factorisation crash."""
    set_local = _mkl_threads()[1]
    previous = set_local(threads)
    try:
        _pardiso(handle, phase, matrix, iparm, rhs, rhs.copy() if solution is None else solution)
    finally:
        set_local(previous)


class _Analysis:
    """PARDISO's analysis (fill-reducing ordering and symbolic factorisation) of one upper-triangle structure, and the
    one numeric factorisation it holds at a time.

    The analysis costs about twice the numeric factorisation (0.8 s against 0.4 s at degree 4; docs/fem.md, "Speed")
    and depends only on the structure, which every evaluation of one mesh topology shares: it is made once and
    each factorisation of that structure only factorises its numbers.  A factor whose numbers were replaced by
    another's factorises them again before its next solve, so a solve always uses its own matrix.
    """

    def __init__(self, structure: _UpperStructure, data: np.ndarray):
        self.size = len(structure.indptr) - 1
        self.ia, self.ja = structure.indptr.astype(np.int32) + 1, structure.indices.astype(np.int32) + 1
        self.handle = np.zeros(64, dtype=np.int64)
        self.iparm = np.zeros(64, dtype=np.int32)  # iparm(1) = 0: PARDISO fills in its defaults
        self.lock = threading.RLock()  # re-entrant: a finalizer (release) may run inside a call, when memory is allocated
        self.holder = None  # the factor whose numbers are factorised
        self.threads = _mkl_threads()[0]()
        self._call(11, data)
        self.iparm[7] = 0  # iparm(8): no iterative refinement in the solves (the default does 2 steps)
        matrix = (self.size, data[:0], self.ia, self.ja)
        finalizer = weakref.finalize(self, _with_threads, self.threads, self.handle, -1, matrix, self.iparm, np.zeros(0))
        finalizer.atexit = False  # at exit the process's memory goes anyway

    def _call(self, phase: int, data: np.ndarray, rhs=None, solution=None) -> None:
        rhs = np.zeros(self.size) if rhs is None else rhs
        _with_threads(self.threads, self.handle, phase, (self.size, data, self.ia, self.ja), self.iparm, rhs, solution)

    def factorise(self, factor: "_Pardiso") -> None:
        """Factorise the numbers of ``factor`` (they replace those held)."""
        with self.lock:
            self._call(22, factor.data)
            self.holder = weakref.ref(factor)

    def solve(self, factor: "_Pardiso", rhs: np.ndarray) -> np.ndarray:
        """``factor``'s matrix^-1 rhs, its numbers factorised again if another factor's replaced them."""
        with self.lock:
            if self.holder is None or self.holder() is not factor:
                self._call(22, factor.data)
                self.holder = weakref.ref(factor)
            solution = np.zeros_like(rhs)
            self._call(33, factor.data, rhs, solution)
            return solution

    def release(self, factor_reference) -> None:
        """Free the numeric factorisation's memory if the factor (now gone) of ``factor_reference`` still holds it."""
        with self.lock:
            if self.holder is factor_reference:
                self._call(0, np.zeros(0))
                self.holder = None


class _Pardiso:
    """A PARDISO factorisation of a symmetric matrix kept for repeated solves (MKL called directly).

    PARDISO's defaults, but without iterative refinement in the solves: residuals stay ~1e-12 and a
    solve costs a third.  Shared structures reuse their analysis (:class:`_Analysis`).
    """

    def __init__(self, matrix):
        matrix = canonical(matrix)
        structure = _upper_selection(matrix)  # remembered with its analysis only for shared structures
        self.data = np.ascontiguousarray(matrix.data[structure.keep], dtype=float)
        if structure.analysis is None:
            structure.analysis = _Analysis(structure, self.data)
        self._analysis = structure.analysis
        self._analysis.factorise(self)
        finalizer = weakref.finalize(self, self._analysis.release, self._analysis.holder)
        finalizer.atexit = False

    def solve(self, rhs):
        rhs = np.asfortranarray(rhs, dtype=float)
        return np.ascontiguousarray(self._analysis.solve(self, rhs))


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
