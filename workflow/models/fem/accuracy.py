"""Accuracy control of the plate FEM: meshes that follow the geometry, and discretisation-error estimates.

A mesh *level* n is the number of elements along each ceramic; everything else follows the
geometry (docs/fem.md, "Accuracy control"):

* along x, elements shrink towards the ceramic ends (grading :data:`GRADING`), where the
  bimaterial corners make the field singular, and the gaps get elements as small as the
  smallest ceramic element;
* through the thickness, n/4 elements per layer (at least 2), graded towards the bond;
* across the width, elements :data:`WIDTH_ELEMENT_RATIO` times the mean x element length, so a
  transverse mode near the working frequency is resolved as well as the working mode.

A result's error is estimated by Richardson extrapolation from the same geometry on the next
coarser level, with the conservative rate :data:`RICHARDSON_RATE` (observed 2.3 in x on the thin
designs): e = (v_coarse - v_n) / ((n / n_coarse)^p - 1) estimates v_n - v_converged.
:func:`evaluate_to_accuracy` refines until the frequency estimate meets the target.
"""

import math
from dataclasses import asdict, dataclass, replace
from typing import Callable

import numpy as np

from workflow.errors import TactileError
from workflow.models.fem.mesh import MeshTooLargeError, check_memory
from workflow.models.fem.settings import PIEZO_MODELS, FemSettings
from workflow.models.limits import LIMITS
from workflow.models.plate import Plate

LEVELS = (4, 6, 8, 10, 12, 16)
"""Mesh levels: elements per ceramic [-]; each error estimate pairs a level with the one before."""
GRADING = 0.6
"""Grading of the elements towards the ceramic ends and the bond: end element (1-c)/(1+c) of the mean [-]."""
WIDTH_ELEMENT_RATIO = 3.0
"""Element length across the width over the mean element length along x [-]."""
RICHARDSON_RATE = 2.0
"""Assumed convergence rate p of the frequency and deflection in the element size [-]."""
DEFAULT_ACCURACY = 2e-3
"""Default target relative frequency error of an FEM evaluation [-] (0.2 %)."""
SURVEY_ACCURACY = 0.01
"""Default target of maps and width sweeps (many geometries) [-] (1 %)."""
ACCURACY_RANGE = LIMITS["fem_accuracy"]
"""Accepted targets [-]."""


@dataclass(frozen=True)
class FemAccuracy:
    """Ask the FEM for a relative frequency accuracy instead of a fixed mesh.

    Attributes
    ----------
    target : float
        Relative frequency error to reach, |f_n / f_converged - 1| [-].
    n_modes : int
        Eigenmodes computed nearest the analytical resonance [-].
    max_level : int
        Finest level allowed (elements per ceramic, one of :data:`LEVELS`) [-]; a result that
        still misses the target there says so (``ErrorEstimate.met``).
    piezo : str
        Piezo model, one of :data:`~workflow.models.fem.settings.PIEZO_MODELS`.
    """

    target: float = DEFAULT_ACCURACY
    n_modes: int = 6
    max_level: int = 12
    piezo: str = "eigenstrain"

    def __post_init__(self):
        low, high = ACCURACY_RANGE
        if not (isinstance(self.target, (int, float)) and math.isfinite(self.target) and low <= self.target <= high):
            raise TactileError(f"FEM accuracy must be a relative error from {low:g} to {high:g}, got {self.target!r}")
        if self.piezo not in PIEZO_MODELS:
            raise TactileError(f"unknown piezo model {self.piezo!r}; choose one of {', '.join(PIEZO_MODELS)}")
        if self.max_level not in LEVELS[1:]:
            raise TactileError(f"max_level must be one of {', '.join(map(str, LEVELS[1:]))}, got {self.max_level!r}")

    @property
    def start_level(self) -> int:
        """First level tried: 8 for targets under 0.5 %, else 6 (the 4/6 pair is not yet asymptotic)."""
        return min(8 if self.target < 5e-3 else 6, self.max_level)

    def as_dict(self) -> dict:
        """Plain dict (content hashing and JSON)."""
        return {"kind": "accuracy", **asdict(self)}


@dataclass(frozen=True)
class ErrorEstimate:
    """Estimated discretisation error of an FEM result's best mode.

    Attributes
    ----------
    frequency, deflection : float
        Relative error estimates of the reported values, v_n / v_converged - 1 (signed) [-].
    level, coarse_level : int
        Elements per ceramic of the reported and of the coarser mesh [-].
    coarse_frequency, coarse_deflection : float
        The same mode on the coarser mesh [Hz], [m].
    mode_match : float
        Modal assurance criterion between the two meshes' modes at the probes [-] (1: same shape).
    target : float or None
        The accuracy asked for [-] (None for a fixed mesh).
    """

    frequency: float
    deflection: float
    level: int
    coarse_level: int
    coarse_frequency: float
    coarse_deflection: float
    mode_match: float
    target: float | None = None

    @property
    def met(self) -> bool:
        """Whether the frequency estimate is within the target (False for a fixed mesh)."""
        return self.target is not None and abs(self.frequency) <= self.target

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "ErrorEstimate":
        return cls(**data)


