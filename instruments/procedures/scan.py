"""Deflection scan: the plate driven at one frequency and voltage, the laser spot moved over a grid of points.

The vibrometer's scanner puts the spot on each point (``Set,Scanner,0,X|Y``; docs/instruments.md);
each point's velocity amplitude and phase go to a log with ``x_mm``, ``y_mm`` columns
(docs/log-format.md), one row per point, so an interrupted scan resumes without losing or
repeating a point (rows are keyed by their position).
"""

import hashlib
from dataclasses import dataclass

import numpy as np

from instruments.procedures.sweeps import PlannedPoint, ProcedureResult, Station, check_frequencies, check_sizes, run_procedure
from workflow import logformat
from workflow.units import MM

DEFAULT_GRID = (11, 5)
"""Scan points along x and y [-]."""
DEFAULT_MARGIN = 2e-3
"""Distance of the outermost points from the plate's edges [m] (a laser spot near an edge is unreliable)."""
DEFAULT_VOLTAGE = 5.0
"""Drive of a scan [V peak across the ceramics]."""


def grid_points(half_length: float, half_width: float, nx: int, ny: int, margin: float = DEFAULT_MARGIN) -> tuple:
    """Points (x, y) [m] of an ``nx`` x ``ny`` grid over the plate, ``margin`` [m] inside its edges.

    Rows along x, one per y, in alternating directions (the scanner's shortest path).  A single
    point along an axis sits on the centre line.

    Parameters
    ----------
    half_length, half_width : float
        L/2 and b/2 [m].
    nx, ny : int
        Points along x and y [-].
    margin : float
        [m], smaller than the half extents.
    """
    if not (0 <= margin < min(half_length, half_width)):
        raise ValueError(f"scan margin {margin / MM:g} mm must be >= 0 and inside the plate "
                         f"({half_length / MM:g} x {half_width / MM:g} mm from its centre)")
    xs = np.linspace(-(half_length - margin), half_length - margin, nx) if nx > 1 else np.zeros(1)
    ys = np.linspace(-(half_width - margin), half_width - margin, ny) if ny > 1 else np.zeros(1)
    return tuple((float(x), float(y)) for row, y in enumerate(ys) for x in (xs if row % 2 == 0 else xs[::-1]))


@dataclass(frozen=True)
class ScanPlan:
    """Drive at ``frequency`` [Hz] with ``voltage`` [V peak across the ceramics]; measure at ``points``.

    Attributes
    ----------
    frequency : float
        [Hz], usually the resonance.
    voltage : float
        [V peak across the ceramics].
    points : tuple of (float, float)
        Laser spot positions (x, y) from the plate's centre [m], in scanning order.
    """

    frequency: float
    voltage: float
    points: tuple

    def __post_init__(self):
        check_sizes({}, len(self.points), "scan plan")
        check_frequencies(self.frequency, self.frequency, "scan plan")
        if not self.points:
            raise ValueError("a scan needs at least one point")

    def planned(self) -> list[PlannedPoint]:
        """The points to measure, all in sweep 0."""
        return [PlannedPoint(0, self.frequency, self.voltage, point) for point in self.points]

    def metadata(self) -> dict:
        """The ``plan_*`` items: frequency, voltage, the number of points and a digest of their positions.

        Resuming requires the same items, so the same points (as logged, to 0.1 um).
        """
        keys = "".join(f"{x / MM:.4f},{y / MM:.4f};" for x, y in self.points)
        return {"frequency": self.frequency, "voltage": self.voltage, "points": len(self.points),
                "points_sha256": hashlib.sha256(keys.encode()).hexdigest()[:16]}


def deflection_scan(station: Station, path, plan: ScanPlan, metadata: dict | None = None, restart: bool = False,
                    fsync: bool = True) -> ProcedureResult:
    """Measure the velocity at every point of ``plan``; summary: ``frequency_hz``, ``voltage_v``, ``points``,
    the largest deflection ``max_deflection_um`` and where it is (``max_x_mm``, ``max_y_mm``)."""
    rows, counts = run_procedure(station, path, "scan", plan.metadata(), [plan.voltage], lambda log: [plan.planned()],
                        metadata or {}, restart, fsync, columns=logformat.SCAN_COLUMNS)
    velocity = np.array([float(row[logformat.VELOCITY]) for row in rows])
    top = rows[int(np.argmax(velocity))]
    summary = {
        "frequency_hz": plan.frequency,
        "voltage_v": plan.voltage,
        "points": len(rows),
        "max_deflection_um": float(velocity.max() / (2 * np.pi * plan.frequency) / 1e-6),
        "max_x_mm": float(top[logformat.X_POSITION]),
        "max_y_mm": float(top[logformat.Y_POSITION]),
    }
    return ProcedureResult(**counts, summary=summary)
