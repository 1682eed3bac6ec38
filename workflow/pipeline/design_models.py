"""The plate models the design commands offer (``--model``), each one object with the same methods: ``evaluate``,
``optimize`` and ``maps`` look the model up by name (:data:`DESIGN_MODELS`) and call it, instead of switching on
the name.  The beam model and the FEM (eigenstrain or coupled, at an accuracy or on a mesh) differ in what they give
(the FEM also its modes, its error estimate, its electrical quantities) and in how their optimum is found (NLopt on
the beam; space mapping or NLopt on the FEM); both give their working mode as a
:class:`~workflow.models.response.PlateResponse`, so Q(v) is applied to either the same way
(:mod:`workflow.optimise.damped`).
"""

from dataclasses import dataclass
from functools import partial
from typing import Any, Optional

from workflow.models import analytical
from workflow.models.plate import Plate
from workflow.models.response import PlateResponse
from workflow.optimise.damped import DampedFemModel, DampedMaps, damped_beam_model, damped_maps, damped_optimum
from workflow.optimise.fem_optimum import optimise_fem
from workflow.optimise.maps import DesignMap, design_map
from workflow.optimise.problem import DesignProblem, Optimum, PlateModel, analytical_model, optimise_analytical
from workflow.pipeline.records import damping_record, fem_accuracy_record, fem_coupled_record, optimum_record
from workflow.units import KHZ, UM


@dataclass(frozen=True)
class Evaluation:
    """One geometry evaluated by a design model: its JSON keys and, for the FEM, its working mode.

    Attributes
    ----------
    record : dict
        ``w_dyn_um``, ``f_r_khz`` and what the model adds (error estimate, electrical keys, modes, Q(v)).
    working_mode : int or None
        Index of the mode whose deflection is reported (None for the beam model).
    """

    record: dict
    working_mode: Optional[int] = None


class DesignModel:
    """What the design models share: the optimum's record and the Q(v) design written once on each model's
    :meth:`response` (its working mode as a :class:`~workflow.models.response.PlateResponse`) and :meth:`search`
    (its optimiser, with constant Q or with a Q(v) law)."""

    name: str
    model_label: str
    """How a figure's title names the model."""

    def response(self, plate: Plate, voltage: float) -> PlateResponse:
        """The working mode of ``plate`` (a batch) at ``voltage`` [V peak]."""
        raise NotImplementedError

    def search(self, problem: DesignProblem, law=None, method: str = "space-mapping") -> tuple[Optimum, dict]:
        """(the optimum with the constant Q, or with the Q(v) ``law`` solved self-consistently, its record's extra
        keys: evaluation counts, the accurate check)."""
        raise NotImplementedError

    def optimum(self, problem: DesignProblem) -> Optimum:
        """The optimum with the constant Q."""
        return self.search(problem)[0]

    def optimum_record(self, problem: DesignProblem, posterior=None, method: str = "space-mapping") -> dict:
        """The optimum's JSON keys (constant Q, or the posterior-median Q(v) and its keys), with the evaluation
        counts and, for the FEM, the accurate check's error estimate."""
        optimum, extra = self.search(problem, None if posterior is None else posterior.median_law(), method)
        record = optimum_record(optimum, **extra)
        if posterior is not None:
            record.update(damping_record(posterior, self.response(optimum.plate, problem.voltage)))
        return record

    def damped(self, posterior, problem: DesignProblem, points: int, draws: int) -> tuple[Optimum, dict, DampedMaps]:
        """(optimum, its Q(v) keys, the maps) with the posterior-median Q(v) on a points x points grid."""
        optimum, _ = self.search(problem, posterior.median_law())
        response = partial(self.response, voltage=problem.voltage)
        maps = damped_maps(posterior, problem, points, draws=draws, optimum=optimum, response=response,
                           model_label=self.model_label)
        return optimum, damping_record(posterior, response(optimum.plate)), maps


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
        record = {"w_dyn_um": float(analytical.dynamic_deflection(plate, self.voltage, self.q)) / UM,
                  "f_r_khz": float(analytical.resonance_frequency(plate)) / KHZ}
        if posterior is not None:
            record.update(damping_record(posterior, self.response(plate, self.voltage)))
        return Evaluation(record)

    def search(self, problem: DesignProblem, law=None, method: str | None = None) -> tuple[Optimum, dict]:
        """NLopt on the beam model (``method`` unused: one optimiser)."""
        optimum = optimise_analytical(problem, self.q) if law is None else damped_optimum(law, problem)
        return optimum, {"coarse_evaluations": optimum.evaluations}

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
        record = {"w_dyn_um": result.deflection / UM, "f_r_khz": result.frequency / KHZ,
                  **fem_accuracy_record(result.error), **fem_coupled_record(result),
                  "modes": [{"f_khz": m.frequency / KHZ, "w_um": m.deflection / UM, "transverse": m.transverse_indicator}
                            for m in result.modes]}
        if posterior is not None:
            record.update(damping_record(posterior, result))
        return Evaluation(record, result.best_index)

    def search(self, problem: DesignProblem, law=None, method: str = "space-mapping") -> tuple[Optimum, dict]:
        """Space mapping (or NLopt, ``method``) on the FEM; with a Q(v) law the fine model is the FEM with Q(v) solved
        on each geometry's best mode and the coarse model the beam model with the same law."""
        if law is None:
            found = optimise_fem(problem, self.fem, method)
        else:
            fine = DampedFemModel(law, self.fem, problem.voltage)
            found = optimise_fem(problem, fine, method, coarse_model=damped_beam_model(law, problem.voltage))
        extra = dict(method=found.method, fine_evaluations=found.fine_evaluations,
                     coarse_evaluations=found.coarse_evaluations)
        if found.error is not None:
            extra.update(fem_accuracy_record(found.error), verified=found.verified,
                         verification_evaluations=found.verification_evaluations)
        return found.optimum, extra

    def design_map(self, problem: DesignProblem, points: int, optimum: Optimum) -> DesignMap:
        """w, f_r and every point's modes over a points x points (lambda, h_i) grid, one FEM batch."""
        return design_map(self.fem, problem, points, self.name, optimum, self.fem.results)


DESIGN_MODELS = {"analytical": BeamDesignModel, "fem": FemDesignModel}
"""``--model`` name -> its design model class."""
