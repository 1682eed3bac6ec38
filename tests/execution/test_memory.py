"""The C allocator keeps freed large arrays for reuse (workflow.execution.memory)."""

import json
import platform
import subprocess
import sys

import pytest

CHILD = """
import json, resource, sys
import numpy as np
from workflow.execution.memory import keep_freed_memory
kept = keep_freed_memory() if sys.argv[1] == "kept" else False
faults = []
for _ in range(3):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    array = np.ones(25_000_000)  # 200 MB, touched
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    del array
print(json.dumps({"kept": kept, "faults": faults}))
"""


def _faults(setting: str) -> dict:
    output = subprocess.run([sys.executable, "-c", CHILD, setting], capture_output=True, text=True, check=True).stdout
    return json.loads(output)


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc's mallopt")
def test_a_freed_large_array_is_reused_instead_of_faulted_in_again():
    """glibc's default gives every 200 MB array fresh pages (tens of thousands of page faults each time); once the
    thresholds are raised the second and third arrays reuse the first one's pages."""
    default, kept = _faults("default"), _faults("kept")
    assert kept["kept"] and not default["kept"]
    pages = 200e6 / 4096
    assert min(default["faults"][1:]) > 0.1 * pages / 512  # fresh pages each time (even as 2 MB huge pages)
    assert max(kept["faults"][1:]) < 0.01 * min(default["faults"][1:]) + 50


def test_keep_freed_memory_says_whether_it_applied():
    from workflow.execution.memory import keep_freed_memory

    applies = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"
    assert _faults("kept")["kept"] is applies
    assert keep_freed_memory() is applies  # and again: idempotent
