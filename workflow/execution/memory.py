"""How the C allocator treats the FEM's large arrays (glibc, Linux).

glibc serves an allocation above its mmap threshold (at most 32 MB) with fresh pages from the kernel and returns them
when it is freed; every first touch of such a page is a page fault, the kernel zeroing it. An FEM evaluation allocates
and frees arrays of 20-200 MB dozens of times (the sparsity pattern's index arrays, the matrices' data, PARDISO's
factor, the Krylov blocks): `tactile run` spent 258 of its 1169 s of CPU time in the kernel. :func:`keep_freed_memory`
raises the thresholds so that such arrays come from the heap and freed ones are reused: measured with ``python
bench/bench_allocator.py`` (docs/fem.md, "Speed"), a repeated evaluation at 0.2 % is 1.13-1.17 times faster (system
time 0.3-0.5 s -> 0.07-0.2 s), a first one gains nothing; a process's peak memory rose by 0.13-0.19 GB and the run's
by 1.2 GB (10.4 -> 11.6 GB), its wall time (11 min 09 s -> 10 min 38 s to 11 min 13 s) not beyond its scatter.
"""

import ctypes
import ctypes.util
import platform

MMAP_THRESHOLD = 1 << 30
"""Allocations from this size on still get their own pages from the kernel [bytes] (glibc's default: 128 kB rising
to 32 MB)."""
TRIM_THRESHOLD = 512 << 20
"""Free memory at the top of the heap beyond this is returned to the kernel [bytes] (glibc's default: 128 kB, or
twice the mmap threshold once that has risen)."""
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameter numbers (malloc.h)


def keep_freed_memory() -> bool:
    """Let this process keep and reuse freed large arrays (:data:`MMAP_THRESHOLD`, :data:`TRIM_THRESHOLD`).

    Process-wide, and inherited by forked workers; a no-op returning False where the C library is not glibc
    (macOS, Windows, musl).  Returns True when both thresholds were set.
    """
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    library = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    mallopt = getattr(library, "mallopt", None)
    if mallopt is None:
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
