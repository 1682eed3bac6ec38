"""Space-mapping optimisation: the FEM optimum from a handful of FEM evaluations (SPEC 5 (b)).

The coarse model (the beam) is cheap, the fine model (the FEM) is not.  Both are
:data:`~workflow.optimize.PlateModel` callables; the design variables are x = (lambda, h_i)
in millimetres, the responses r(x) = (ln w, ln f).

Why not the textbook extraction.  Aggressive space mapping (Bandler) extracts
P(x) = argmin_z |r_c(z) - r_f(x)| and solves P(x) = z* by Broyden iterations.  Here that
extraction is ill-posed exactly where it matters: at the coarse constrained optimum z* the
gradients of w and f are parallel (the KKT condition of an active frequency constraint), so
the map z -> (w, f) folds at z* (its Jacobian determinant vanishes: 0.01 for h_p = 1 mm) and
the deflection a FEM point reaches at 25 kHz can lie outside every deflection the beam reaches
at 25 kHz; P is then not unique, and P(x) = z* is not the fine optimum.

What this module does instead (space mapping with a Broyden-updated mapping; Koziel, Bandler
and Madsen's general space-mapping framework, output mapping with first-order correction):
at every fine point x_k the mapping parameters are extracted so that the surrogate

    s_k(x) = r_c(x) + d_k + E_k (x - x_k),        d_k = r_f(x_k) - r_c(x_k)

reproduces the fine response at x_k exactly (zero order), and the mapping Jacobian E_k
(2 x 2, E_0 = 0, i.e. the coarse model's sensitivities) is updated by Broyden's rank-one
formula from the fine and coarse changes along each step.  The next point maximises the
surrogate deflection subject to the surrogate frequency >= f_min within the bounds (and a
trust box around x_k).  When the steps vanish the surrogate matches the fine model's value
and slope at x_k, so x_k satisfies the fine model's KKT conditions: it is the fine
constrained optimum, including the resonance constraint and any active bound (h_i = 0.5 mm
for h_p = 0.5 mm).  The first point is the coarse optimum z*; the coarse model's curvature
does the rest, which takes 3 to 5 fine evaluations.
"""

from dataclasses import dataclass, field
from typing import Tuple

import numpy as np

from .optimize import DesignProblem, Optimum, PlateModel, maximise_deflection
from .units import MM

TRUST_FRACTION = 0.1
"""Initial (and largest) trust box half-width, as a fraction of each variable's range [-]."""
PENALTY = 20.0
"""Weight of the frequency shortfall in the merit that accepts or rejects a step [-]."""
FREQUENCY_TOLERANCE = 1e-3
"""Relative distance to f_min within which the frequency constraint counts as active [-]."""
PROBE_FRACTION = 0.01
"""Length of a probing step, as a fraction of each variable's range [-]."""
COVERAGE = 0.3
"""Smallest singular value of (free directions)^T (unit steps) that counts as explored [-]."""


@dataclass(frozen=True)
class SpaceMappingStep:
    """One fine evaluation of the iteration.

    Attributes
    ----------
    design : ndarray
        (lambda, h_i) [m].
    deflection, frequency : float
        Fine response [m], [Hz].
    coarse_deflection, coarse_frequency : float
        Coarse response at the same design [m], [Hz].
    """

    design: np.ndarray
    deflection: float
    frequency: float
    coarse_deflection: float
    coarse_frequency: float


@dataclass(frozen=True)
class SpaceMappingResult:
    """Outcome of :func:`space_mapping_optimum`.

    Attributes
    ----------
    optimum : Optimum
        The last fine point with its fine response (``evaluations`` = fine evaluations).
    coarse_optimum : Optimum
        The coarse model's optimum z*, the starting point.
    trajectory : tuple of SpaceMappingStep
        Every fine evaluation in order.
    fine_evaluations, coarse_evaluations : int
        Geometries evaluated by each model.
    mapping_jacobian : ndarray
        The final Broyden estimate E of d(r_f - r_c)/dx [1/mm].
    converged : bool
        Whether the last step was below the tolerance.
    """

    optimum: Optimum
    coarse_optimum: Optimum
    trajectory: Tuple[SpaceMappingStep, ...]
    fine_evaluations: int
    coarse_evaluations: int
    mapping_jacobian: np.ndarray = field(repr=False)
    converged: bool


