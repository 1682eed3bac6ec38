"""Benchmarks, run on purpose: ``pytest -m bench``."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "bench"


@pytest.mark.bench
def test_analytical_benchmark_meets_its_targets():
    out = subprocess.run([sys.executable, str(BENCH / "bench_analytical.py")], capture_output=True, text=True, check=True)
    figures = json.loads(out.stdout.strip().splitlines()[-1])
    assert figures["geometries_per_s"] >= 1e6
    assert figures["optimisation_max_s"] <= 0.05
