"""Accuracy control of the plate FEM: meshes that follow the geometry, and discretisation-error estimates.

A mesh *level* k is the polynomial degree of its spectral elements, along x, y and z alike
(:func:`mesh_for_level`; docs/fem.md, "Accuracy control").  The mesh itself does not change with k:

* along x, :data:`ELEMENTS_PER_CERAMIC` elements per ceramic, graded (:data:`GRADING`) towards the
  ceramic ends, where the bimaterial corners make the field singular, and two across each gap;
* through the thickness, one element per layer (ceramic, glue, resonator);
* across the width, elements :data:`WIDTH_ELEMENT_RATIO` times the mean element length along x, so
  a short wavelength gets more of them and a transverse mode near the working one is resolved.

Raising the degree on a fixed mesh converges algebraically, as a power of the degree (the bimaterial
corners at the ceramic ends are singular: observed rates 2.15-2.5 on a thin one-ceramic plate, 3 and
more on the designs).  A result's error is estimated from the same geometry at a lower level by Richardson
extrapolation in the degree with the conservative rate :data:`RICHARDSON_RATE`:
e = (v_coarse - v_k) / ((k / k_coarse)^p - 1), the estimated v_k - v_converged (validated against
converged solutions in tests/models/test_fem_accuracy.py and docs/fem.md).  :func:`evaluate_to_accuracy`
raises the degree until the frequency estimate meets the target.
"""

import math
from dataclasses import asdict, dataclass, replace
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from workflow.errors import TactileError
from workflow.models.fem.mesh import MeshTooLargeError, check_memory
from workflow.models.fem.settings import FemSettings, check_piezo
from workflow.models.limits import LIMITS
from workflow.models.plate import Plate

LEVELS = (2, 3, 4, 5, 6)
"""Mesh levels: the polynomial degree of the spectral elements along x, y and z [-]; each error estimate
pairs a level with the one below."""
ELEMENTS_PER_CERAMIC = 4
"""Elements along x per full ceramic (the half ceramic at x = 0 gets half) [-]."""
ELEMENTS_PER_GAP = 2
"""Elements along x across each gap between ceramics [-]."""
GRADING = 0.85
"""Grading of the elements towards the ceramic ends: end element (1-c)/(1+c) of the mean [-]."""
WIDTH_ELEMENT_RATIO = 2.0
"""Element length across the width over the mean element length along a ceramic [-]."""
RICHARDSON_RATE = 2.0
"""Assumed convergence rate p of the frequency and deflection in the degree [-]: below the lowest observed, 2.15 on a
thin one-ceramic plate at degrees 4-6 (2.5 at degrees 3-5, 3 and more on the designs; tests/models/test_fem_accuracy.py
checks it)."""
ASYMPTOTIC_LEVEL = 3
"""Lowest degree whose pairing with the one below gives a Richardson estimate to extrapolate from [-]: degree 2 is not
yet asymptotic (the original plate's frequency rises from degree 2 to 3, then falls; docs/fem.md), so an estimate of
degree 3 against 2 that misses the target only says "one level more", not how many (it predicted degree 5 where
degree 4 met the target, see :func:`evaluate_to_accuracy`)."""
DEFAULT_ACCURACY = 2e-3
"""Default target relative frequency error of an FEM evaluation [-] (0.2 %)."""
SURVEY_ACCURACY = 5e-3
"""Default target of maps and width sweeps (many geometries) [-] (0.5 %)."""
SIMULATION_ACCURACY_TARGET = 1e-2
"""Default target of the bench simulator's built plate (1 % in frequency, degree 3: a few seconds, once per plate)
[-]; the simulator's plate is a discretisation of its own, as a built plate is a plate of its own."""
ACCURACY_RANGE = LIMITS["fem_accuracy"]
"""Accepted targets [-]."""