class _Counted:
    """A plate model that counts the geometries it evaluates."""

    def __init__(self, model: PlateModel):
        self.model, self.evaluations = model, 0

    def __call__(self, plate):
        self.evaluations += int(np.size(np.broadcast(plate.wavelength, plate.resonator_thickness)))
        return self.model(plate)


def _log_response(model: PlateModel, problem: DesignProblem, x_mm: np.ndarray) -> np.ndarray:
    """(ln w, ln f) of one design x [mm] as a vector."""
    deflection, frequency = model(problem.plate(np.atleast_1d(x_mm[0] * MM), np.atleast_1d(x_mm[1] * MM)))
    return np.log([float(np.ravel(deflection)[0]), float(np.ravel(frequency)[0])])


def _surrogate(coarse: PlateModel, offset: np.ndarray, jacobian: np.ndarray, centre_mm: np.ndarray) -> PlateModel:
    """s(x) = r_c(x) + offset + jacobian (x - centre), as a plate model."""

    def model(plate):
        deflection, frequency = coarse(plate)
        shift = np.stack(
            [np.asarray(plate.wavelength) / MM - centre_mm[0], np.asarray(plate.resonator_thickness) / MM - centre_mm[1]]
        )
        correction = offset[:, None] + jacobian @ shift.reshape(2, -1)
        return deflection * np.exp(correction[0]), frequency * np.exp(correction[1])

    return model


def _merit(log_response: np.ndarray, problem: DesignProblem) -> float:
    """ln w minus :data:`PENALTY` times the relative shortfall of f below f_min [-]."""
    return float(log_response[0] - PENALTY * max(0.0, np.log(problem.min_frequency) - log_response[1]))


def _trust_problem(problem: DesignProblem, centre_mm: np.ndarray, fraction: float) -> DesignProblem:
    """The problem restricted to a box of ``fraction`` of the ranges around x [mm]."""
    radius = fraction * (problem.upper - problem.lower)
    low = np.maximum(problem.lower, centre_mm * MM - radius)
    high = np.minimum(problem.upper, centre_mm * MM + radius)
    return DesignProblem(
        ceramic_thickness=problem.ceramic_thickness,
        width=problem.width,
        voltage=problem.voltage,
        min_frequency=problem.min_frequency,
        min_resonator_thickness=float(low[1]),
        max_resonator_thickness=float(high[1]),
        wavelength_range=(float(low[0]), float(high[0])),
    )


def _unit(step_mm: np.ndarray, problem: DesignProblem) -> np.ndarray:
    """A step [mm] as a unit vector in range-normalised coordinates."""
    scaled = step_mm * MM / (problem.upper - problem.lower)
    return scaled / np.linalg.norm(scaled)


def _free_directions(model: PlateModel, problem: DesignProblem, x_mm: np.ndarray) -> np.ndarray:
    """Orthonormal basis (columns, range-normalised) of the directions no active constraint fixes at x."""
    span = problem.upper - problem.lower
    active = [np.eye(2)[i] for i in range(2) if min(abs(x_mm[i] * MM - problem.lower[i]), abs(x_mm[i] * MM - problem.upper[i])) <= 1e-6 * span[i]]
    step = 1e-6
    points = x_mm * MM + np.array([[step, 0], [-step, 0], [0, step], [0, -step]]) * span
    _, frequency = model(problem.plate(points[:, 0], points[:, 1]))
    _, frequency_here = model(problem.plate(np.atleast_1d(x_mm[0] * MM), np.atleast_1d(x_mm[1] * MM)))
    if abs(float(np.ravel(frequency_here)[0]) / problem.min_frequency - 1) <= 1e-6:
        active.append(np.array([frequency[0] - frequency[1], frequency[2] - frequency[3]]))
    if not active:
        return np.eye(2)
    _, singular, rows = np.linalg.svd(np.array(active))
    rank = int(np.sum(singular > 1e-9 * singular[0]))
    return rows[rank:].T


def _least_explored(free: np.ndarray, directions: list):
    """The free direction the past steps cover least, or None when all are covered."""
    if free.shape[1] == 0:
        return None
    if not directions:
        return free[:, 0]
    left, singular, _ = np.linalg.svd(free.T @ np.array(directions).T, full_matrices=True)
    covered = np.zeros(free.shape[1])
    covered[: len(singular)] = singular
    weakest = int(np.argmin(covered))
    return None if covered[weakest] >= COVERAGE else free @ left[:, weakest]


