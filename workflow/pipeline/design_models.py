"""The plate models the design commands offer (``--model``), each one object with the same methods: ``evaluate``,
``optimize`` and ``maps`` look the model up by name (:data:`DESIGN_MODELS`) and call it, instead of switching on
the name.  The beam model and the FEM (eigenstrain or coupled, at an accuracy or on a mesh) differ in what they give
(the FEM also its modes, its error estimate, its electrical quantities) and in how their optimum is found (NLopt on
the beam; space mapping or NLopt on the FEM); both give their working mode as a
:class:`~workflow.models.response.PlateResponse`, so Q(v) is applied to either the same way
(:mod:`workflow.optimise.damped`).
"""

from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Optional

from workflow.models import analytical
from workflow.models.plate import Plate
from workflow.models.response import PlateResponse
from workflow.optimise.damped import (
    DampedFemModel,
    DampedMaps,
    QOfV,
    damped_beam_model,
    damped_maps,
    damped_optimum,
    q_of_v,
)
from workflow.optimise.fem_optimum import FemOptimum, optimise_fem
from workflow.optimise.maps import DesignMap, design_map
from workflow.optimise.problem import DesignProblem, Optimum, PlateModel, analytical_model, optimise_analytical


@dataclass(frozen=True)
class Evaluation:
    """One geometry evaluated by a design model (SI; :func:`~workflow.pipeline.records.evaluation_record` gives its
    JSON keys).

    Attributes
    ----------
    model : str
        The design model's name (``--model``).
    plate : Plate
    q : float
        The constant quality factor the model evaluated with [-] (the FEM: it picks the working mode).
    voltage : float
        Drive amplitude [V peak].
    deflection, frequency : float
        Working mode's antinode deflection at ``q`` [m] and resonance [Hz].
    fem : FemResult or None
        The FEM's result (its modes, working mode, error estimate, electrical quantities); None for the beam model.
    q_of_v : QOfV or None
        The working mode with the fitted Q(v) (``--damping``).
    """

    model: str
    plate: Plate
    q: float
    voltage: float
    deflection: float
    frequency: float
    fem: Any = None
    q_of_v: Optional[QOfV] = None

    @property
    def working_mode(self) -> Optional[int]:
        """Index of the FEM mode whose deflection is reported (None for the beam model)."""
        return None if self.fem is None else self.fem.best_index


@dataclass(frozen=True)
class DesignOptimum:
    """An optimum found by a design model and what it cost (SI; :func:`~workflow.pipeline.records.design_optimum_record`
    gives its JSON keys).

    Attributes
    ----------
    optimum : Optimum
        With the constant Q, or with the Q(v) law solved self-consistently.
    coarse_evaluations : int
        Beam-model geometries evaluated [-].
    fem_search : FemOptimum or None
        The FEM's search: its method, FEM evaluation counts, the accurate check's error estimate and verdict.
    q_of_v : QOfV or None
        The optimum's working mode with the fitted Q(v) (the posterior's intervals).
    """

    optimum: Optimum
    coarse_evaluations: int
    fem_search: Optional[FemOptimum] = None
    q_of_v: Optional[QOfV] = None


class DesignModel:
    """What the design models share: the optimum with the posterior's intervals and the Q(v) maps, written once on
    each model's :meth:`response` (its working mode as a :class:`~workflow.models.response.PlateResponse`) and
    :meth:`search` (its optimiser, with constant Q or with a Q(v) law).  Results are typed (:class:`Evaluation`,
    :class:`DesignOptimum`, SI); their JSON keys are written by :mod:`workflow.pipeline.records`."""

    name: str
    model_label: str
    """How a figure's title names the model."""

    def response(self, plate: Plate, voltage: float) -> PlateResponse:
        """The working mode of ``plate`` (a batch) at ``voltage`` [V peak]."""
        raise NotImplementedError

    def search(self, problem: DesignProblem, law=None, method: str = "space-mapping") -> DesignOptimum:
        """The optimum with the constant Q, or with the Q(v) ``law`` solved self-consistently, and what it cost."""
        raise NotImplementedError

    def optimum(self, problem: DesignProblem) -> Optimum:
        """The optimum with the constant Q."""
        return self.search(problem).optimum

    def design_optimum(self, problem: DesignProblem, posterior=None, method: str = "space-mapping") -> DesignOptimum:
        """The optimum (constant Q, or the posterior-median Q(v) with the posterior's intervals at the optimum), with
        the evaluation counts and, for the FEM, the accurate check."""
        found = self.search(problem, None if posterior is None else posterior.median_law(), method)
        if posterior is None:
            return found
        return replace(found, q_of_v=q_of_v(posterior, self.response(found.optimum.plate, problem.voltage)))

    def damped(self, posterior, problem: DesignProblem, points: int, draws: int) -> tuple[DesignOptimum, DampedMaps]:
        """(the optimum with the posterior-median Q(v), the maps) on a points x points grid."""
        found = self.design_optimum(problem, posterior)
        maps = damped_maps(posterior, problem, points, draws=draws, optimum=found.optimum,
                           response=partial(self.response, voltage=problem.voltage), model_label=self.model_label)
        return found, maps


