"""Running ``tactile run``'s steps: context, timing, progress, caching and failures.

Each :class:`Step` computes ``compute(context) -> result`` from a :class:`RunContext`;
results are kept in :class:`RunResults`, one field per step, for the steps after it and for the report.  A step that fails
stops the run with a :class:`StepError` naming the step and the reason.  The steps
themselves are in :mod:`workflow.pipeline.steps`.
"""

import hashlib
import sys
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Optional

import numpy as np

import instruments
import workflow
from workflow.errors import TactileError
from workflow.execution.cache import EvaluationCache, content_key, package_directory, source_version
from workflow.inputfiles import MAX_LOG_BYTES, read_input
from workflow.pipeline.outputs import save_figure
from workflow.progress import format_duration


if TYPE_CHECKING:  # result types only: importing them here would load the fit and the FEM with the runner
    from workflow.damping.fit import DampingFit
    from workflow.models.fem import FemResult
    from workflow.optimise.maps import DesignMap, WidthSweep
    from workflow.optimise.problem import Optimum
    from workflow.optimise.robust import RobustDesign
    from workflow.pipeline.recommendation import Recommendation


class StepError(TactileError):
    """A step of ``tactile run`` failed."""


@dataclass
class RunResults:
    """What the run's steps returned, one field per step (its :attr:`Step.key`; None until the step ran or where it
    was off).  Quantities in SI; units are applied where they are written (report, JSON).

    Four result types are defined by modules that import this one, and are typed ``Any`` here: ``fem_optima``'s
    ``FemOptima`` per h_p (:mod:`workflow.pipeline.steps`), ``built_calibration`` a ``BuiltCalibration`` and
    ``robust_recommendation`` a ``RobustRecommendation`` (:mod:`workflow.pipeline.robust_recommendation`), the loop's
    plates ``BuiltMeasurement`` (:mod:`workflow.pipeline.loop`).
    """

    logs: Optional[List[Path]] = None
    """The interferometer logs fitted (the simulated campaign's, or --logs)."""
    analytical_optima: Optional[Dict[float, "Optimum"]] = None
    """The beam model's optimum at constant Q, per h_p [m]."""
    damping_fit: Optional["DampingFit"] = None
    damped_design: Optional[tuple] = None
    """(the designs with Q(v) and their posterior propagation, the damped maps)."""
    fem_original: Optional["FemResult"] = None
    fem_responses: Optional[tuple] = None
    """(frequency response, transient response) of the original plate."""
    fem_optima: Optional[Dict[float, Any]] = None
    recommended_design: Optional["Recommendation"] = None
    built_calibration: Any = None
    robust_recommendation: Any = None
    texture_rendering: Optional[dict] = None
    """Per h_p: the design's texture rendering and electrical load."""
    calibrated_designs: Optional[dict] = None
    """Per h_p [m]: the design as --calibration predicts it (a ``Prediction``, :mod:`workflow.calibration.calibration`)."""
    loop_first_plate: Any = None
    loop_calibration: Optional[tuple] = None
    """(the calibration on plate #1, the predicted frequency band of the re-design [Hz])."""
    loop_redesign: Optional["RobustDesign"] = None
    loop_second_plate: Any = None
    case_study: Optional[list] = None
    """Each published plate calibrated on the other and predicted (a ``CrossPrediction`` per direction)."""
    analytical_maps: Optional[Dict[float, "DesignMap"]] = None
    fem_maps: Optional[Dict[float, "DesignMap"]] = None
    width_sweep: Optional["WidthSweep"] = None


@dataclass
class StepTiming:
    """How long a step took [s] and whether its result came from the cache."""

    name: str
    seconds: float
    cached: bool = False


@dataclass(frozen=True)
class FigureFile:
    """A figure a step wrote: its path relative to the output folder, its caption and the key of the step."""

    name: str
    caption: str
    step: str


@dataclass
class RunContext:
    """What the steps share: the configuration, the output folder, the results so far, the figures written
    (path relative to the output folder -> :class:`FigureFile`, in the order written) and the step running."""

    config: dict
    out: Path
    scheduler: Optional[str] = None
    logs: List[Path] = field(default_factory=list)
    results: RunResults = field(default_factory=RunResults)
    timings: List[StepTiming] = field(default_factory=list)
    figures: Dict[str, FigureFile] = field(default_factory=dict)
    cache: Optional[EvaluationCache] = None
    calibration: Optional[Path] = None
    step: str = ""

    def save_figure(self, figure, name: str, caption: str) -> Path:
        """Write a matplotlib figure as the PNG ``name`` (relative to the output folder), recorded for the report with
        its caption."""
        path = Path(save_figure(figure, self.out / name, tight=True))
        self.record_figure(name, caption)
        return path

    def record_figure(self, name: str, caption: str) -> None:
        """Record a figure the running step wrote into the output folder (``name`` relative to it) for the report."""
        self.figures[name] = FigureFile(name, caption, self.step)

    def figures_of(self, step: str) -> List[FigureFile]:
        """The figures the step ``step`` (its key) wrote, in the order it wrote them."""
        return [figure for figure in self.figures.values() if figure.step == step]


