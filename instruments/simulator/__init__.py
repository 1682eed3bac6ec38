"""The bench simulator: one simulated plate shared by a simulated generator, vibrometer controller and lock-in.

Reach it through pyserial (``serial.serial_for_url("tactile-sim://NAME/generator")``,
after importing :mod:`instruments.simulator.urlhandler` or calling :func:`register_url_handler`)
or as pseudo-terminals (:mod:`.ptyserver`, ``tactile simulate --pty``).
"""

from instruments.simulator.bench import (
    Bench,
    BenchSettings,
    default_bench_settings,
    get_bench,
    register_bench,
)
from instruments.simulator.faults import FaultSettings
from instruments.simulator.urlhandler import URL_SCHEME, bench_url, register_url_handler

__all__ = [
    "Bench",
    "BenchSettings",
    "FaultSettings",
    "URL_SCHEME",
    "bench_url",
    "default_bench_settings",
    "get_bench",
    "register_bench",
    "register_url_handler",
]
