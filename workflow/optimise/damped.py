"""Design with the amplitude-dependent quality factor Q(v) (docs/damping.md).

At resonance the antinode deflection is proportional to Q: w = Q k V with k the
deflection per volt and per unit of Q.  With Q = Q(v) and v = 2 pi f_r w the deflection
solves w = Q(2 pi f_r w) k V (the iterative harmonic solve, vectorised over geometries
and posterior draws).

Calibration choice (beam model): the fitted Q(v) is the plate's physical Q, as the FEM
and the bench use it.  The beam model's calibration :data:`~workflow.models.analytical.BEAM_CALIBRATION`
corrects the beam's deflection per unit Q (a model error, constant across geometries);
it is applied to k, never to Q.  The velocity that sets Q is the velocity of the
calibrated deflection, so the beam and the FEM see Q(v) at the same physical velocity.
The original plate, whose Q = 54 was measured at its 15 V working point, keeps its
deflection by construction when Q(v) passes through Q = 54 there.

Required voltage: w grows monotonically with V, and at the target deflection w* the
velocity v* = 2 pi f_r w* is known, so V* = w* / (Q(v*) k) in closed form (FEM:
V* = V_0 w* / D(Q(v*)), D the deflection at V_0 as a function of Q, linear in V).
"""

from dataclasses import dataclass, replace
from functools import partial
from typing import Callable, Dict, Optional, Sequence

import numpy as np

from workflow.damping.harmonic import self_consistent_deflection
from workflow.damping.laws import POSTERIOR_LAWS, law_parameters
from workflow.damping.posterior import DampingPosterior
from workflow.models import analytical, materials
from workflow.models.plate import ORIGINAL_PLATE, Plate
from workflow.models.response import PlateResponse, ScaledResponse
from workflow.optimise.maps import grid_axes
from workflow.optimise.problem import DesignProblem, Optimum, PlateModel, maximise_deflection

QUANTILES = (0.05, 0.5, 0.95)
"""Credible-interval quantiles reported for propagated quantities."""
MAP_DRAW_BUDGET = 2_000_000
"""Grid points x posterior draws of a required-voltage map's interval (bounds the memory)."""
MAX_MAP_DRAWS = 100
"""Most posterior draws behind a required-voltage map's interval."""


def damped_deflection(response: PlateResponse, law):
    """Antinode deflection at resonance with Q = Q(2 pi f_r w), solved self-consistently [m], for any plate model.

    Parameters
    ----------
    response : PlateResponse
        The beam model's (:func:`~workflow.models.analytical.beam_response`, fields may be arrays: a batch of
        geometries) or an FEM result (its best mode; its ``deflection_at_q`` gives the deflection for other Q without
        a new solve).
    law : Q(v) law
        Parameters may be arrays broadcasting against the response's (e.g. draws on a new axis).
    """
    omega = 2 * np.pi * np.asarray(response.frequency, dtype=float)
    return self_consistent_deflection(response.deflection_at_q, law.quality_factor, omega)


def required_voltage(response: PlateResponse, law, target: float = materials.TARGET_DEFLECTION):
    """Drive amplitude that gives the deflection ``target`` with Q(v) [V peak], for any plate model.

    Every model here is linear in V: V* = V w* / D(Q(2 pi f_r w*)), D the deflection at the response's voltage V as
    a function of Q (the beam model: V* = w* / (Q(v*) k)).
    """
    q_target = law.quality_factor(2 * np.pi * np.asarray(response.frequency, dtype=float) * target)
    return response.voltage * target / response.deflection_at_q(q_target)


POSTERIOR_DRAWS = 200
"""Posterior draws behind the intervals of a single evaluation or optimum."""


@dataclass(frozen=True)
class QOfV:
    """One plate's working mode with the fitted Q(v) (any model's response).

    Attributes
    ----------
    deflection : float
        Self-consistent antinode deflection with the posterior-median law at the response's voltage [m].
    deflection_interval : tuple of float
        Its p05 and p95 over posterior draws [m].
    quality_factor : float
        The median law's Q at that deflection's velocity [-].
    required_voltage : tuple of float
        p05, p50, p95 over posterior draws of the voltage for ``target`` [V peak].
    target : float
        Deflection the required voltage aims at [m].
    law : Q(v) law
        The posterior-median law (for a mixture of laws, its most frequent law's).
    posterior : DampingPosterior
    """

    deflection: float
    deflection_interval: tuple
    quality_factor: float
    required_voltage: tuple
    target: float
    law: object
    posterior: DampingPosterior