@dataclass(frozen=True)
class Step:
    """One step of the run.

    Attributes
    ----------
    title : str
        Shown in the progress lines, the timings and the error message.
    key : str
        Name of the result in ``context.results`` (a :class:`RunResults` field).
    compute : callable
        ``compute(context) -> result`` (no figures).
    figures : callable or None
        ``figures(context, result)`` writes the step's figures into the output folder.
    cacheable : bool
        Keep the result in the evaluation cache, keyed by the configuration, the logs'
        contents and the code, so that a rerun reuses it.
    """

    title: str
    key: str
    compute: Callable[[RunContext], Any]
    figures: Optional[Callable[[RunContext, Any], None]] = None
    cacheable: bool = True

    def __post_init__(self):
        if self.key not in RunResults.__dataclass_fields__:
            raise TypeError(f"step {self.title!r}: its key {self.key!r} is not a field of RunResults")


@lru_cache(maxsize=256)
def _file_digest(path: str, modified_ns: int, size: int) -> str:
    """SHA-256 of a log's bytes, read once per (path, modification time, size): every step's key holds it."""
    return hashlib.sha256(read_input(Path(path), path, MAX_LOG_BYTES)).hexdigest()


def _digests(paths) -> list:
    """The SHA-256 of each log of ``paths`` (:func:`_file_digest`; a file that cannot be read says so as
    :func:`~workflow.inputfiles.read_input` does)."""
    digests = []
    for path in paths:
        try:
            stat = Path(path).stat()
        except OSError:
            digests.append(hashlib.sha256(read_input(path, str(path), MAX_LOG_BYTES)).hexdigest())
            continue
        digests.append(_file_digest(str(path), stat.st_mtime_ns, stat.st_size))
    return digests


def _step_key(context: RunContext, step: Step) -> str:
    """Content key of a step's result: step, configuration, the bytes of the logs it reads (the campaign's and the
    built plates'), code."""
    return content_key(
        {
            "step": step.key,
            "config": context.config,
            "logs": _digests(context.results.logs or []),
            "built_plates": _digests(context.config.get("recommendation", {}).get("built_plates", [])),
            "code": [source_version(package_directory(workflow)), source_version(package_directory(instruments))],
        }
    )


def _compute(context: RunContext, step: Step):
    """(result, from cache, key) of a step, through the cache when it may be used (key None when not)."""
    if not (step.cacheable and context.cache is not None):
        return step.compute(context), False, None
    key = _step_key(context, step)
    found, value = context.cache.load(key)
    if found:
        return value, True, key
    value = step.compute(context)
    context.cache.store(key, value)
    return value, False, key


def _stat(folder: Path) -> Dict[str, tuple]:
    """Path relative to ``folder`` -> (size, modification time) of every file under it."""
    return {path.relative_to(folder).as_posix(): (stat.st_size, stat.st_mtime_ns)
            for path in folder.rglob("*") if path.is_file() and (stat := path.stat())}


def _write_files(context: RunContext, step: Step, result, key: Optional[str], cached: bool) -> None:
    """Write the step's files (figures, posteriors, JSON) into the output folder.

    The files of a cacheable step are kept in the cache beside its result, keyed by the result's key and the output
    folder (some files name their own paths), so that a rerun of a cached step copies them instead of drawing its
    figures again (the Q(v) fit's corner and trace plots alone take seconds).
    """
    if key is None:
        step.figures(context, result)
        return
    files_key = content_key({"files": key, "out": str(context.out.resolve())})
    if cached:
        found, stored = context.cache.load(files_key)
        if found:
            for name, data in stored["files"].items():
                path = context.out / name
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(data.tobytes())
            for figure in stored["figures"]:
                context.figures[figure.name] = replace(figure, step=step.key)
            return
    before = _stat(context.out)
    step.figures(context, result)
    written = sorted(name for name, state in _stat(context.out).items() if before.get(name) != state)
    files = {name: np.frombuffer((context.out / name).read_bytes(), dtype=np.uint8) for name in written}
    context.cache.store(files_key, {"files": files, "figures": context.figures_of(step.key)})


def run_steps(context: RunContext, steps: List[Step], stream=None) -> RunContext:
    """Run ``steps`` in order, printing progress and timings to ``stream`` (stderr).

    Each step prints a line when it starts and one when it ends, with its time and the run's
    so far; inside a step, long computations show their own progress (emcee, FEM batches).
    """
    stream = sys.stderr if stream is None else stream
    context.out.mkdir(parents=True, exist_ok=True)
    run_start = time.perf_counter()
    for number, step in enumerate(steps, start=1):
        print(f"[{number}/{len(steps)}] {step.title} ...", file=stream, flush=True)
        start = time.perf_counter()
        context.step = step.key
        try:
            result, cached, key = _compute(context, step)
            setattr(context.results, step.key, result)
            if step.figures is not None:
                _write_files(context, step, result, key, cached)
        except StepError:
            raise
        except TactileError as error:
            raise StepError(f"step '{step.title}' failed: {error}") from None
        except Exception as error:  # an unexpected failure still names its step
            raise StepError(f"step '{step.title}' failed unexpectedly: {type(error).__name__}: {error}") from error
        seconds = time.perf_counter() - start
        context.timings.append(StepTiming(step.title, seconds, cached))
        note = " (from cache)" if cached else ""
        elapsed = format_duration(time.perf_counter() - run_start)
        print(f"[{number}/{len(steps)}] {step.title}: done in {format_duration(seconds)}{note}, {elapsed} elapsed",
              file=stream, flush=True)
    return context
