"""Constrained maximisation of the deflection with NLopt (docs/model.md).

The design variables are x = (lambda, h_i); h_p, b and the drive voltage are fixed by a
:class:`DesignProblem`.  The optimiser takes any plate model as a callable

    model(plate) -> (deflection [m], resonance frequency [Hz])

that accepts a :class:`Plate` whose wavelength and resonator thickness are 1-D arrays (a
batch of candidate geometries), so the beam model, the FEM and the designs with Q(v) all
go through the same code.  Gradients come from finite differences evaluated as one batch.
"""

from dataclasses import dataclass
from typing import Callable, Optional, Tuple

import nlopt
import numpy as np

from workflow.errors import InfeasibleError
from workflow.models import analytical, materials
from workflow.models.plate import ORIGINAL_PLATE, Plate, check_design_space
from workflow.units import MM

PlateModel = Callable[[Plate], Tuple[np.ndarray, np.ndarray]]
"""model(plate) -> (deflection [m], resonance frequency [Hz]), batched over the plate's arrays."""


FREQUENCY_SLACK = 1e-6
"""Relative shortfall of f_r below its limit still counted as on it [-] (0.025 Hz at 25 kHz)."""


@dataclass(frozen=True)
class DesignProblem:
    """Maximise the deflection over (lambda, h_i) with f_r >= ``min_frequency``.

    Attributes
    ----------
    ceramic_thickness : float
        h_p [m], one of the commercial sizes.
    width : float
        b [m].
    voltage : float
        Drive amplitude across the ceramics [V peak].
    min_frequency : float
        Lowest acceptable resonance frequency [Hz].
    min_resonator_thickness : float
        Lower bound on h_i [m] (the practical minimum by default).
    max_resonator_thickness : float
        Upper bound on h_i [m].
    wavelength_range : tuple of float
        Bounds on lambda [m].
    build : Plate
        The plate whose materials, glue and number of ceramics the designs share (the paper's by default).
    """

    ceramic_thickness: float
    width: float = ORIGINAL_PLATE.width
    voltage: float = materials.DESIGN_VOLTAGE
    min_frequency: float = materials.MIN_FREQUENCY
    min_resonator_thickness: float = materials.PRACTICAL_MIN_RESONATOR_THICKNESS
    max_resonator_thickness: float = materials.RESONATOR_THICKNESS_RANGE[1]
    wavelength_range: Tuple[float, float] = materials.WAVELENGTH_RANGE
    build: Plate = ORIGINAL_PLATE

    def __post_init__(self):
        check_design_space(self.plate(np.mean(self.wavelength_range), self.max_resonator_thickness))
        check_design_space(self.plate(np.mean(self.wavelength_range), self.min_resonator_thickness))

    @property
    def lower(self) -> np.ndarray:
        """Lower bounds of (lambda, h_i) [m]."""
        return np.array([self.wavelength_range[0], self.min_resonator_thickness])

    @property
    def upper(self) -> np.ndarray:
        """Upper bounds of (lambda, h_i) [m]."""
        return np.array([self.wavelength_range[1], self.max_resonator_thickness])

    def plate(self, wavelength, resonator_thickness) -> Plate:
        """The plate at design point (lambda, h_i) [m], built like :attr:`build`."""
        return self.build.with_(
            wavelength=wavelength,
            resonator_thickness=resonator_thickness,
            ceramic_thickness=self.ceramic_thickness,
            width=self.width,
        )


@dataclass(frozen=True)
class Optimum:
    """Result of a constrained maximisation.

    Attributes
    ----------
    plate : Plate
        The optimal geometry.
    deflection : float
        Deflection amplitude at the optimum [m].
    frequency : float
        Resonance frequency at the optimum [Hz].
    evaluations : int
        Geometries the model evaluated (every finite-difference point counts).
    constraint_active : bool
        Whether f_r sits on its lower limit (within :data:`FREQUENCY_SLACK`, or the constraint tolerance).
    status : str
        NLopt's stopping reason.
    """

    plate: Plate
    deflection: float
    frequency: float
    evaluations: int
    constraint_active: bool
    status: str


def analytical_model(q: float = materials.PLATE_Q, voltage: float = materials.DESIGN_VOLTAGE) -> PlateModel:
    """The calibrated beam model with constant Q as a :data:`PlateModel`."""

    def model(plate: Plate):
        return analytical.dynamic_deflection(plate, voltage, q), analytical.resonance_frequency(plate)

    return model


class _CountingModel:
    """Wraps a model, counts the geometries it evaluates."""

    def __init__(self, model: PlateModel, problem: DesignProblem):
        self.model, self.problem, self.evaluations = model, problem, 0

    def __call__(self, points: np.ndarray):
        """points: (k, 2) array of (lambda, h_i) [m] -> (deflection, frequency) arrays of shape (k,)."""
        self.evaluations += len(points)
        deflection, frequency = self.model(self.problem.plate(points[:, 0], points[:, 1]))
        return np.broadcast_to(deflection, len(points)), np.broadcast_to(frequency, len(points))


def feasible_start(model: PlateModel, problem: DesignProblem, grid: int = 41) -> np.ndarray:
    """The best feasible (lambda, h_i) of a ``grid`` x ``grid`` scan of the bounds [m].

    Raises
    ------
    InfeasibleError
        When no grid point satisfies the frequency constraint.
    """
    axes = [np.linspace(low, high, grid) for low, high in zip(problem.lower, problem.upper)]
    points = np.column_stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")])
    counting = model if isinstance(model, _CountingModel) else _CountingModel(model, problem)
    deflection, frequency = counting(points)
    feasible = frequency >= problem.min_frequency
    if not feasible.any():
        raise InfeasibleError(
            f"no feasible design for h_p = {problem.ceramic_thickness / MM:g} mm: the highest resonance in the "
            f"bounds is {frequency.max() / 1e3:.2f} kHz < {problem.min_frequency / 1e3:g} kHz; "
            "allow thicker resonators or shorter wavelengths"
        )
    return points[np.argmax(np.where(feasible, deflection, -np.inf))]