def q_of_v(posterior: DampingPosterior, response: PlateResponse, draws: int = POSTERIOR_DRAWS,
           target: float = materials.TARGET_DEFLECTION) -> QOfV:
    """The :class:`QOfV` of one plate's response (``draws`` posterior draws behind the intervals)."""
    law, drawn = posterior.median_law(), posterior.draws(draws)
    deflection = float(damped_deflection(response, law))
    w05, _, w95 = np.quantile(damped_deflection(response, drawn), QUANTILES)
    return QOfV(
        deflection=deflection,
        deflection_interval=(float(w05), float(w95)),
        quality_factor=float(law.quality_factor(2 * np.pi * float(response.frequency) * deflection)),
        required_voltage=tuple(float(v) for v in np.quantile(required_voltage(response, drawn, target), QUANTILES)),
        target=target,
        law=law,
        posterior=posterior,
    )


@dataclass
class DampedFemModel:
    """The FEM with Q(v) as a :data:`~workflow.optimise.problem.PlateModel`.

    Attributes
    ----------
    law : Q(v) law
    fem_model : workflow.optimise.fem_model.FemModel
        Evaluates (and caches) the FEM at its own voltage and Q; the Q only picks the
        best mode, the deflection is then solved with Q(v).
    voltage : float
        Drive amplitude [V peak]; the FEM's response is scaled to it (linear in V).
    """

    law: object
    fem_model: object
    voltage: float = materials.DESIGN_VOLTAGE

    @property
    def settings(self):
        """The underlying FEM's settings (an accuracy or a fixed mesh)."""
        return self.fem_model.settings

    def on_mesh(self, mesh) -> "DampedFemModel":
        """The same model with its FEM on a fixed mesh."""
        return replace(self, fem_model=self.fem_model.on_mesh(mesh))

    def results(self, plate: Plate):
        return self.fem_model.results(plate)

    def responses(self, plate: Plate):
        """Deflection with Q(v) [m], frequency [Hz] and transverse indicator [-] of each plate's best mode."""
        batch = self.fem_model.response(plate)
        indicator = np.reshape([r.best.transverse_indicator for r in batch.responses], plate.batch_shape)
        deflection = damped_deflection(ScaledResponse(batch, self.voltage / self.fem_model.voltage), self.law)
        return deflection, batch.frequency, indicator

    def __call__(self, plate: Plate):
        return self.responses(plate)[:2]

    def space_mapping_fine(self) -> tuple:
        """(fine model, mapping) of space mapping on the FEM with Q(v): its responses (no sensitivities of Q(v))."""
        from workflow.optimise.space_mapping import ResponseMapping

        return self.responses, ResponseMapping


def damped_beam_model(law, voltage: float = materials.DESIGN_VOLTAGE) -> PlateModel:
    """The beam model with Q(v), usable by :func:`~workflow.optimise.problem.maximise_deflection`
    (:class:`DampedFemModel` is the FEM's).

    Parameters
    ----------
    law : Q(v) law
        Scalar parameters.
    voltage : float
        Drive amplitude [V peak].
    """

    def beam(plate: Plate):
        response = analytical.beam_response(plate, voltage)
        return damped_deflection(response, law), response.frequency

    return beam


@dataclass(frozen=True)
class DrawTask:
    """One posterior draw's optimisation (module-level data, picklable for process pools)."""

    law_name: str
    parameters: tuple
    problem: DesignProblem
    target: float


def optimise_draw(task: DrawTask) -> tuple:
    """(lambda [m], h_i [m], deflection [m], frequency [Hz], required voltage [V]) of one draw's beam optimum."""
    law = POSTERIOR_LAWS[task.law_name](*task.parameters)
    optimum = maximise_deflection(damped_beam_model(law, task.problem.voltage), task.problem)
    voltage = float(required_voltage(analytical.beam_response(optimum.plate, task.problem.voltage), law, task.target))
    return (
        float(optimum.plate.wavelength),
        float(optimum.plate.resonator_thickness),
        optimum.deflection,
        optimum.frequency,
        voltage,
    )


