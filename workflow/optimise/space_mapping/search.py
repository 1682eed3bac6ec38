"""The space-mapping search: one loop for both mappings, and what they share.

The loop (:func:`space_mapping_optimum`): the first fine point is the coarse optimum z*; then,
until it stops, the mapping is fitted to the fine points around an anchor, the surrogate (the
coarse model seen through the mapping) is maximised along its f_min curve over the candidate
thicknesses (within the trust interval around the anchor, feasible on the surrogate, away from
mixed modes), and its maximiser, placed on the surrogate's f_min curve at that thickness, is
the next fine point.  When the surrogate promises less than the gain tolerance over the best
feasible fine point (or a point the mapping counts as reached), the search ends once fine
points bracket that answer (for the mapping that asks for a bracket; else it evaluates the
missing side).  While the mapping is not determined (too few thicknesses), a proposal next to
an evaluated point is replaced by an exploring one.  A proposal that repeats an evaluated
point, the fine-evaluation budget or an empty surrogate end it too.  The answer is always a
fine point.

What differs between the two mappings (:class:`Mapping`): what one fine evaluation gives, how
the mapping is fitted, where new points are placed, the trust interval and its updates, the
candidate thicknesses, and when a proposal counts as reached or as a repeat.
"""

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from workflow.errors import InfeasibleError
from workflow.optimise.problem import DesignProblem, Optimum, maximise_deflection
from workflow.optimise.space_mapping.steps import FREQUENCY_TOLERANCE, FineStep
from workflow.units import MM

BISECTION_STEPS = 48
"""Bisection steps of the coarse wavelength at a given frequency [-] (1e-12 m)."""
REACH_SLACK_MM = 1e-12
"""Rounding slack of the trust interval's edge [mm]."""


@dataclass(frozen=True)
class Surrogate:
    """The coarse model seen through a mapping fitted around an anchor, on the h_i grid.

    Attributes
    ----------
    anchor : FineStep
        The fine step the mapping is centred on (the best feasible clean step, else one near the
        f_min curve: each mapping says which).
    anchor_log_deflection : float
        ln w of the anchor on the fine f_min curve [ln m].
    feasible : ndarray of bool
        Where the surrogate's f_min curve lies above the shortest wavelength.
    log_deflection : ndarray
        ln w along the surrogate's f_min curve, lambda clipped to its bounds [ln m].
    determined : bool
        Whether the mapping is determined (else the search explores).
    mapping : object
        The fitted mapping (what :meth:`Mapping.place` refits from).
    """

    anchor: FineStep
    anchor_log_deflection: float
    feasible: np.ndarray
    log_deflection: np.ndarray
    determined: bool
    mapping: object


@dataclass(frozen=True)
class Proposal:
    """A design about to be evaluated and what the search expected of it.

    Attributes
    ----------
    design : ndarray
        (lambda, h_i) [m].
    from_surrogate : bool
        Whether it maximises the surrogate (not a bracketing or exploring point).
    promised : float
        ln w the surrogate predicts there less ``reference`` [-].
    reference : float
        ln w of the best feasible fine point, or of the anchor on the curve when there is none [ln m].
    at_edge : bool
        Whether it lies at the edge of the trust interval.
    best : FineStep or None
        The best feasible fine point before it.
    determined : bool
        Whether the mapping that proposed it was determined.
    """

    design: np.ndarray
    from_surrogate: bool
    promised: float
    reference: float
    at_edge: bool
    best: FineStep | None
    determined: bool