def maximise_deflection(
    model: PlateModel,
    problem: DesignProblem,
    start: Optional[np.ndarray] = None,
    xtol_rel: float = 1e-8,
    relative_step: float = 1e-6,
    difference: str = "central",
    max_evaluations: int = 2000,
    constraint_tolerance: float = 1e-9,
) -> Optimum:
    """Maximise the deflection subject to f_r >= f_min with NLopt's SLSQP.

    Parameters
    ----------
    model : PlateModel
        Deflection and frequency of a batch of geometries.
    problem : DesignProblem
    start : array of 2 floats, optional
        Starting (lambda, h_i) [m]; by default the best feasible point of a grid scan.
    xtol_rel : float
        Relative tolerance on (lambda, h_i).
    relative_step : float
        Finite-difference step relative to each bound's span.
    difference : {"central", "forward"}
        Finite-difference scheme (forward halves the evaluations of an expensive model).
    max_evaluations : int
        Upper limit on optimiser iterations.
    constraint_tolerance : float
        Accepted relative violation of f_r >= f_min [-]; a model with finite-difference
        noise (the FEM) needs ~1e-7 for SLSQP to count its iterates feasible and stop.

    Raises
    ------
    InfeasibleError
        When no feasible point exists or the optimiser ends infeasible.
    """
    counting = _CountingModel(model, problem)
    if start is None:
        start = feasible_start(counting, problem)
    # Work in millimetres so both variables are O(1).
    scale = MM
    start_mm = np.clip(start / scale, problem.lower / scale, problem.upper / scale)
    step = relative_step * (problem.upper - problem.lower) / scale
    offsets = _difference_offsets(step, difference)
    cache = {}

    def evaluate(x_mm):
        key = tuple(x_mm)
        if key not in cache:
            points = (x_mm[None, :] + offsets) * scale
            deflection, frequency = counting(points)
            cache.clear()
            cache[key] = (np.asarray(deflection, float), np.asarray(frequency, float))
        return cache[key]

    def derivative(values):
        if difference == "central":
            return np.array([(values[1 + 2 * i] - values[2 + 2 * i]) / (2 * step[i]) for i in range(2)])
        return np.array([(values[1 + i] - values[0]) / step[i] for i in range(2)])

    # Objective in micrometres, or in tenths of the start's deflection when that is larger (a large
    # Q x voltage: SLSQP stops on round-off when the objective is in the thousands); frequency constraint relative.
    deflection_unit = max(1e-6, float(evaluate(start_mm)[0][0]) / 10)

    def objective(x, grad):
        deflection, _ = evaluate(x)
        if grad.size:
            grad[:] = derivative(deflection) / deflection_unit
        return float(deflection[0]) / deflection_unit

    def constraint(x, grad):
        _, frequency = evaluate(x)
        if grad.size:
            grad[:] = -derivative(frequency) / problem.min_frequency
        return 1.0 - float(frequency[0]) / problem.min_frequency

    optimizer = nlopt.opt(nlopt.LD_SLSQP, 2)
    optimizer.set_lower_bounds(list(problem.lower / scale))
    optimizer.set_upper_bounds(list(problem.upper / scale))
    optimizer.set_max_objective(objective)
    optimizer.add_inequality_constraint(constraint, constraint_tolerance)
    optimizer.set_xtol_rel(xtol_rel)
    optimizer.set_maxeval(max_evaluations)
    x_opt = optimizer.optimize(list(start_mm))
    status = _STATUS.get(optimizer.last_optimize_result(), str(optimizer.last_optimize_result()))
    deflection, frequency = (float(v[0]) for v in evaluate(np.asarray(x_opt)))
    slack = max(FREQUENCY_SLACK, constraint_tolerance)
    if frequency < problem.min_frequency * (1 - slack):
        raise InfeasibleError(
            f"the optimiser ended on an infeasible point (f_r = {frequency / 1e3:.3f} kHz < "
            f"{problem.min_frequency / 1e3:g} kHz, {status}); try another start"
        )
    plate = problem.plate(float(x_opt[0]) * scale, float(x_opt[1]) * scale)
    return Optimum(
        plate=plate,
        deflection=deflection,
        frequency=frequency,
        evaluations=counting.evaluations,
        constraint_active=bool(frequency <= problem.min_frequency * (1 + slack)),
        status=status,
    )


def _difference_offsets(step: np.ndarray, difference: str) -> np.ndarray:
    """Rows: the point itself, then the finite-difference neighbours (mm)."""
    if difference == "central":
        rows = [np.zeros(2)]
        for i in range(2):
            e = np.zeros(2)
            e[i] = step[i]
            rows += [e, -e]
        return np.array(rows)
    if difference == "forward":
        return np.vstack([np.zeros(2), np.diag(step)])
    raise ValueError(f"difference must be 'central' or 'forward', got {difference!r}")


_STATUS = {
    nlopt.SUCCESS: "success",
    nlopt.STOPVAL_REACHED: "stopval reached",
    nlopt.FTOL_REACHED: "ftol reached",
    nlopt.XTOL_REACHED: "xtol reached",
    nlopt.MAXEVAL_REACHED: "maximum evaluations reached",
    nlopt.MAXTIME_REACHED: "maximum time reached",
}


def optimise_analytical(problem: DesignProblem, q: float = materials.PLATE_Q) -> Optimum:
    """The beam-model optimum with constant Q (docs/model.md)."""
    return maximise_deflection(analytical_model(q, problem.voltage), problem)
