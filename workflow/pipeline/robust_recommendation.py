"""The design to build that holds when built (docs/calibration.md, "The recommended design in tactile run").

A nominal FEM optimum sits a few tens of hertz above the frequency limit, while plates built from such optima
resonated 5–8 % below the uncalibrated FEM (the published P1 and P2).  So ``tactile run`` calibrates the FEM on
every measured built plate it has — the shipped published plates and those of ``[recommendation] built_plates``
(``--built-plates``) — and designs, per h_p, the robust plate: the stock resonator thickness and the wavelength
with P(f_r >= f_min) >= the reliability under the calibration's posterior and the manufacturing tolerances
(:mod:`workflow.optimise.robust`).  The nominal optimum is checked under the same calibration and tolerances,
for comparison.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np

from workflow.calibration.calibration import Calibration
from workflow.calibration.published import published_plates
from workflow.errors import InfeasibleError
from workflow.models.materials import WAVELENGTH_RANGE
from workflow.models.plate import Plate
from workflow.optimise.robust import RobustCandidate, RobustSettings
from workflow.pipeline.design_models import DESIGN_MODELS
from workflow.pipeline.recommendation import RecommendedDesign
from workflow.pipeline.runner import RunContext
from workflow.units import KHZ, MM, UM

CALIBRATION_FOLDER = "calibration"
"""Sub-folder of the run's output with the calibration on the built plates (``calibration.json``, its pairs figure)."""
STOCK_HI_MM = (0.5, 0.6, 0.7, 0.75, 0.8, 1.0, 1.2, 1.5, 2.0, 2.5, 3.0)
"""Resonator stock thicknesses the robust design chooses from [mm] (common CuBe strip gauges)."""
STOCKS_PER_DESIGN = 2
"""Stocks tried per h_p: those nearest (in ratio) to the nominal optimum's h_i [-]; each costs a surrogate of
:func:`~workflow.calibration.calibration.prediction_points` FEM evaluations."""


@dataclass(frozen=True)
class BuiltCalibration:
    """The calibration on the measured built plates (the published ones named P1 and P2, the user's by their logs)."""

    calibration: Calibration

    @property
    def names(self) -> tuple:
        """The plates' names as the report gives them: P1, P2, then the log files' names."""
        return tuple(Path(plate.name).name for plate in self.calibration.plates)

    def surrogates_of(self, names: Sequence[str]) -> Optional[tuple]:
        """The prior surrogates of the plates ``names`` (all among :attr:`names`), else None."""
        if not all(name in self.names for name in names):
            return None
        return tuple(self.calibration.surrogates[self.names.index(name)] for name in names)

    def plates_of(self, names: Sequence[str]) -> tuple:
        """The measured plates ``names``."""
        return tuple(self.calibration.plates[self.names.index(name)] for name in names)


@dataclass(frozen=True)
class RobustChoice:
    """The robust design of one h_p and its nominal optimum under the same calibration.

    Attributes
    ----------
    candidates : tuple of RobustCandidate
        One per stock tried.
    best : RobustCandidate or None
        The robust design (:func:`~workflow.optimise.robust.select_robust`); None when no stock gives one.
    reason : str or None
        Why there is no robust design.
    nominal : RobustCandidate
        The nominal optimum's geometry checked under the calibration and the tolerances (its own lambda).
    best_damped, nominal_damped : RecommendedDesign or None
        The robust and the nominal design at their posterior-median plates with the fitted Q(v): deflection at the
        design voltage and voltage for the target (quantiles over Q(v) draws); None without a Q(v) fit.
    nominal_source : str
        The model whose optimum the nominal design is ("FEM", or "beam model" without the FEM optima).
    """

    candidates: tuple
    best: Optional[RobustCandidate]
    reason: Optional[str]
    nominal: RobustCandidate
    best_damped: Optional[RecommendedDesign] = None
    nominal_damped: Optional[RecommendedDesign] = None
    nominal_source: str = "FEM"

    @property
    def evaluations(self) -> int:
        return self.nominal.evaluations + sum(c.evaluations for c in self.candidates)


