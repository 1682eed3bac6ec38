"""The FEM optimum (docs/fem.md): direct NLopt from the beam optimum, or space mapping.

Space mapping (:mod:`workflow.optimise.space_mapping`) maps the beam onto the FEM with the FEM's
design sensitivities when the fine model has them (the plain FEM) and from its responses only
otherwise (e.g. the FEM with Q(v)).
"""

from dataclasses import dataclass

import numpy as np

from workflow.optimise.problem import (
    DesignProblem,
    Optimum,
    PlateModel,
    analytical_model,
    maximise_deflection,
)
from workflow.optimise.space_mapping import ResponseMapping, SensitivityMapping, space_mapping_optimum

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


@dataclass(frozen=True)
class FemOptimum:
    """An FEM optimum and what it cost.

    Attributes
    ----------
    optimum : Optimum
    method : str
        One of :data:`METHODS`.
    fine_evaluations, coarse_evaluations : int
        FEM and beam-model geometries evaluated.
    trajectory : tuple of FineStep
        The FEM points of a space-mapping search in evaluation order (empty for the direct run).
    """

    optimum: Optimum
    method: str
    fine_evaluations: int
    coarse_evaluations: int
    trajectory: tuple = ()


def optimise_fem(
    problem: DesignProblem,
    fem_model,
    method: str = "space-mapping",
    q: float | None = None,
    coarse_model: PlateModel | None = None,
) -> FemOptimum:
    """Maximise the FEM deflection subject to the FEM f_r >= f_min.

    Parameters
    ----------
    problem : DesignProblem
    fem_model : PlateModel
        Usually a :class:`~workflow.optimise.fem_model.FemModel` (its ``q`` is used when ``q`` is None).
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
        if hasattr(fem_model, "responses_with_gradients"):  # the FEM: exact design sensitivities
            fine, mapping = fem_model.responses_with_gradients, SensitivityMapping
        else:  # e.g. the FEM with Q(v): responses only, with the transverse indicator when there is one
            fine, mapping = getattr(fem_model, "responses", fem_model), ResponseMapping
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
