"""Folders of the checkout the tests read (README, docs, bench scripts, shipped data), wherever a test module lives in
the layer folders of ``tests/``."""

from pathlib import Path

CHECKOUT = Path(__file__).resolve().parents[1]
"""The source checkout: ``tests/`` is in it."""
BENCH = CHECKOUT / "bench"
README = CHECKOUT / "README.md"
