"""How the C allocator treats the FEM's large arrays (glibc, Linux).

glibc serves an allocation above its mmap threshold (at most 32 MB) with fresh pages from the kernel and
returns them when it is freed; every first touch of such a page is a page fault, the kernel zeroing it.  An FEM
evaluation allocates and frees arrays of 20-200 MB dozens of times (the sparsity pattern's index arrays, the
matrices' data, PARDISO's factor, the Krylov blocks), so that a third of a first evaluation's CPU time was the
kernel's (system time 2.2-2.8 s of 7 s on the original plate).  :func:`keep_freed_memory` raises the thresholds so
that such arrays come from the heap and freed ones are reused: measured on the original plate at 0.2 %
(``python bench/bench_allocator.py``), the system time of a repeated evaluation fell from 0.3 s to 0.1 s and that
of a first one by more than half; the peak memory of a process rose by 0.13 GB (7 %).
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