class Mapping(Protocol):
    """The part of the search that differs: how the coarse model is mapped onto the fine one.

    Built per search as ``mapping(coarse, problem)``; ``thickness_mm`` is its h_i grid [mm].
    """

    thickness_mm: np.ndarray
    gain_tolerance: float
    what: str

    def evaluate(self, fine, design: np.ndarray) -> FineStep:
        """One fine evaluation at (lambda, h_i) [m] and what the mapping needs from it."""

    def best(self, steps) -> FineStep | None:
        """The answer so far: the best feasible fine step the mapping accepts."""

    def surrogate(self, steps) -> Surrogate:
        """The mapping fitted to ``steps`` and the surrogate on the grid."""

    def reach(self, steps, surrogate: Surrogate) -> float:
        """Half-width of the trust interval around the anchor [mm]."""

    def candidates(self, within: np.ndarray, steps, surrogate: Surrogate) -> np.ndarray:
        """Where on the grid the surrogate may propose, of the feasible thicknesses ``within`` reach [bool]."""

    def place(self, steps, surrogate: Surrogate, thickness_mm: float) -> np.ndarray:
        """The design (lambda, h_i) [m] on the surrogate's f_min curve at ``thickness_mm``."""

    def reached(self, thickness_mm: float, design: np.ndarray, best: FineStep, steps) -> bool:
        """Whether the surrogate's proposal (at h_i ``thickness_mm`` [mm]) counts as the point ``best`` already is."""

    def repeats(self, thickness_mm: float, design: np.ndarray, steps) -> bool:
        """Whether ``design`` (at h_i ``thickness_mm`` [mm]) was evaluated already (the search stops)."""

    def bracket_thickness(self, steps, best: FineStep, surrogate: Surrogate) -> float | None:
        """h_i [mm] of the missing bracket of ``best``, None when it is bracketed (or needs no bracket)."""

    def explores_instead_of(self, steps, thickness_mm: float | None) -> bool:
        """Whether an exploring point replaces the surrogate's proposal at ``thickness_mm`` [mm] (None: no
        proposal); asked only while the mapping is not determined."""

    def exploring_thickness(self, steps, surrogate: Surrogate) -> float | None:
        """An exploring h_i [mm], None when nothing is left to explore."""

    def learn(self, proposal: Proposal, step: FineStep) -> None:
        """Update the trust interval from what the step at ``proposal`` delivered."""


FineModel = Callable
"""fine(plate) -> the fine responses of one geometry (what the mapping's ``evaluate`` reads)."""


@dataclass(frozen=True)
class SpaceMappingResult:
    """Outcome of :func:`space_mapping_optimum`.

    Attributes
    ----------
    optimum : Optimum
        The best feasible fine point with its fine response (``evaluations`` = fine evaluations).
    coarse_optimum : Optimum
        The coarse model's optimum z*, the first fine point.
    trajectory : tuple of FineStep
        Every fine evaluation in order.
    fine_evaluations, coarse_evaluations : int
        Geometries evaluated by each model.
    converged : bool
        Whether the surrogate, fully determined, promised no further gain.
    """

    optimum: Optimum
    coarse_optimum: Optimum
    trajectory: tuple[FineStep, ...]
    fine_evaluations: int
    coarse_evaluations: int
    converged: bool


class CountedModel:
    """A plate model that counts the geometries it evaluates."""

    def __init__(self, model):
        self.model, self.evaluations = model, 0

    def __call__(self, plate):
        self.evaluations += int(np.prod(plate.batch_shape, dtype=int))
        return self.model(plate)


def coarse_wavelength(coarse, problem: DesignProblem, thickness, frequency) -> np.ndarray:
    """Wavelength [m] at which the coarse f_r equals ``frequency`` [Hz] at each h_i [m].

    Bisection on a wide bracket (f_r falls as lambda grows), vectorised over the inputs.
    """
    thickness, frequency = np.broadcast_arrays(np.asarray(thickness, dtype=float), np.asarray(frequency, dtype=float))
    low = np.full(thickness.shape, problem.wavelength_range[0] / 2)
    high = np.full(thickness.shape, problem.wavelength_range[1] * 2)
    for _ in range(BISECTION_STEPS):
        middle = 0.5 * (low + high)
        _, found = coarse(problem.plate(middle, thickness))
        above = found > frequency
        low, high = np.where(above, middle, low), np.where(above, high, middle)
    return 0.5 * (low + high)