@dataclass(frozen=True)
class FemAccuracy:
    """Ask the FEM for a relative frequency accuracy instead of a fixed mesh.

    Attributes
    ----------
    target : float
        Relative frequency error to reach, |f_k / f_converged - 1| [-].
    n_modes : int
        Eigenmodes computed nearest the analytical resonance [-].
    max_level : int
        Highest level allowed (polynomial degree, one of :data:`LEVELS`) [-]; a result that
        still misses the target there says so (``ErrorEstimate.met``).
    piezo : str
        Piezo model, one of :data:`~workflow.models.fem.settings.PIEZO_MODELS`.
    """

    target: float = DEFAULT_ACCURACY
    n_modes: int = 6
    max_level: int = 5
    piezo: str = "eigenstrain"

    def __post_init__(self):
        low, high = ACCURACY_RANGE
        if not (isinstance(self.target, (int, float)) and math.isfinite(self.target) and low <= self.target <= high):
            raise TactileError(f"FEM accuracy must be a relative error from {low:g} to {high:g}, got {self.target!r}")
        check_piezo(self.piezo)
        if self.max_level not in LEVELS[1:]:
            raise TactileError(f"max_level must be one of {', '.join(map(str, LEVELS[1:]))}, got {self.max_level!r}")

    @property
    def start_level(self) -> int:
        """First level tried: degree 4 for targets under 0.5 %, else 3 (against 2, barely asymptotic)."""
        return min(4 if self.target < SURVEY_ACCURACY else 3, self.max_level)

    def as_dict(self) -> dict:
        """Plain dict (content hashing and JSON)."""
        return {"kind": "accuracy", **asdict(self)}

    refines = True
    """An evaluation refines its mesh until the target is met (a :class:`~workflow.models.fem.settings.FemSettings`
    is one fixed mesh)."""

    def resolved(self, plate: Plate, evaluate: Callable) -> tuple:
        """(the fixed mesh an evaluation of ``plate`` to this accuracy ends on, its error estimate), from one
        evaluation ``evaluate()`` -> FemResult; a :class:`~workflow.models.fem.settings.FemSettings` answers with
        itself and no estimate, evaluating nothing."""
        error = evaluate().error
        return mesh_for_level(plate, error.level, self.n_modes, self.piezo), error

    def evaluated(self, plate: Plate, evaluate_mesh: Callable, start=None, keep_solution: bool = False):
        """The FEM result of ``plate`` to this accuracy (:func:`evaluate_to_accuracy`; ``start`` unused: each level
        starts from the one below).  A :class:`~workflow.models.fem.settings.FemSettings` answers the same call on its
        fixed mesh, so an evaluation takes either without asking which it has."""
        return evaluate_to_accuracy(plate, self, evaluate_mesh, keep_solution)


@dataclass(frozen=True)
class FemLevel:
    """One level of the geometry-following mesh (:func:`mesh_for_level`) for every plate, without an error estimate.

    What the points of a two-level surrogate design are evaluated on
    (:class:`~workflow.calibration.plate_surrogate.DesignFem`): the mesh follows each plate as an accuracy's does,
    but its degree is fixed, so neighbouring plates share a discretisation and their differences are accurate
    beyond their values.

    Attributes
    ----------
    level : int
        Polynomial degree, one of :data:`LEVELS` [-].
    n_modes : int
        Eigenmodes computed nearest the analytical resonance [-].
    piezo : str
        Piezo model, one of :data:`~workflow.models.fem.settings.PIEZO_MODELS`.
    """

    level: int = 3
    n_modes: int = 6
    piezo: str = "eigenstrain"

    def __post_init__(self):
        if self.level not in LEVELS:
            raise TactileError(f"an FEM level must be one of {', '.join(map(str, LEVELS))}, got {self.level!r}")
        check_piezo(self.piezo)

    refines = False
    """One mesh per plate, not refined (as :class:`~workflow.models.fem.settings.FemSettings`)."""

    def as_dict(self) -> dict:
        """Plain dict (content hashing and JSON)."""
        return {"kind": "level", **asdict(self)}

    def mesh(self, plate: Plate) -> FemSettings:
        """The fixed mesh of ``plate`` at this level."""
        return mesh_for_level(plate, self.level, self.n_modes, self.piezo)

    def resolved(self, plate: Plate, evaluate: Callable) -> tuple:
        """(the mesh of ``plate`` at this level, no estimate); ``evaluate`` is not called."""
        return self.mesh(plate), None

    def evaluated(self, plate: Plate, evaluate_mesh: Callable, start=None, keep_solution: bool = False):
        """The FEM result of ``plate`` on its mesh at this level: ``evaluate_mesh(mesh, start)`` (its solution kept;
        ``keep_solution`` unused, as for a fixed mesh)."""
        return evaluate_mesh(self.mesh(plate), start)