@dataclass(frozen=True)
class RobustRecommendation:
    """Per h_p [m] a :class:`RobustChoice`, and what they rest on.

    Attributes
    ----------
    choices : dict
    calibrated_on : tuple of str
        The built plates' names.
    settings : RobustSettings
        The reliability, frequency limit, mode separation and tolerances the designs were made with.
    q : float
        The constant Q of the deflections [-].
    """

    choices: Dict[float, RobustChoice]
    calibrated_on: tuple
    settings: RobustSettings
    q: float

    @property
    def evaluations(self) -> int:
        """FEM evaluations of the robust designs and the checks [-]."""
        return sum(choice.evaluations for choice in self.choices.values())


def own_plates(config: dict, warnings: list | None = None) -> list:
    """The plates measured in the logs of ``[recommendation] built_plates`` (resonance logs, with a scan log where
    there is one; none read when ``robust`` is off); reading them first, before any step, makes a bad log fail early
    (naming the file).  A scan of another plate accepted by ``[damping] mixed_plates = "warn"`` is appended to
    ``warnings``."""
    from workflow.calibration.parameters import load_settings
    from workflow.pipeline.calibration_files import measured_plates

    paths = config["recommendation"]["built_plates"]
    if not (paths and config["recommendation"]["robust"]):
        return []
    return measured_plates([Path(p) for p in paths], load_settings(), mixed_plates=config["damping"]["mixed_plates"],
                           warnings=[] if warnings is None else warnings)


def built_plates(config: dict) -> list:
    """The measured built plates: the published ones when ``[recommendation] published_plates``, then
    :func:`own_plates`."""
    return (published_plates() if config["recommendation"]["published_plates"] else []) + own_plates(config)


def built_calibration(context: RunContext) -> Optional[BuiltCalibration]:
    """The calibration (default priors and sampler, the survey accuracy) on the measured built plates; None when
    ``[recommendation] robust`` is off or there are no built plates."""
    from workflow.calibration.calibration import calibrate
    from workflow.calibration.parameters import load_settings
    from workflow.pipeline.loop import calibration_model

    if not context.config["recommendation"]["robust"]:
        return None
    plates = built_plates(context.config)
    if not plates:
        return None
    model, fem = calibration_model(context)
    return BuiltCalibration(calibrate(plates, load_settings(), model.design_fem(), fem))


CALIBRATION_CAPTION = "Posterior of the calibration on the built plates"
"""Caption of the built plates' calibration pairs figure."""


def built_calibration_files(context: RunContext, built: Optional[BuiltCalibration]) -> None:
    """``calibration/calibration.json`` (what ``--calibration`` reads) and its pairs figure."""
    from workflow.pipeline.calibration_files import write_calibration

    if built is None:
        return
    folder = context.out / CALIBRATION_FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    for path in write_calibration(built.calibration, folder)["figures"]:
        context.record_figure(Path(path).relative_to(context.out).as_posix(), CALIBRATION_CAPTION)


def nearest_stocks(thickness: float, stock: Sequence[float], count: int) -> list:
    """The ``count`` stock thicknesses nearest to ``thickness`` in ratio, thinnest first [m]."""
    ordered = sorted(stock, key=lambda h: (abs(np.log(h / thickness)), h))
    return sorted(ordered[:count])