def space_mapping_optimum(
    fine: FineModel, coarse, problem: DesignProblem, mapping: Callable[..., Mapping], max_fine_evaluations: int = 12
) -> SpaceMappingResult:
    """Maximise the fine deflection subject to the fine f_r >= f_min by space mapping.

    Parameters
    ----------
    fine : FineModel
        Expensive model, called with one geometry at a time (with the outputs ``mapping`` reads).
    coarse : PlateModel
        Cheap model of (deflection [m], frequency [Hz]), batched.
    problem : DesignProblem
    mapping : callable
        ``mapping(coarse, problem)`` -> :class:`Mapping`:
        :class:`~workflow.optimise.space_mapping.from_sensitivities.SensitivityMapping` for a fine
        model with design sensitivities,
        :class:`~workflow.optimise.space_mapping.from_responses.ResponseMapping` for one without.
    max_fine_evaluations : int
        Upper limit on fine evaluations.

    Returns
    -------
    SpaceMappingResult

    Raises
    ------
    InfeasibleError
        When no fine point the mapping accepts reached f_min.
    """
    fine, coarse = CountedModel(fine), CountedModel(coarse)
    coarse_optimum = maximise_deflection(coarse, problem)
    search = mapping(coarse, problem)
    grid_mm = search.thickness_mm
    start = np.array([coarse_optimum.plate.wavelength, coarse_optimum.plate.resonator_thickness], float)
    steps = [search.evaluate(fine, start)]
    converged = False
    while True:
        surrogate = search.surrogate(steps)
        if not np.any(surrogate.feasible):
            status = "stopped: no thickness reaches f_min on the surrogate"
            break
        best = search.best(steps)
        reach = search.reach(steps, surrogate)
        offset = grid_mm - surrogate.anchor.thickness_mm
        within = (np.abs(offset) <= reach + REACH_SLACK_MM) & surrogate.feasible
        candidates = search.candidates(within, steps, surrogate)
        index, proposal_mm, design, gain = None, None, None, -np.inf
        if np.any(candidates):
            index = int(np.nanargmax(np.where(candidates, surrogate.log_deflection, np.nan)))
            proposal_mm = grid_mm[index]
            design = search.place(steps, surrogate, proposal_mm)
            gain = surrogate.log_deflection[index] - np.log(best.deflection) if best is not None else np.inf
        thickness_mm = None  # of a bracketing or exploring point instead of the proposal
        if (  # nothing left to gain: stop once the answer is bracketed
            best is not None
            and surrogate.determined
            and (design is None or search.reached(proposal_mm, design, best, steps) or gain <= search.gain_tolerance)
        ):
            thickness_mm = search.bracket_thickness(steps, best, surrogate)
            if thickness_mm is None:
                converged, status = True, "converged"
                break
        if fine.evaluations >= max_fine_evaluations:
            status = f"stopped: {max_fine_evaluations} fine evaluations"
            break
        if not surrogate.determined and search.explores_instead_of(steps, proposal_mm):
            thickness_mm = search.exploring_thickness(steps, surrogate)
            if thickness_mm is None:
                status = "stopped: no unexplored thickness within reach"
                break
        from_surrogate = thickness_mm is None
        if not from_surrogate:
            proposal_mm, design = thickness_mm, search.place(steps, surrogate, thickness_mm)
        if design is None:
            status = "stopped: no thickness within reach reaches f_min on the surrogate"
            break
        if search.repeats(proposal_mm, design, steps):
            status = "stopped: the next point was evaluated already"
            break
        reference = np.log(best.deflection) if best is not None else surrogate.anchor_log_deflection
        proposal = Proposal(
            design,
            from_surrogate,
            surrogate.log_deflection[index] - reference if from_surrogate else np.nan,
            reference,
            from_surrogate and abs(offset[index]) >= reach - (grid_mm[1] - grid_mm[0]),
            best,
            surrogate.determined,
        )
        steps.append(search.evaluate(fine, design))
        search.learn(proposal, steps[-1])
    return _result(steps, search, problem, fine, coarse, coarse_optimum, status, converged)


def _result(steps, search: Mapping, problem, fine, coarse, coarse_optimum, status: str, converged: bool):
    """The :class:`SpaceMappingResult` whose answer is the mapping's best fine step.

    Raises
    ------
    InfeasibleError
        When there is none (no fine point the mapping accepts reached f_min).
    """
    answer = search.best(steps)
    if answer is None:
        closest = max(steps, key=lambda s: s.frequency)
        raise InfeasibleError(
            f"space mapping found no {search.what} with f_r >= {problem.min_frequency / 1e3:g} kHz in "
            f"{fine.evaluations} fine evaluations (highest {closest.frequency / 1e3:.3f} kHz at lambda "
            f"{closest.design[0] / MM:.3f} mm, h_i {closest.thickness_mm:.3f} mm); widen the bounds or lower f_min"
        )
    optimum = Optimum(
        plate=problem.plate(float(answer.design[0]), float(answer.design[1])),
        deflection=answer.deflection,
        frequency=answer.frequency,
        evaluations=fine.evaluations,
        constraint_active=bool(abs(answer.frequency / problem.min_frequency - 1) <= FREQUENCY_TOLERANCE),
        status=status,
    )
    return SpaceMappingResult(optimum, coarse_optimum, tuple(steps), fine.evaluations, coarse.evaluations, converged)