@dataclass(frozen=True)
class ErrorEstimate:
    """Estimated discretisation error of an FEM result's best mode.

    Attributes
    ----------
    frequency, deflection : float
        Relative error estimates of the reported values, v_n / v_converged - 1 (signed) [-].
    level, coarse_level : int
        Polynomial degree of the reported and of the lower level [-].
    coarse_frequency, coarse_deflection : float
        The same mode on the lower level [Hz], [m].
    mode_match : float
        Modal assurance criterion between the two levels' modes at the probes [-] (1: same shape).
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
    """The spectral-element mesh of ``plate`` at a level (polynomial degree), following its geometry.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    level : int
        Polynomial degree along x, y and z [-].
    n_modes : int
        Eigenmodes to compute [-].
    piezo : str
        Piezo model.
    """
    mean_length = float(plate.ceramic_length) / ELEMENTS_PER_CERAMIC
    return FemSettings(
        elements_per_ceramic=ELEMENTS_PER_CERAMIC,
        elements_per_gap=ELEMENTS_PER_GAP,
        elements_per_layer=1,
        elements_across_half_width=max(3, math.ceil(float(plate.width) / 2 / (WIDTH_ELEMENT_RATIO * mean_length))),
        n_modes=n_modes,
        element=f"spectral-{level}-{level}-{level}",
        grading=GRADING,
        piezo=piezo,
    )


def richardson_error(fine: float, coarse: float, ratio: float, rate: float = RICHARDSON_RATE) -> float:
    """Estimated error v_fine - v_converged from two levels whose degrees differ by ``ratio`` (> 1).

    From v_k = v_converged + C k^-p: v_converged = v_fine + (v_fine - v_coarse) / (ratio^p - 1).
    """
    return (coarse - fine) / (ratio**rate - 1)


def extrapolated_limit(values, levels) -> tuple[float, float]:
    """(converged value, observed rate) of three levels' values under v_k = v_converged + C k^-r, r fitted to them.

    The reference against which the estimates are validated (it does not assume :data:`RICHARDSON_RATE`).

    Parameters
    ----------
    values : 3 floats
        The values at ``levels`` (ascending degrees), converging monotonically.
    levels : 3 ints
    """
    (a, b, c), (k0, k1, k2) = values, levels
    observed = (b - c) / (a - b)
    if not 0 < observed < 1:
        raise TactileError(f"the values {a}, {b}, {c} do not converge monotonically; no limit can be extrapolated")
    rate = brentq(lambda r: (k1**-r - k2**-r) / (k0**-r - k1**-r) - observed, 1e-3, 50.0)
    constant = (b - c) / (k1**-rate - k2**-rate)
    return c - constant * k2**-rate, rate


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
    """The lowest level predicted to meet ``target`` at rate p, at least one higher, at most ``max_level``."""
    higher = [n for n in LEVELS if level < n <= max_level]
    for n in higher:
        if abs(relative_error) * (level / n) ** RICHARDSON_RATE <= target:
            return n
    return higher[-1]


def evaluate_to_accuracy(plate: Plate, accuracy: FemAccuracy, evaluate_mesh: Callable, keep_solution: bool = False):
    """Raise the degree of the mesh of ``plate`` until the estimated frequency error meets ``accuracy.target``.

    Each step goes to the lowest degree predicted to meet the target at :data:`RICHARDSON_RATE` (:func:`next_level`),
    or one degree up after an estimate against a degree below :data:`ASYMPTOTIC_LEVEL`.

    Parameters
    ----------
    plate : Plate
        Scalar geometry [m].
    accuracy : FemAccuracy
    evaluate_mesh : callable
        (FemSettings, ModalSolution or None) -> FemResult for this plate (Q and voltage bound by the caller); the
        second argument is the lower level's ``solution``, to start its eigen solve.
    keep_solution : bool
        Return the final level's ``solution`` (in memory: e.g. to sample the top face without a new solve).
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
    coarse = evaluate_mesh(mesh_for_level(plate, coarse_level, accuracy.n_modes, accuracy.piezo), None)
    while True:
        fine = evaluate_mesh(mesh_for_level(plate, level, accuracy.n_modes, accuracy.piezo), coarse.solution)
        estimate = estimate_error(fine, coarse, level, coarse_level, accuracy.target)
        if estimate.met or level >= max_level:
            return replace(fine, error=estimate, solution=fine.solution if keep_solution else None)
        asymptotic = coarse_level >= ASYMPTOTIC_LEVEL
        coarse, coarse_level = fine, level
        level = next_level(level, estimate.frequency, accuracy.target, max_level if asymptotic else level + 1)


def _fits(plate: Plate, level: int, accuracy: FemAccuracy) -> bool:
    """Whether the mesh of ``level`` fits the memory budget (:func:`~workflow.models.fem.mesh.check_memory`)."""
    try:
        check_memory(plate, mesh_for_level(plate, level, accuracy.n_modes, accuracy.piezo))
    except MeshTooLargeError:
        return False
    return True