@dataclass(frozen=True)
class BeamDesignModel(DesignModel):
    """The calibrated beam model with constant Q (docs/model.md): analytical, vectorised, no discretisation error."""

    q: float
    voltage: float
    name = "analytical"
    label = "analytical"
    """How help texts name it."""
    model_label = "beam model"
    default_grid = 81
    """Points per axis of a map (a vectorised evaluation: fine grids cost nothing)."""
    sampled_grid = False
    """A map is one closed-form evaluation over the grid (its contours are exact between the points)."""
    resolves_width = False
    """The beam model does not depend on the plate's width b: no width sweep."""
    calibrated = False
    """A calibration corrects the FEM, not this model."""
    discretised = False
    """Closed form: no discretisation error to estimate."""

    @classmethod
    def for_command(cls, q: float, voltage: float, make_fem) -> "BeamDesignModel":
        """The model at Q [-] and ``voltage`` [V peak] (``make_fem``, the command's FEM factory, unused)."""
        return cls(q, voltage)

    @property
    def plate_model(self) -> PlateModel:
        return analytical_model(self.q, self.voltage)

    def response(self, plate: Plate, voltage: float) -> PlateResponse:
        return analytical.beam_response(plate, voltage)

    def evaluate(self, plate: Plate, posterior=None) -> Evaluation:
        damped = None if posterior is None else q_of_v(posterior, self.response(plate, self.voltage))
        return Evaluation(self.name, plate, self.q, self.voltage,
                          float(analytical.dynamic_deflection(plate, self.voltage, self.q)),
                          float(analytical.resonance_frequency(plate)), q_of_v=damped)

    def search(self, problem: DesignProblem, law=None, method: str | None = None) -> DesignOptimum:
        """NLopt on the beam model (``method`` unused: one optimiser)."""
        optimum = optimise_analytical(problem, self.q) if law is None else damped_optimum(law, problem)
        return DesignOptimum(optimum, optimum.evaluations)

    def design_map(self, problem: DesignProblem, points: int, optimum: Optimum) -> DesignMap:
        """w and f_r over a points x points (lambda, h_i) grid, one vectorised evaluation."""
        return design_map(self.plate_model, problem, points, self.name, optimum)


@dataclass(frozen=True)
class FemDesignModel(DesignModel):
    """The FEM (:class:`~workflow.optimise.fem_model.FemModel`: cached, refined to its accuracy or on a mesh)."""

    fem: Any
    name = "fem"
    label = "FEM"
    model_label = "FEM"
    default_grid = 12
    """Points per axis of a map (each point one FEM evaluation)."""
    sampled_grid = True
    """Each point of a map is its own evaluation: the contours interpolate between them (the figures mark them)."""
    resolves_width = True
    calibrated = True
    discretised = True
    """A mesh: its values carry a discretisation error (estimated when it runs to an accuracy)."""

    @classmethod
    def for_command(cls, q: float, voltage: float, make_fem) -> "FemDesignModel":
        """The command's FEM (``make_fem()``, at its Q and voltage)."""
        return cls(make_fem())

    @property
    def plate_model(self) -> PlateModel:
        return self.fem

    def response(self, plate: Plate, voltage: float) -> PlateResponse:
        return self.fem.response(plate, voltage)

    def evaluate(self, plate: Plate, posterior=None) -> Evaluation:
        from workflow.models.fem import evaluate_fem

        result = evaluate_fem(plate, q=self.fem.q, voltage=self.fem.voltage, settings=self.fem.settings)
        damped = None if posterior is None else q_of_v(posterior, result)
        return Evaluation(self.name, plate, self.fem.q, self.fem.voltage, result.deflection, result.frequency, result,
                          damped)

    def search(self, problem: DesignProblem, law=None, method: str = "space-mapping") -> DesignOptimum:
        """Space mapping (or NLopt, ``method``) on the FEM; with a Q(v) law the fine model is the FEM with Q(v) solved
        on each geometry's best mode and the coarse model the beam model with the same law."""
        if law is None:
            found = optimise_fem(problem, self.fem, method)
        else:
            fine = DampedFemModel(law, self.fem, problem.voltage)
            found = optimise_fem(problem, fine, method, coarse_model=damped_beam_model(law, problem.voltage))
        return DesignOptimum(found.optimum, found.coarse_evaluations, found)

    def design_map(self, problem: DesignProblem, points: int, optimum: Optimum) -> DesignMap:
        """w, f_r and every point's modes over a points x points (lambda, h_i) grid, one FEM batch."""
        return design_map(self.fem, problem, points, self.name, optimum, self.fem.results)


DESIGN_MODELS = {"analytical": BeamDesignModel, "fem": FemDesignModel}
"""``--model`` name -> its design model class."""
