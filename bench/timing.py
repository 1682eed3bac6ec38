"""Timing shared by the benchmark scripts."""

import time


def best_time(function, repeat):
    """Shortest wall time of ``repeat`` calls [s]."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)