@dataclass(frozen=True)
class DampedOptimum:
    """The beam optimum of one h_p with constant Q and with Q(v), and its posterior spread.

    Attributes
    ----------
    problem : DesignProblem
    constant_q : Optimum
        With the plate's constant Q (:data:`~workflow.models.materials.PLATE_Q`).
    damped : Optimum
        With the posterior-median Q(v).
    required_voltage : float
        Voltage for the target deflection at ``damped`` with the median law [V].
    draws : dict
        "wavelength", "resonator_thickness" [m], "deflection" [m], "frequency" [Hz],
        "required_voltage" [V]: one value per posterior draw.
    """

    problem: DesignProblem
    constant_q: Optimum
    damped: Optimum
    required_voltage: float
    draws: Dict[str, np.ndarray]

    def interval(self, name: str) -> np.ndarray:
        """(p05, p50, p95) of a drawn quantity."""
        return np.quantile(self.draws[name], QUANTILES)


@dataclass(frozen=True)
class DampedDesign:
    """Result of :func:`design_with_damping`.

    Attributes
    ----------
    posterior : DampingPosterior
    median_law : Q(v) law
    optima : dict
        h_p [m] -> :class:`DampedOptimum`.
    original_deflection : numpy.ndarray
        Original plate at the design voltage with Q(v): one value per draw [m].
    original_required_voltage : numpy.ndarray
        Original plate, voltage for the target: one value per draw [V].
    target : float
        Target deflection [m].
    """

    posterior: DampingPosterior
    median_law: object
    optima: Dict[float, DampedOptimum]
    original_deflection: np.ndarray
    original_required_voltage: np.ndarray
    target: float


def design_with_damping(
    posterior: DampingPosterior,
    problems: Sequence[DesignProblem],
    draws: int = 100,
    seed: int = 0,
    target: float = materials.TARGET_DEFLECTION,
    scheduler=None,
    progress: bool = False,
) -> DampedDesign:
    """Optimise every problem with constant Q and with Q(v), and propagate the posterior.

    Parameters
    ----------
    posterior : DampingPosterior
    problems : sequence of DesignProblem
        Typically one per commercial h_p.
    draws : int
        Posterior draws propagated through each optimisation.
    seed : int
        Selects the draws.
    target : float
        Deflection the required voltage aims at [m].
    scheduler : None, "synchronous", str or distributed.Client
        Where the per-draw optimisations run (:func:`workflow.execution.parallel.map_evaluations`).
    progress : bool
    """
    from workflow.execution.parallel import map_evaluations
    from workflow.optimise.problem import analytical_model

    median = posterior.median_law()
    drawn = posterior.draws(draws, seed)
    names = list(law_parameters(drawn))
    columns = [np.ravel(getattr(drawn, name)) for name in names]
    optima = {}
    for problem in problems:
        tasks = [DrawTask(posterior.law_name, tuple(float(c[i]) for c in columns), problem, target) for i in range(draws)]
        rows = np.array(map_evaluations(optimise_draw, tasks, scheduler=scheduler, progress=progress, description="Q(v) draws"))
        damped = maximise_deflection(damped_beam_model(median, problem.voltage), problem)
        optima[problem.ceramic_thickness] = DampedOptimum(
            problem=problem,
            constant_q=maximise_deflection(analytical_model(materials.PLATE_Q, problem.voltage), problem),
            damped=damped,
            required_voltage=float(required_voltage(analytical.beam_response(damped.plate, problem.voltage), median, target)),
            draws=dict(zip(("wavelength", "resonator_thickness", "deflection", "frequency", "required_voltage"), rows.T)),
        )
    voltage = problems[0].voltage if problems else materials.DESIGN_VOLTAGE
    original = analytical.beam_response(ORIGINAL_PLATE, voltage)
    return DampedDesign(
        posterior=posterior,
        median_law=median,
        optima=optima,
        original_deflection=damped_deflection(original, drawn),
        original_required_voltage=required_voltage(original, drawn, target),
        target=target,
    )


