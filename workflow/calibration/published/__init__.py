"""Logs of the two plates built and measured in the source paper (P1, P2; docs/calibration.md), read as package data."""

from contextlib import ExitStack
from dataclasses import replace
from importlib import resources

PUBLISHED_PLATES = {"P1": "paper_P1.csv", "P2": "paper_P2.csv"}
"""The published plates' built-plate logs in this package, by name."""


def published_plates() -> list:
    """The published plates as :class:`~workflow.calibration.calibration.MeasuredPlate`, named P1 and P2."""
    from workflow.calibration.calibration import measured_plate
    from workflow.calibration.logs import read_built_plate

    with ExitStack() as stack:
        paths = {name: stack.enter_context(resources.as_file(resources.files(__name__) / log))
                 for name, log in PUBLISHED_PLATES.items()}
        return [replace(measured_plate(read_built_plate(path)), name=name) for name, path in paths.items()]
