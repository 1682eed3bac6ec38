"""The FEM optimum (docs/fem.md): direct NLopt from the beam optimum, or space mapping.

Space mapping (:mod:`workflow.optimise.space_mapping`) maps the beam onto the FEM with the FEM's
design sensitivities when the fine model has them (the plain FEM) and from its responses only
otherwise (e.g. the FEM with Q(v)).
"""

from dataclasses import dataclass, replace

import numpy as np

from workflow.models.fem.accuracy import LEVELS, ErrorEstimate, FemAccuracy, mesh_for_level

from workflow.optimise.problem import (
    DesignProblem,
    Optimum,
    PlateModel,
    analytical_model,
    maximise_deflection,
)
from workflow.optimise.space_mapping import ResponseMapping, space_mapping_optimum

METHODS = ("nlopt", "space-mapping")
"""Ways to reach the FEM optimum."""

DIRECT_RELATIVE_STEP = 1e-4
"""Forward-difference step of the direct run, relative to each bound's span [-] (2.5 um on lambda)."""
DIRECT_XTOL = 1e-4
"""Relative tolerance on (lambda, h_i) of the direct run [-]."""
DIRECT_CONSTRAINT_TOLERANCE = 1e-5
"""Accepted relative shortfall of f_r in the direct run [-] (0.25 Hz: forward differences are noisy)."""
DIRECT_MAX_ITERATIONS = 100
"""Cap on SLSQP iterations of the direct run (each costs 3 FEM evaluations) [-]."""
VERIFICATION_ROUNDS = 3
"""Most searches (each corrected by the accurate evaluation of the last optimum) before an FEM optimum
is returned unverified [-]."""
VERIFICATION_TOLERANCE = 1e-4
"""Accepted relative shortfall of a verified optimum's frequency on its margin [-]: 2.5 Hz at 25 kHz,
well inside the margin itself (the estimated error, typically 0.1-0.2 %)."""
SETTLE_TOLERANCE = 5e-4
"""A verified optimum more than this above its margin (relative; 12.5 Hz at 25 kHz) gives away deflection:
the search is repeated with the offset measured there (within :data:`VERIFICATION_ROUNDS`)."""


def search_level(accuracy: FemAccuracy) -> int:
    """Mesh level (polynomial degree) of the search: the one below the accuracy's first level [-].

    3 for targets under 0.5 %, 2 for coarser ones; the search only needs to be smooth in the geometry,
    its offset from the accurate model is measured and corrected.
    """
    return LEVELS[LEVELS.index(accuracy.start_level) - 1]


@dataclass(frozen=True)
class FemOptimum:
    """An FEM optimum and what it cost.

    Attributes
    ----------
    optimum : Optimum
    method : str
        One of :data:`METHODS`.
    fine_evaluations, coarse_evaluations : int
        FEM (on the search mesh when the model has an accuracy) and beam-model geometries evaluated.
    trajectory : tuple of FineStep
        The FEM points of a space-mapping search in evaluation order (empty for the direct run).
    error : ErrorEstimate or None
        Discretisation error of the optimum, from its evaluation at the requested accuracy
        (None when the model ran on a fixed mesh).
    verified : bool
        The optimum's frequency, less its estimated error, meets the limit on the converged model
        (always False on a fixed mesh, where nothing is verified).
    verification_evaluations : int
        Evaluations at the requested accuracy (start point and each search's optimum) [-].
    """

    optimum: Optimum
    method: str
    fine_evaluations: int
    coarse_evaluations: int
    trajectory: tuple = ()
    error: ErrorEstimate | None = None
    verified: bool = False
    verification_evaluations: int = 0


def margin_frequency(min_frequency: float, relative_error: float) -> float:
    """The frequency a mesh must show so that the converged f_r clears ``min_frequency`` by the error [Hz].

    With f_n = f_converged (1 + e): f_n >= f_min (1 + e + |e|).
    """
    return min_frequency * (1 + relative_error + abs(relative_error))


