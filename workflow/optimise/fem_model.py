"""Many FEM evaluations: cached on disk by content, run in parallel, usable as a plate model.

:class:`FemModel` turns :func:`workflow.models.fem.evaluate_fem` into a
:data:`~workflow.optimise.problem.PlateModel` (a batch of plates in, deflection and frequency of
each plate's best mode out), so the optimiser, space mapping and the maps all drive the
FEM the same way.  Every geometry is one :class:`FemTask`; tasks run through
:func:`~workflow.execution.cache.cached_map`, whose key holds the model name, the plate's
fields, Q, the voltage, the FEM settings and a hash of the FEM's source code.
:meth:`FemModel.gradients` adds the design sensitivities of :mod:`workflow.models.fem.sensitivity`
(results with tangents are cached under their own model name).  :meth:`FemModel.results_with_surfaces`
adds the modes over the top face (:func:`workflow.models.fem.surface.evaluate_surface`), sampled from the
same evaluation, cached as "fem+surface".
"""

from dataclasses import dataclass, field, replace

import numpy as np

from workflow.calibration.plate_surrogate import TWO_LEVEL_COARSE, DesignFem
from workflow.execution.cache import EvaluationCache, cached_map, package_directory, source_version
from workflow.models import fem, materials
from workflow.models.fem import FemResult, FemSettings, evaluate_fem
from workflow.models.fem.accuracy import FemAccuracy, FemLevel
from workflow.models.fem.sensitivity import DESIGN_PARAMETERS, best_mode_gradients, evaluate_fem_with_tangents
from workflow.models.fem.surface import SurfaceModes, evaluate_surface
from workflow.models.plate import Plate
from workflow.models.response import PlateResponse, ScaledResponse, StackedResponse

FEM_SOURCE = package_directory(fem)
"""Directory whose sources version the cached FEM results."""


@dataclass(frozen=True)
class FemTask:
    """One FEM evaluation: a scalar plate, Q [-], voltage [V], the settings and whether to add the tangents.

    With ``tangents`` the result also carries the derivatives of its probe model with respect
    to lambda and h_i (:func:`workflow.models.fem.sensitivity.evaluate_fem_with_tangents`).
    """

    plate: Plate
    q: float
    voltage: float
    settings: FemAccuracy | FemSettings | FemLevel
    tangents: bool = False


def run_fem_task(task: FemTask) -> FemResult:
    """Evaluate one task (module level, so that process pools and Dask can pickle it)."""
    evaluate = evaluate_fem_with_tangents if task.tangents else evaluate_fem
    return evaluate(task.plate, task.q, task.voltage, task.settings).stripped()


def run_surface_task(task: FemTask) -> tuple[FemResult, SurfaceModes]:
    """The result of one task and its modes over the top face, from one evaluation (module level, picklable)."""
    return evaluate_surface(task.plate, task.q, task.voltage, task.settings)


def describe_surface_task(task: FemTask) -> dict:
    """The cache-key content of a task with its surface."""
    return {**describe_fem_task(task), "model": "fem+surface"}


def describe_fem_task(task: FemTask) -> dict:
    """The cache-key content of a task (results with tangents under their own model name)."""
    return {
        "model": "fem+tangents" if task.tangents else "fem",
        "plate": task.plate,
        "q": float(task.q),
        "voltage": float(task.voltage),
        "settings": task.settings.as_dict(),
        "code": source_version(FEM_SOURCE),
    }


def scalar_plates(plate: Plate) -> list[Plate]:
    """The plates of a batch (array fields broadcast together), flattened in C order."""
    names = ("wavelength", "resonator_thickness", "ceramic_thickness", "width")
    arrays = np.broadcast_arrays(*(np.asarray(getattr(plate, name), dtype=float) for name in names))
    return [plate.with_(**{name: float(a.flat[i]) for name, a in zip(names, arrays)}) for i in range(arrays[0].size)]


