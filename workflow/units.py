"""Unit conversions at the edges (CLI flags, JSON, reports).  Inside: SI only."""

MM = 1e-3
"""One millimetre [m]."""
UM = 1e-6
"""One micrometre [m]."""
KHZ = 1e3
"""One kilohertz [Hz]."""
PM_PER_V = 1e-12
"""One picometre per volt [m/V]."""
NM = 1e-9
"""One nanometre [m]."""