def optimise_fem(
    problem: DesignProblem,
    fem_model,
    method: str = "space-mapping",
    q: float | None = None,
    coarse_model: PlateModel | None = None,
) -> FemOptimum:
    """Maximise the FEM deflection subject to the FEM f_r >= f_min, verified at the model's accuracy.

    When the model evaluates to an accuracy (``fem_model.settings`` a
    :class:`~workflow.models.fem.accuracy.FemAccuracy`), the search runs on one fixed coarse mesh
    (:func:`search_level`: cheap, and smooth in the geometry) whose frequency limit is
    corrected by the coarse mesh's offset from the accurate evaluation at the current point and
    raised by that evaluation's error estimate (:func:`margin_frequency`).  The optimum is then
    evaluated at the requested accuracy; while its frequency misses the margin, the offset is
    measured there and the search repeated (at most :data:`VERIFICATION_ROUNDS` times); so it is when it
    clears the margin by more than :data:`SETTLE_TOLERANCE`, which would give away deflection.
    Parameters as :func:`optimise_fem_on_mesh`.
    """
    accuracy = fem_model.settings
    if not accuracy.refines:
        return optimise_fem_on_mesh(problem, fem_model, method, q, coarse_model)
    if coarse_model is None:
        coarse_model = analytical_model(fem_model.q if q is None else q, problem.voltage)
    plate = maximise_deflection(coarse_model, problem).plate
    search = fem_model.on_mesh(mesh_for_level(plate, search_level(accuracy), accuracy.n_modes, accuracy.piezo))
    (check,) = fem_model.results(plate)
    fine_evaluations, coarse_evaluations, checks, trajectory = 0, 0, 1, ()
    for _ in range(VERIFICATION_ROUNDS):
        offset = float(search(plate)[1][()]) / check.frequency
        limit = margin_frequency(problem.min_frequency, check.error.frequency) * offset
        found = optimise_fem_on_mesh(replace(problem, min_frequency=limit), search, method, q, coarse_model)
        fine_evaluations += found.fine_evaluations
        coarse_evaluations += found.coarse_evaluations
        trajectory += found.trajectory
        plate = found.optimum.plate
        (check,) = fem_model.results(plate)
        checks += 1
        margin = margin_frequency(problem.min_frequency, check.error.frequency)
        verified = check.frequency >= margin * (1 - VERIFICATION_TOLERANCE)
        if verified and check.frequency <= margin * (1 + SETTLE_TOLERANCE):
            break
    optimum = replace(found.optimum, deflection=check.deflection, frequency=check.frequency)
    return FemOptimum(
        optimum, method, fine_evaluations, coarse_evaluations, trajectory, check.error, verified, checks
    )


@dataclass(frozen=True)
class ResponsesModel:
    """A fine model given by its responses alone (deflection [m], frequency [Hz], optionally the transverse
    indicator [-], batched over the plate's arrays), for space mapping from the responses or a direct NLopt run."""

    responses: object

    def space_mapping_fine(self) -> tuple:
        return self.responses, ResponseMapping

    def __call__(self, plate):
        return self.responses(plate)[:2]


def optimise_fem_on_mesh(
    problem: DesignProblem,
    fem_model,
    method: str = "space-mapping",
    q: float | None = None,
    coarse_model: PlateModel | None = None,
) -> FemOptimum:
    """Maximise the FEM deflection subject to the FEM f_r >= f_min, on the model as it is.

    Parameters
    ----------
    problem : DesignProblem
    fem_model : PlateModel
        With ``space_mapping_fine()`` -> (fine model, mapping): a :class:`~workflow.optimise.fem_model.FemModel` (its
        ``q`` is used when ``q`` is None), the FEM with Q(v) (:class:`~workflow.optimise.damped.DampedFemModel`) or
        any responses function wrapped as :class:`ResponsesModel`.
    method : {"nlopt", "space-mapping"}
    q : float, optional
        Quality factor of the coarse (beam) model [-]; ignored when ``coarse_model`` is given.
    coarse_model : PlateModel, optional
        The cheap model (space mapping's coarse model, the direct run's start); default the
        beam model at ``q`` (e.g. give the beam model with Q(v) for a FEM with Q(v)).
    """
    if coarse_model is None:
        coarse_model = analytical_model(fem_model.q if q is None else q, problem.voltage)
    if method == "space-mapping":
        fine, mapping = fem_model.space_mapping_fine()
        result = space_mapping_optimum(fine, coarse_model, problem, mapping)
        return FemOptimum(result.optimum, method, result.fine_evaluations, result.coarse_evaluations, result.trajectory)
    if method == "nlopt":
        coarse = maximise_deflection(coarse_model, problem)
        start = np.array([coarse.plate.wavelength, coarse.plate.resonator_thickness])
        direct = maximise_deflection(
            fem_model,
            problem,
            start=start,
            xtol_rel=DIRECT_XTOL,
            relative_step=DIRECT_RELATIVE_STEP,
            difference="forward",
            constraint_tolerance=DIRECT_CONSTRAINT_TOLERANCE,
            max_evaluations=DIRECT_MAX_ITERATIONS,
        )
        return FemOptimum(direct, method, direct.evaluations, coarse.evaluations)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")