def mesh_for_level(plate: Plate, level: int, n_modes: int = 6, piezo: str = "eigenstrain") -> FemSettings:
    """The mesh of ``plate`` at a level (elements per ceramic), following its geometry.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    level : int
        Elements per ceramic along x, even [-].
    n_modes : int
        Eigenmodes to compute [-].
    piezo : str
        Piezo model.
    """
    ceramic_length = float(plate.ceramic_length)
    mean_length = ceramic_length / level
    smallest = mean_length * (1 - GRADING) / (1 + GRADING)
    return FemSettings(
        elements_per_ceramic=level,
        elements_per_gap=max(1, math.ceil(plate.gap / (1.5 * smallest))),
        elements_per_layer=max(2, math.ceil(level / 4)),
        elements_across_half_width=max(3, math.ceil(float(plate.width) / 2 / (WIDTH_ELEMENT_RATIO * mean_length))),
        n_modes=n_modes,
        grading=GRADING,
        piezo=piezo,
    )


def richardson_error(fine: float, coarse: float, ratio: float, rate: float = RICHARDSON_RATE) -> float:
    """Estimated error v_fine - v_converged from two meshes whose element sizes differ by ``ratio`` (> 1).

    From v_h = v_converged + C h^p: v_converged = v_fine + (v_fine - v_coarse) / (ratio^p - 1).
    """
    return (coarse - fine) / (ratio**rate - 1)


def modal_assurance(a, b) -> np.ndarray:
    """MAC |a.b|^2 / (|a|^2 |b|^2) between a vector ``a`` and the columns of ``b`` [-]."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return (a @ b) ** 2 / ((a @ a) * np.einsum("ij,ij->j", b, b))


def estimate_error(fine, coarse, level: int, coarse_level: int, target: float | None = None) -> ErrorEstimate:
    """Error estimate of ``fine``'s best mode from the matching mode of ``coarse`` (two FemResults).

    The coarse mode is the one whose probe shape is closest (MAC) to the fine best mode's.
    """
    shapes = coarse.probe_model.probe_shapes
    match = modal_assurance(fine.probe_model.probe_shapes[:, fine.best_index], shapes)
    partner = coarse.modes[int(np.argmax(match))]
    ratio = level / coarse_level
    f_error = richardson_error(fine.frequency, partner.frequency, ratio)
    w_error = richardson_error(fine.deflection, partner.deflection, ratio)
    return ErrorEstimate(
        frequency=float(f_error / (fine.frequency - f_error)),
        deflection=float(w_error / (fine.deflection - w_error)),
        level=level,
        coarse_level=coarse_level,
        coarse_frequency=float(partner.frequency),
        coarse_deflection=float(partner.deflection),
        mode_match=float(np.max(match)),
        target=target,
    )


def next_level(level: int, relative_error: float, target: float, max_level: int) -> int:
    """The coarsest level predicted to meet ``target`` at rate p, at least one step finer, at most ``max_level``."""
    finer = [n for n in LEVELS if level < n <= max_level]
    for n in finer:
        if abs(relative_error) * (level / n) ** RICHARDSON_RATE <= target:
            return n
    return finer[-1]


def evaluate_to_accuracy(plate: Plate, accuracy: FemAccuracy, evaluate_mesh: Callable):
    """Refine the mesh of ``plate`` until the estimated frequency error meets ``accuracy.target``.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    accuracy : FemAccuracy
    evaluate_mesh : callable
        FemSettings -> FemResult for this plate (Q and voltage bound by the caller).
    Returns
    -------
    FemResult
        The finest evaluation, with ``error`` set; the finest level is the coarser of ``accuracy.max_level``
        and the finest within the memory budget (:data:`~workflow.models.fem.mesh.MEMORY_BUDGET`).

    Raises
    ------
    MeshTooLargeError
        If not even the two coarsest levels fit the budget.
    """
    fitting = [n for n in LEVELS if n <= accuracy.max_level and _fits(plate, n, accuracy)]
    max_level = fitting[-1] if len(fitting) >= 2 else accuracy.max_level
    level = min(accuracy.start_level, max_level)
    coarse_level = LEVELS[LEVELS.index(level) - 1]
    coarse = evaluate_mesh(mesh_for_level(plate, coarse_level, accuracy.n_modes, accuracy.piezo))
    while True:
        fine = evaluate_mesh(mesh_for_level(plate, level, accuracy.n_modes, accuracy.piezo))
        estimate = estimate_error(fine, coarse, level, coarse_level, accuracy.target)
        if estimate.met or level >= max_level:
            return replace(fine, error=estimate)
        coarse, coarse_level = fine, level
        level = next_level(level, estimate.frequency, accuracy.target, max_level)


def _fits(plate: Plate, level: int, accuracy: FemAccuracy) -> bool:
    """Whether the mesh of ``level`` fits the memory budget (:func:`~workflow.models.fem.mesh.check_memory`)."""
    try:
        check_memory(plate, mesh_for_level(plate, level, accuracy.n_modes, accuracy.piezo))
    except MeshTooLargeError:
        return False
    return True