def best_mode_values(results, shape: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deflection [m], frequency [Hz] and transverse indicator [-] of each result's best mode, shaped ``shape``."""
    return tuple(
        np.array([getattr(r.best, name) for r in results]).reshape(shape)
        for name in ("deflection", "frequency", "transverse_indicator")
    )


@dataclass
class FemModel:
    """The FEM as a batched plate model, with a disk cache and parallel evaluation.

    Attributes
    ----------
    q : float
        Plate quality factor [-].
    voltage : float
        Drive amplitude [V].
    settings : FemAccuracy or FemSettings
        An accuracy (each geometry gets the mesh it needs and an error estimate) or a fixed mesh.
    cache : EvaluationCache or None
        None recomputes everything.
    scheduler : None, str or distributed.Client
        Where batches run (see :func:`~workflow.execution.parallel.map_evaluations`).
    progress : bool
        Show each batch's progress on stderr (a bar on a terminal, plain lines otherwise).
    evaluations : int
        Geometries requested so far (cached or not).
    """

    q: float = materials.PLATE_Q
    voltage: float = materials.DESIGN_VOLTAGE
    settings: FemAccuracy | FemSettings | FemLevel = field(default_factory=FemAccuracy)
    cache: EvaluationCache | None = None
    scheduler: object = None
    progress: bool = False
    evaluations: int = 0

    def on_mesh(self, mesh: FemSettings) -> "FemModel":
        """The same model on a fixed mesh (same cache and scheduler), its evaluation count at zero."""
        return replace(self, settings=mesh, evaluations=0)

    def at_level(self, level: int) -> "FemModel":
        """The same model on each plate's mesh of one fixed level (:class:`~workflow.models.fem.accuracy.FemLevel`,
        its modes and piezo model this model's), same cache and scheduler, its evaluation count at zero."""
        return replace(self, settings=FemLevel(level, self.settings.n_modes, self.settings.piezo), evaluations=0)

    def design_fem(self) -> DesignFem:
        """How this model evaluates a surrogate's design: two-level (every point on the level
        :data:`~workflow.calibration.plate_surrogate.TWO_LEVEL_COARSE`, the anchors to this model's accuracy) when
        the accuracy starts above that level, else every point with this model.  The coarse evaluations go through a
        model of their own: :attr:`evaluations` counts only this model's (a design's values count both)."""
        if not (self.settings.refines and self.settings.start_level > TWO_LEVEL_COARSE):
            return DesignFem(self.evaluate_plates, self.results_with_surfaces)
        coarse = self.at_level(TWO_LEVEL_COARSE)
        return DesignFem(self.evaluate_plates, self.results_with_surfaces, coarse.evaluate_plates,
                         coarse.results_with_surfaces, TWO_LEVEL_COARSE)

    def results(self, plate: Plate, with_tangents: bool = False) -> list[FemResult]:
        """The full FEM result of every plate of the batch.

        Parameters
        ----------
        plate : Plate
            A batch of geometries [m].
        with_tangents : bool
            Also compute the derivatives of each result's probe model with respect to lambda
            and h_i (``FemResult.tangents``; about 1.7 times the cost, cached separately).
        """
        return self.evaluate_plates(scalar_plates(plate), with_tangents)

    def response(self, plate: Plate, voltage: float | None = None) -> PlateResponse:
        """The working modes of a batch of plates as one batched :class:`~workflow.models.response.PlateResponse`
        (each geometry's best mode), at ``voltage`` [V peak]; without it the
        :class:`~workflow.models.response.StackedResponse` of the results at the model's voltage."""
        batch = StackedResponse(tuple(self.results(plate)), plate.batch_shape)
        return batch if voltage is None else ScaledResponse(batch, voltage / self.voltage)

    def evaluate_plates(self, plates: list[Plate], with_tangents: bool = False) -> list[FemResult]:
        """The full FEM result of each scalar plate of a list (materials and bond may differ between them)."""
        tasks = [FemTask(p, self.q, self.voltage, self.settings, with_tangents) for p in plates]
        self.evaluations += len(tasks)
        return cached_map(
            run_fem_task, tasks, describe_fem_task, self.cache, self.scheduler, self.progress, description="FEM evaluations"
        )

    def results_with_surfaces(self, plates: list[Plate]) -> tuple[list[FemResult], list[SurfaceModes]]:
        """The result of each scalar plate and its modes over the top face (eigenstrain drive), both from one
        evaluation (the surface sampled from the final level's own modes), cached together."""
        tasks = [FemTask(p, self.q, self.voltage, self.settings) for p in plates]
        self.evaluations += len(tasks)
        pairs = cached_map(run_surface_task, tasks, describe_surface_task, self.cache, self.scheduler, self.progress,
                           description="FEM evaluations with surfaces")
        return [result for result, _ in pairs], [surface for _, surface in pairs]

    def gradients(self, plate: Plate) -> tuple[np.ndarray, np.ndarray]:
        """Gradients over (lambda, h_i) of the best mode's deflection and frequency of each plate.

        The best mode's index is held fixed (the one-sided derivative of the max over the modes).

        Returns
        -------
        deflection_gradient : array
            Batch shape + (2,), d w / d (lambda, h_i) [m/m].
        frequency_gradient : array
            Batch shape + (2,), d f_r / d (lambda, h_i) [Hz/m].
        """
        return self.responses_with_gradients(plate)[3:]

    def responses_with_gradients(self, plate: Plate) -> tuple[np.ndarray, ...]:
        """:meth:`responses` and :meth:`gradients` of each plate from one evaluation with tangents.

        Returns
        -------
        deflection, frequency, indicator : array
            Batch shape: [m], [Hz], [-].
        deflection_gradient, frequency_gradient : array
            Batch shape + (2,), over (lambda, h_i): [m/m], [Hz/m].
        """
        results = self.results(plate, with_tangents=True)
        pairs = [best_mode_gradients(result) for result in results]
        gradient_shape = plate.batch_shape + (len(DESIGN_PARAMETERS),)
        gradients = tuple(np.array([pair[k] for pair in pairs]).reshape(gradient_shape) for k in (1, 0))
        return best_mode_values(results, plate.batch_shape) + gradients

    def responses(self, plate: Plate) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Deflection [m], frequency [Hz] and transverse indicator [-] of the best mode of each plate."""
        return best_mode_values(self.results(plate), plate.batch_shape)

    def space_mapping_fine(self) -> tuple:
        """(fine model, mapping) of space mapping on this FEM: its responses with the exact design sensitivities."""
        from workflow.optimise.space_mapping import SensitivityMapping

        return self.responses_with_gradients, SensitivityMapping

    def __call__(self, plate: Plate) -> tuple[np.ndarray, np.ndarray]:
        """Deflection [m] and frequency [Hz] of the best mode of each plate, shaped like the batch."""
        return self.responses(plate)[:2]