@dataclass(frozen=True)
class DampedMaps:
    """Beam-model maps over (lambda, h_i) with Q(v) for one h_p.

    Attributes
    ----------
    wavelength, resonator_thickness : numpy.ndarray
        Axes [m].
    deflection : numpy.ndarray (n_lambda, n_h)
        Deflection at the design voltage with the median law [m].
    frequency : numpy.ndarray (n_lambda, n_h)
        Resonance [Hz].
    required_voltage : numpy.ndarray (n_lambda, n_h)
        Voltage for the target deflection with the median law [V].
    required_voltage_interval : numpy.ndarray (3, n_lambda, n_h) or None
        p05, p50, p95 over posterior draws [V].
    ceramic_thickness, min_frequency, min_resonator_thickness : float
        h_p [m], the frequency limit [Hz] and the practical h_i minimum [m], for the figure.
    optimum : Optimum or None
        The Q(v) optimum, marked on the figure.
    law_label : str
    """

    wavelength: np.ndarray
    resonator_thickness: np.ndarray
    deflection: np.ndarray
    frequency: np.ndarray
    required_voltage: np.ndarray
    required_voltage_interval: Optional[np.ndarray]
    ceramic_thickness: float
    min_frequency: float
    min_resonator_thickness: float
    optimum: Optional[Optimum]
    law_label: str


def damped_maps(
    posterior: DampingPosterior,
    problem: DesignProblem,
    grid: int = 41,
    draws: int = 100,
    seed: int = 0,
    target: float = materials.TARGET_DEFLECTION,
    optimum: Optional[Optimum] = None,
    response: Optional[Callable[[Plate], PlateResponse]] = None,
    model_label: str = "beam model",
) -> DampedMaps:
    """Deflection and required-voltage maps with Q(v) over the problem's (lambda, h_i) box, for any plate model.

    Parameters
    ----------
    response : callable or None
        Batch of plates -> its :class:`~workflow.models.response.PlateResponse` at ``problem.voltage`` (the FEM's
        :meth:`~workflow.optimise.fem_model.FemModel.response`); None: the beam model, one vectorised solve.
    model_label : str
        How the figure's title names the model.

    The posterior draws add a leading axis to the grid (the FEM: each point's modal response evaluated for every
    draw's Q, without a new solve).
    """
    if response is None:
        response = partial(analytical.beam_response, voltage=problem.voltage)
    wavelength, thickness = grid_axes(problem, grid)
    at = response(problem.plate(wavelength[:, None], thickness[None, :]))
    median = posterior.median_law()
    interval = None
    if draws:
        drawn = posterior.draws(draws, seed)
        on_axis = POSTERIOR_LAWS[posterior.law_name](**{k: np.reshape(v, (-1, 1, 1)) for k, v in law_parameters(drawn).items()})
        interval = np.quantile(required_voltage(at, on_axis, target), QUANTILES, axis=0)
    return DampedMaps(
        wavelength=wavelength,
        resonator_thickness=thickness,
        deflection=damped_deflection(at, median),
        frequency=np.broadcast_to(at.frequency, (grid, grid)),
        required_voltage=required_voltage(at, median, target),
        required_voltage_interval=interval,
        ceramic_thickness=problem.ceramic_thickness,
        min_frequency=problem.min_frequency,
        min_resonator_thickness=problem.min_resonator_thickness,
        optimum=optimum,
        law_label=f"{model_label}, " + _law_label(posterior, median),
    )


def _law_label(posterior: DampingPosterior, law) -> str:
    """"quadratic Q(v), median: q0 = ..., alpha = ..." for a figure's title (a mixture: its shares, and the median of
    its most frequent law, ``law``)."""
    parameters = ", ".join(f"{k} = {v:.4g}" for k, v in law_parameters(law).items())
    median = "median" if law.name == posterior.law_name else f"median of its {law.name} law"
    return f"{posterior.description} Q(v), {median}: {parameters}"


def damped_optimum(law, problem: DesignProblem) -> Optimum:
    """The beam optimum with the Q(v) ``law`` solved self-consistently at ``problem.voltage``."""
    return maximise_deflection(damped_beam_model(law, problem.voltage), problem)


def map_draws(points: int) -> int:
    """Posterior draws for the required-voltage interval of a points x points map (within the budget)."""
    return int(np.clip(MAP_DRAW_BUDGET // points**2, 1, MAX_MAP_DRAWS))