def _probe(model: PlateModel, problem: DesignProblem, x_mm: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """A short step from x [mm] along ``direction`` (range-normalised), uphill in the model's deflection."""
    span_mm = (problem.upper - problem.lower) / MM
    candidates = np.array([x_mm + sign * PROBE_FRACTION * direction * span_mm for sign in (1, -1)])
    candidates = np.clip(candidates, problem.lower / MM, problem.upper / MM)
    deflection, _ = model(problem.plate(candidates[:, 0] * MM, candidates[:, 1] * MM))
    return candidates[int(np.argmax(deflection))]


def space_mapping_optimum(
    fine: PlateModel,
    coarse: PlateModel,
    problem: DesignProblem,
    tolerance: float = 0.005 * MM,
    max_fine_evaluations: int = 12,
    merit_tolerance: float = 1e-4,
) -> SpaceMappingResult:
    """Maximise the fine deflection subject to the fine f_r >= f_min by space mapping.

    Parameters
    ----------
    fine, coarse : PlateModel
        Expensive and cheap models of (deflection [m], frequency [Hz]); the fine one is
        called with one geometry at a time.
    problem : DesignProblem
    tolerance : float
        Stop when the next step is shorter than this in both variables [m].
    max_fine_evaluations : int
        Upper limit on fine evaluations.
    merit_tolerance : float
        Stop when the surrogate promises less than this gain of the merit
        (ln w less the frequency-shortfall penalty) [-], 1e-4 being 0.01 % of deflection.

    Returns
    -------
    SpaceMappingResult
    """
    fine, coarse = _Counted(fine), _Counted(coarse)
    coarse_optimum = maximise_deflection(coarse, problem)
    x = np.array([coarse_optimum.plate.wavelength, coarse_optimum.plate.resonator_thickness]) / MM
    centre = (x, _log_response(fine, problem, x), _log_response(coarse, problem, x))
    trajectory = [SpaceMappingStep(x * MM, *np.exp(centre[1]), *np.exp(centre[2]))]
    jacobian, directions, radius, converged = np.zeros((2, 2)), [], TRUST_FRACTION, False
    while fine.evaluations < max_fine_evaluations and radius * np.min(problem.upper - problem.lower) > tolerance:
        x, fine_response, coarse_response = centre
        surrogate = _surrogate(coarse, fine_response - coarse_response, jacobian, x)
        following = maximise_deflection(surrogate, _trust_problem(problem, x, radius), start=x * MM)
        x_next = np.array([following.plate.wavelength, following.plate.resonator_thickness]) / MM
        predicted_gain = _merit(_log_response(surrogate, problem, x_next), problem) - _merit(fine_response, problem)
        if predicted_gain <= merit_tolerance or np.all(np.abs(x_next - x) * MM <= tolerance):
            unexplored = _least_explored(_free_directions(surrogate, problem, x_next), directions)
            if unexplored is None:
                converged = True
                break
            x_next = _probe(surrogate, problem, x, unexplored)
        next_fine, next_coarse = _log_response(fine, problem, x_next), _log_response(coarse, problem, x_next)
        trajectory.append(SpaceMappingStep(x_next * MM, *np.exp(next_fine), *np.exp(next_coarse)))
        step = x_next - x
        change = (next_fine - fine_response) - (next_coarse - coarse_response)
        jacobian = jacobian + np.outer(change - jacobian @ step, step) / (step @ step)
        directions.append(_unit(step, problem))
        if _merit(next_fine, problem) > _merit(fine_response, problem):
            centre = (x_next, next_fine, next_coarse)
        else:
            radius /= 2
    x, fine_response, _ = centre
    deflection, frequency = np.exp(fine_response)
    optimum = Optimum(
        plate=problem.plate(float(x[0] * MM), float(x[1] * MM)),
        deflection=float(deflection),
        frequency=float(frequency),
        evaluations=fine.evaluations,
        constraint_active=bool(abs(frequency / problem.min_frequency - 1) <= FREQUENCY_TOLERANCE),
        status="converged" if converged else "stopped: trust region collapsed or maximum fine evaluations",
    )
    return SpaceMappingResult(
        optimum=optimum,
        coarse_optimum=coarse_optimum,
        trajectory=tuple(trajectory),
        fine_evaluations=fine.evaluations,
        coarse_evaluations=coarse.evaluations,
        mapping_jacobian=jacobian,
        converged=converged,
    )
