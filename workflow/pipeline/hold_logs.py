"""Hold logs (``tactile measure hold``) read back, and their figure."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from instruments.procedures.logwriter import HOLD_KEY_COLUMNS, read_log
from workflow import logformat
from workflow.errors import InputFileError
from workflow.pipeline.rendering import save_figure


@dataclass(frozen=True)
class HoldRecord:
    """One hold, its samples in hold-time order.

    Attributes
    ----------
    label : str
    time : numpy.ndarray
        Hold time [s].
    velocity, frequency, drive : numpy.ndarray
        [m/s], [Hz], [V peak across the ceramics].
    temperature : numpy.ndarray
        [deg C] (nan where the bench has no sensor).
    target : float
        The velocity held [m/s].
    closed : bool
        Closed loop, or frozen once locked.
    """

    label: str
    time: np.ndarray
    velocity: np.ndarray
    frequency: np.ndarray
    drive: np.ndarray
    temperature: np.ndarray
    target: float
    closed: bool


def read_hold_log(path) -> HoldRecord:
    """The hold in the log ``path`` (a sample logged twice counts once, the first)."""
    path = Path(path)
    logged = read_log(path, logformat.HOLD_COLUMNS)
    metadata = logged.metadata
    try:
        target = float(metadata["plan_target_velocity"])
        closed = metadata["plan_closed"] == "True"
    except (KeyError, ValueError):
        raise InputFileError(f"{path}: not a hold log (no plan_target_velocity / plan_closed metadata)") from None
    rows = {}
    for row in logged.rows:
        rows.setdefault(tuple(row[column] for column in HOLD_KEY_COLUMNS), row)
    ordered = sorted(rows.values(), key=lambda row: float(row[logformat.HOLD_TIME]))

    def column(name):
        return np.array([float(row[name]) if row[name] else np.nan for row in ordered])

    label = f"{'closed' if closed else 'open'} loop ({path.name})"
    return HoldRecord(label, column(logformat.HOLD_TIME), column(logformat.VELOCITY), column(logformat.FREQUENCY),
                      column(logformat.DRIVE_VOLTAGE), column(logformat.TEMPERATURE), target, closed)


def hold_figure_file(logs, path) -> dict:
    """Draw the holds of ``logs`` together (:func:`workflow.pipeline.figures.hold.hold_figure`) at ``path``."""
    from workflow.pipeline.figures.hold import hold_figure

    save_figure(hold_figure([read_hold_log(log) for log in logs]), path)
    return {"figure": str(path)}