def robust_choices(calibration: Calibration, nominals: Dict[float, Plate], stock: Sequence[float], count: int,
                   settings, fem, q: float, with_damping=None, wavelength_range: tuple = WAVELENGTH_RANGE,
                   sources: Dict[float, str] | None = None) -> Dict[float, RobustChoice]:
    """Per h_p: the robust design from the ``count`` stocks nearest the nominal optimum's h_i, and the nominal
    optimum checked under the calibration; all surrogates in one batch (:func:`~workflow.optimise.robust.robust_candidates`).

    Parameters
    ----------
    calibration : Calibration
    nominals : dict
        h_p [m] -> the nominal optimum's plate.
    stock : sequence of float
        Stock resonator thicknesses [m].
    count : int
    settings : RobustSettings
    fem : DesignFem
        How the surrogates' designs (and the designs' posterior medians) are evaluated.
    q : float
        Constant Q of the deflections [-].
    with_damping : callable, optional
        (h_p, RobustCandidate) -> RecommendedDesign with Q(v) at the candidate's posterior-median FEM result.
    wavelength_range : tuple of float
        The design space's lambda bounds [m] a robust design must lie within.
    sources : dict, optional
        h_p -> the model of the nominal optimum (default "FEM").
    """
    from workflow.optimise.robust import robust_candidates, select_robust, start_problem

    plates, solve, owner, unstarted = [], [], [], {}
    for hp, nominal in nominals.items():
        for thickness in nearest_stocks(float(nominal.resonator_thickness), stock, count):
            plate = nominal.with_(resonator_thickness=thickness)
            problem = start_problem(calibration, plate, settings)
            if problem is not None:  # this stock cannot reach the limit at any wavelength: said, not fatal
                unstarted.setdefault(hp, []).append(f"h_i {thickness * 1e3:g} mm: {problem}")
                continue
            plates.append(plate)
            solve.append(True)
            owner.append(hp)
        plates.append(nominal)
        solve.append(False)
        owner.append(hp)
    candidates = robust_candidates(calibration, plates, settings, fem, q, solve)
    choices = {}
    for hp in nominals:
        mine = [c for c, s, o in zip(candidates, solve, owner) if o == hp and s]
        (nominal,) = [c for c, s, o in zip(candidates, solve, owner) if o == hp and not s]
        try:
            best, reason = select_robust(mine, wavelength_range).best, None
        except InfeasibleError as error:
            best, reason = None, "; ".join(([str(error)] if mine else []) + unstarted.get(hp, []))
        damped = [None if with_damping is None or c is None else with_damping(hp, c) for c in (best, nominal)]
        choices[hp] = RobustChoice(tuple(mine), best, reason, nominal, *damped, (sources or {}).get(hp, "FEM"))
    return choices


def damped_evaluation(context: RunContext):
    """(h_p, RobustCandidate) -> its :class:`RecommendedDesign` with the run's fitted Q(v) (posterior draws as in the
    recommended design), at the candidate's posterior-median FEM result; None without a Q(v) fit."""
    from workflow.pipeline.domain import design_problems
    from workflow.pipeline.recommendation import fem_recommendation

    fit = context.results.damping_fit
    if fit is None:
        return None
    damping = context.config["damping"]
    draws = fit.answer.draws(damping["posterior_draws"], damping["seed"])
    problems = design_problems(context.config)
    target = context.config["design"]["target_deflection_um"] * UM
    return lambda hp, candidate: fem_recommendation(candidate.working, candidate.plate, problems[hp], draws, target)


def robust_recommendation(context: RunContext) -> Optional[RobustRecommendation]:
    """Per h_p of the run: the robust design under the built plates' calibration, beside the nominal optimum
    (the recommended design's geometry) checked the same way; None without a calibration."""
    from workflow.pipeline.loop import calibration_model

    built = context.results.built_calibration
    if built is None:
        return None
    section, design = context.config["recommendation"], context.config["design"]
    settings = RobustSettings(reliability=section["reliability"], min_frequency=design["min_frequency_khz"] * KHZ)
    model, _ = calibration_model(context)
    designs = context.results.recommended_design.designs
    nominals = {hp: d.plate for hp, d in designs.items()}
    stock = [t * MM for t in section["stock_hi_mm"] if design["hi_min_mm"] - 1e-9 <= t <= design["hi_max_mm"] + 1e-9]
    wavelengths = (design["wavelength_min_mm"] * MM, design["wavelength_max_mm"] * MM)
    sources = {hp: DESIGN_MODELS[d.model].model_label for hp, d in designs.items()}
    choices = robust_choices(built.calibration, nominals, stock, section["stocks_per_design"], settings,
                             model.design_fem(), design["q"], damped_evaluation(context), wavelengths, sources)
    return RobustRecommendation(choices, built.names, settings, design["q"])
