"""Design maps over (lambda, h_i) and the width sweep (docs/model.md, docs/fem.md).

A map evaluates one model on a grid of the whole Table 1 box (so the 0.5 mm practical limit
shows): the beam model in one vectorised call, the FEM through
:class:`~workflow.optimise.fem_model.FemModel` (disk cache, local cores or a Dask cluster).
"""

from dataclasses import dataclass
from typing import Callable, Optional, Tuple

import numpy as np

from workflow.models import materials
from workflow.models.plate import ORIGINAL_PLATE, Plate
from workflow.optimise.problem import DesignProblem, Optimum, PlateModel

TRANSVERSE_THRESHOLD = 0.15
"""Transverse indicator of the working (best) mode above which a point counts as transverse [-].

The indicator is the share of the variance of the mode's w along y at the antinode lines
(0: a clean longitudinal mode, 1: purely transverse).  On the original plate's width sweep
(default mesh) the clean working mode stays at 0.01-0.06 (e.g. b = 55 mm: 0.03) and the widths
where a transverse mode mixes in and the deflection dips (42.5, 65, 77.5, 92.5 mm) reach 0.2-0.37.
"""


@dataclass(frozen=True)
class DesignMap:
    """Deflection and resonance of one model over a (lambda, h_i) grid.

    Attributes
    ----------
    model : str
        "analytical" or "fem".
    problem : DesignProblem
        h_p, b, voltage, f_min and the h_i limit drawn on the map.
    wavelength : ndarray, shape (n,)
        lambda axis [m].
    resonator_thickness : ndarray, shape (m,)
        h_i axis [m].
    deflection, frequency : ndarray, shape (n, m)
        w_dyn [m] and f_r [Hz], indexed [lambda, h_i].
    modes : tuple or None
        FEM only: per grid point (same C order) the tuple of ModeResult.
    optimum : Optimum or None
        The constrained optimum to mark.
    """

    model: str
    problem: DesignProblem
    wavelength: np.ndarray
    resonator_thickness: np.ndarray
    deflection: np.ndarray
    frequency: np.ndarray
    modes: Optional[Tuple] = None
    optimum: Optional[Optimum] = None


def grid_axes(problem: DesignProblem, points: int) -> Tuple[np.ndarray, np.ndarray]:
    """``points`` values of lambda and of h_i spanning the problem's box [m] (h_i from Table 1's lowest, below the
    practical minimum, so that the map shows what the minimum excludes; by default Table 1's ranges)."""
    return (np.linspace(*problem.wavelength_range, points),
            np.linspace(materials.RESONATOR_THICKNESS_RANGE[0], problem.max_resonator_thickness, points))


def design_map(
    model: PlateModel, problem: DesignProblem, points: int, name: str, optimum: Optional[Optimum] = None,
    results: Optional[Callable] = None,
) -> DesignMap:
    """Evaluate ``model`` on a ``points`` x ``points`` grid in one batch.

    ``results`` (plate -> FEM results, the FEM's :meth:`~workflow.optimise.fem_model.FemModel.results`) gives the
    values and the modes of every point instead of ``model``.
    """
    wavelength, thickness = grid_axes(problem, points)
    grid_wavelength, grid_thickness = np.meshgrid(wavelength, thickness, indexing="ij")
    plate = problem.plate(grid_wavelength, grid_thickness)
    modes = None
    if results is not None:
        results = results(plate)
        deflection = np.array([r.deflection for r in results]).reshape(grid_wavelength.shape)
        frequency = np.array([r.frequency for r in results]).reshape(grid_wavelength.shape)
        modes = tuple(r.modes for r in results)
    else:
        deflection, frequency = (np.broadcast_to(v, grid_wavelength.shape) for v in model(plate))
    return DesignMap(name, problem, wavelength, thickness, np.asarray(deflection), np.asarray(frequency), modes, optimum)


@dataclass(frozen=True)
class WidthSweep:
    """FEM deflection and resonance of one plate against its width.

    Attributes
    ----------
    plate : Plate
        The swept plate (its width is ignored).
    width : ndarray
        b [m].
    deflection, frequency : ndarray
        Best mode's w_dyn [m] and f_r [Hz] per width.
    transverse_indicator : ndarray
        Best mode's indicator per width [-].
    modes : tuple
        Every evaluated mode per width.
    """

    plate: Plate
    width: np.ndarray
    deflection: np.ndarray
    frequency: np.ndarray
    transverse_indicator: np.ndarray
    modes: Tuple

    @property
    def transverse(self) -> np.ndarray:
        """Widths whose working mode is transverse-mixed (indicator > :data:`TRANSVERSE_THRESHOLD`)."""
        return self.transverse_indicator > TRANSVERSE_THRESHOLD


def width_sweep(fem_model, plate: Plate = ORIGINAL_PLATE, widths: np.ndarray = None) -> WidthSweep:
    """w(b), f(b) of ``plate`` with the FEM (default b = 30 to 100 mm in 2.5 mm steps).

    Parameters
    ----------
    fem_model : FemModel
        Anything with ``results(plate) -> list of FemResult``.
    plate : Plate
    widths : array, optional
        b values [m].
    """
    widths = np.linspace(30e-3, 100e-3, 29) if widths is None else np.asarray(widths, float)
    results = fem_model.results(plate.with_(width=widths))
    return WidthSweep(
        plate=plate,
        width=widths,
        deflection=np.array([r.deflection for r in results]),
        frequency=np.array([r.frequency for r in results]),
        transverse_indicator=np.array([r.best.transverse_indicator for r in results]),
        modes=tuple(r.modes for r in results),
    )
