"""The steps of ``tactile run``, in order: campaign, optimisation, Q(v) fit and design, FEM, maps.

Each step reads the configuration and earlier results from the :class:`RunContext` and
returns a result; its figure function, if any, writes PNGs into the output folder.
"""

import sys
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Dict, List, Optional

import numpy as np

from workflow.errors import InputFileError, TactileError
from workflow.optimise.problem import optimise_analytical
from workflow.pipeline import loop
from workflow.pipeline import robust_recommendation as robust
from workflow.pipeline.calibration_files import CALIBRATION_OUTPUTS
from workflow.pipeline.damping_files import FIT_OUTPUTS, stated_noise, write_fit
from workflow.pipeline.domain import bench_settings, build_plate, design_problems, fem_model, fem_settings
from workflow.pipeline.runner import RunContext, Step
from workflow.units import KHZ, MM, UM


def analytical_optima(context: RunContext):
    """The beam-model optimum with constant Q for every h_p."""
    q = context.config["design"]["q"]
    return {hp: optimise_analytical(problem, q=q) for hp, problem in design_problems(context.config).items()}


def campaign_logs(context: RunContext) -> List[Path]:
    """The interferometer logs to fit: the given ones, or a campaign (sweeps, then ring-downs) on the simulated bench."""
    if context.logs:
        missing = [str(path) for path in context.logs if not Path(path).is_file()]
        if missing:
            raise TactileError(f"no such log file: {', '.join(missing)}")
        return [Path(path) for path in context.logs]
    from instruments.procedures.simulated import simulate_campaign, simulate_ringdown

    campaign = context.config["campaign"]
    settings = bench_settings(context.config)
    path = context.out / "simulated_campaign.csv"
    simulate_campaign(
        path,
        settings=settings,
        voltages=tuple(campaign["voltages_v"]),
        points_per_sweep=campaign["points_per_sweep"],
        span=campaign["span_hz"],
    )
    if not campaign["ringdown_voltages_v"]:
        return [path]
    ringdowns = context.out / "simulated_ringdown.csv"
    simulate_ringdown(ringdowns, settings, voltages=tuple(campaign["ringdown_voltages_v"]),
                      samples=campaign["ringdown_samples"], interval=campaign["ringdown_interval_us"] * 1e-6)
    return [path, ringdowns]


def damping_fit(context: RunContext):
    """Q(v) fitted to the logs with emcee (:func:`workflow.damping.fit.fit_damping`)."""
    from workflow.damping.fit import fit_damping, minimum_walkers
    from workflow.damping.logs import drop_short_sweeps, read_logs
    from workflow.execution.parallel import map_evaluations
    from workflow.models.limits import LIMITS

    damping = context.config["damping"]
    log = drop_short_sweeps(read_logs(context.results.logs, damping["mixed_plates"]))
    for warning in log.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    forward = run_forward_model(damping, log)
    bursts = 0 if log.ringdown is None else log.ringdown.n_bursts
    fewest = minimum_walkers(damping["laws"], log.n_sweeps, forward, bursts)
    if 0 < damping["walkers"] < fewest:
        raise InputFileError(
            f"configuration: 'damping.walkers' = {damping['walkers']} is outside the accepted range {fewest} to "
            f"{LIMITS['damping.walkers'][1]} for these logs (emcee needs twice the {fewest // 2} parameters "
            f"sampled with {log.n_sweeps} sweeps and {bursts} ring-downs; 0 chooses for each law)"
        )
    fit = fit_damping(
        log,
        laws=tuple(damping["laws"]),
        seed=damping["seed"],
        max_steps=damping["max_steps"],
        n_walkers=damping["walkers"] or None,
        forward=forward,
        progress=True,
        stated_noise=stated_noise(context.results.logs),
        mapper=partial(map_evaluations, scheduler=context.scheduler, description="laws sampled"),
    )
    if fit.warning:
        print(f"warning: {fit.warning}", file=sys.stderr)
    return fit


def run_forward_model(damping: dict, log):
    """The effects the run fits beyond Q(v) (keys ``damping.softening``, ``damping.drift``, ``damping.heating``): all
    need sweeps, the drift and the heating also the logs' ``timestamp_s`` (without it a warning, and they are not
    fitted)."""
    from workflow.damping.likelihood import ForwardModel

    timed = {}
    for effect, what in (("drift", "the drift within a sweep"), ("heating", "the heating within a sweep")):
        timed[effect] = damping[effect] and log.n_sweeps > 0
        if timed[effect] and log.timestamp is None:
            print(f"warning: damping.{effect}: the logs have no timestamp_s column; {what} is not fitted",
                  file=sys.stderr)
            timed[effect] = False
    return ForwardModel(softening=damping["softening"] and log.n_sweeps > 0, **timed)


def damping_fit_files(context: RunContext, fit) -> None:
    """The posterior, ``fit.json`` and the fit's figures under ``damping/``."""
    from workflow.pipeline.figures.damping import fit_figures

    protect = {Path(path).resolve() for path in context.results.logs}
    files = write_fit(fit, context.out / "damping", figures=True, protect=protect)
    captions = {name: caption for name, (caption, _) in fit_figures(fit).items()}
    for path in files["figures"]:
        context.record_figure(Path(path).relative_to(context.out).as_posix(), captions[Path(path).name])


def damped_design(context: RunContext):
    """Design with Q(v): optimum per h_p with credible intervals, and the Q(v) maps."""
    from workflow.optimise.damped import damped_maps, design_with_damping

    damping, design = context.config["damping"], context.config["design"]
    posterior = context.results.damping_fit.answer
    problems = design_problems(context.config)
    target = design["target_deflection_um"] * UM
    result = design_with_damping(
        posterior,
        list(problems.values()),
        draws=damping["posterior_draws"],
        seed=damping["seed"],
        target=target,
        scheduler=context.scheduler,
        progress=True,
    )
    maps = {
        hp: damped_maps(
            posterior,
            problem,
            grid=context.config["maps"]["grid"],
            draws=damping["posterior_draws"],
            seed=damping["seed"],
            target=target,
            optimum=result.optima[hp].damped,
        )
        for hp, problem in problems.items()
    }
    return result, maps


def damped_design_figures(context: RunContext, result) -> None:
    """Deflection and required-voltage maps with Q(v) for every h_p."""
    from workflow.pipeline.figures.damping import design_map_figure

    _, maps = result
    marks = {
        "design_voltage": context.config["design"]["voltage_v"],
        "voltage_limit": context.config["simulator"]["ceramic_voltage_limit_v"],
    }
    target = context.config["design"]["target_deflection_um"]
    captions = {"deflection": "beam model: deflection with Q(v) at the design voltage, h_p = {hp:g} mm",
                "voltage": f"beam model: voltage needed for {target:g} µm with Q(v), h_p = {{hp:g}} mm"}
    for hp, hp_maps in maps.items():
        for quantity, caption in captions.items():
            figure = design_map_figure(hp_maps, quantity, **marks)
            context.save_figure(figure, f"qv_{quantity}_hp{hp / MM:g}mm.png", caption.format(hp=hp / MM))


def fem_original(context: RunContext):
    """The FEM of the original plate (all evaluated modes)."""
    return fem_model(context).results(build_plate(context.config))[0]


def fem_original_figures(context: RunContext, result) -> None:
    from workflow.pipeline.figures.fem_responses import modes_figure

    context.save_figure(modes_figure(result), "fem_modes_original.png",
                        "deflection and transverse indicator of the evaluated modes")


def fem_responses(context: RunContext):
    """Frequency response around the working mode and the switch-on transient of the original plate."""
    from workflow.models.fem.responses import frequency_response, transient_response

    result, q = context.results.fem_original, context.config["design"]["q"]
    return frequency_response(result, q), transient_response(result, q)


def fem_responses_figures(context: RunContext, responses) -> None:
    from workflow.pipeline.figures.fem_responses import frequency_response_figure, transient_figure

    frequency, transient = responses
    context.save_figure(frequency_response_figure(frequency), "fem_frequency_response.png",
                        "frequency response |w|(f) around the working mode")
    context.save_figure(transient_figure(transient), "fem_transient.png", "deflection after a sine at resonance is switched on")


@dataclass(frozen=True)
class FemOptima:
    """The FEM optimum of one h_p by space mapping, and by direct NLopt when asked."""

    space_mapping: Any
    direct: Optional[Any] = None


def fem_optima(context: RunContext) -> Dict[float, FemOptima]:
    """FEM optimum per h_p by aggressive space mapping (and the direct NLopt run if configured);
    none when [fem] space_mapping is false."""
    from workflow.optimise.fem_optimum import optimise_fem

    if not context.config["fem"]["space_mapping"]:
        return {}
    model = fem_model(context)
    direct = context.config["fem"]["direct_nlopt"]
    return {
        hp: FemOptima(
            space_mapping=optimise_fem(problem, model, "space-mapping"),
            direct=optimise_fem(problem, model, "nlopt") if direct else None,
        )
        for hp, problem in design_problems(context.config).items()
    }


def fem_optima_figures(context: RunContext, optima) -> None:
    from workflow.pipeline.figures.space_mapping import trajectory_figure

    if not optima:
        return
    searches = {hp: (record.space_mapping, record.direct) for hp, record in optima.items()}
    minimum = context.config["design"]["min_frequency_khz"] * KHZ
    context.save_figure(trajectory_figure(searches, minimum), "space_mapping_trajectories.png",
                        "FEM points of each space-mapping search, numbered in order")


def recommended_design(context: RunContext):
    """The design to build per h_p, with Q(v) (:mod:`workflow.pipeline.recommendation`).

    The FEM optimum by space mapping where it ran, the beam optimum with Q(v) otherwise;
    the original plate with the FEM as a reference when its FEM ran.
    """
    from workflow.models.plate import ORIGINAL_PLATE
    from workflow.pipeline.recommendation import (
        Recommendation,
        beam_recommendation,
        fem_recommendation,
    )

    damping, design = context.config["damping"], context.config["design"]
    posterior = context.results.damping_fit.answer
    draws = posterior.draws(damping["posterior_draws"], damping["seed"])
    target = design["target_deflection_um"] * UM
    fem_optima = context.results.fem_optima or {}
    beam_optima = context.results.analytical_optima
    damped, _ = context.results.damped_design
    designs = {}
    for hp, problem in design_problems(context.config).items():
        if hp in fem_optima:
            optimum = fem_optima[hp].space_mapping.optimum
            (result,) = fem_model(context).results(optimum.plate)
            ratio = optimum.deflection / beam_optima[hp].deflection
            beam_voltage = float(damped.optima[hp].interval("required_voltage")[1])
            designs[hp] = fem_recommendation(result, optimum.plate, problem, draws, target, ratio, beam_voltage)
        else:
            designs[hp] = beam_recommendation(damped.optima[hp].damped.plate, problem, draws, target)
    original = None
    if context.results.fem_original is not None:
        (problem,) = design_problems(context.config, [ORIGINAL_PLATE.ceramic_thickness / MM]).values()
        original = fem_recommendation(context.results.fem_original, build_plate(context.config), problem, draws, target)
    return Recommendation(
        designs=designs,
        original=original,
        law=posterior.description,
        draws=damping["posterior_draws"],
    )


def recommended_design_figures(context: RunContext, recommendation) -> None:
    """The admittance of the FEM designs when the coupled piezoelectric model ran."""
    from workflow.pipeline.figures.fem_responses import admittance_figure

    curves = {
        f"h_p {hp / MM:g} mm": (*design.admittance, design.frequency, design.antiresonance)
        for hp, design in recommendation.designs.items()
        if design.admittance is not None
    }
    if curves:
        context.save_figure(admittance_figure(curves), "admittance.png",
                            "Admittance |Y| and phase of the recommended designs, with the plate's Q")


def texture_rendering(context: RunContext) -> dict:
    """Per recommended design: the grating periods it renders within 10 % at 50, 100 and 200 mm/s and its
    electrical load at the working amplitude (:func:`workflow.pipeline.rendering.design_rendering`).

    The gratings run between the least useful deflection and the target, within the bench's voltage limit, with
    the fitted Q(v) (posterior median) and softening; the load comes from the coupled piezoelectric FEM at the
    design's geometry (the run's accuracy when its FEM is the coupled one, else the survey accuracy).
    """
    from dataclasses import replace

    from workflow.damping.fit import parameter_summary
    from workflow.models.materials import MIN_USEFUL_DEFLECTION
    from workflow.pipeline.design_rendering import design_rendering

    config = context.config
    fit = context.results.damping_fit
    law = fit.answer.median_law()
    softening = parameter_summary(fit.best).get("kappa", {}).get("median", 0.0)
    accuracy = "accuracy" if config["fem"]["piezo"] == "coupled" else "survey_accuracy"
    coupled = fem_model(context, settings=replace(fem_settings(config, accuracy), piezo="coupled"))
    designs = context.results.recommended_design.designs
    results = coupled.evaluate_plates([design.plate for design in designs.values()])
    levels = (MIN_USEFUL_DEFLECTION, config["design"]["target_deflection_um"] * UM)
    limit = config["simulator"]["ceramic_voltage_limit_v"]
    return {hp: design_rendering(design, law, softening, limit, result, levels)
            for (hp, design), result in zip(designs.items(), results)}


def texture_rendering_figures(context: RunContext, renderings: dict) -> None:
    """Envelope error of gratings against their period, per design."""
    from workflow.pipeline.figures.rendering import period_error_figure

    context.save_figure(period_error_figure(renderings), "rendering_periods.png",
                        "Envelope error of gratings against their period in time, per design")


def calibrated_designs(context: RunContext) -> dict:
    """The recommended designs as the calibration (``--calibration``) predicts them: h_p [m] -> its
    :class:`~workflow.calibration.calibration.Prediction` (f_r and w_dyn with 90 % intervals, docs/calibration.md);
    empty without a calibration.  Q and voltage are the run's."""
    from dataclasses import replace

    from workflow.calibration.calibration import predict
    from workflow.pipeline.calibration_files import calibration_accuracy, load_calibration

    if context.calibration is None:
        return {}
    calibration = load_calibration(context.calibration)
    model = replace(fem_model(context, settings=calibration_accuracy(calibration.fem)), scheduler="synchronous",
                    progress=False)
    designs = context.results.recommended_design.designs
    return {hp: predict(calibration, d.plate, model.design_fem()) for hp, d in designs.items()}


def analytical_maps(context: RunContext):
    """Beam-model maps of w_dyn and f_r over (lambda, h_i) for every h_p, with the optimum."""
    from workflow.optimise.maps import design_map
    from workflow.optimise.problem import analytical_model

    design = context.config["design"]
    model = analytical_model(design["q"], design["voltage_v"])
    optima = context.results.analytical_optima
    return {
        hp: design_map(model, problem, context.config["maps"]["grid"], "analytical", optima[hp])
        for hp, problem in design_problems(context.config).items()
    }


def fem_maps(context: RunContext):
    """FEM maps over a (coarse by default) (lambda, h_i) grid for the configured h_p values."""
    from workflow.optimise.maps import design_map

    problems = design_problems(context.config, context.config["maps"]["fem_ceramic_thicknesses_mm"])
    optima = context.results.fem_optima or {}
    model = fem_model(context, accuracy="survey_accuracy")
    return {
        hp: design_map(
            model,
            problem,
            context.config["maps"]["fem_grid"],
            "fem",
            optima[hp].space_mapping.optimum if hp in optima else None,
            model.results,
        )
        for hp, problem in problems.items()
    }


def maps_figures(context: RunContext, maps) -> None:
    """One two-panel contour figure per map."""
    from workflow.pipeline.figures.maps import map_figure, map_file

    for hp, design_map in maps.items():
        context.save_figure(map_figure(design_map), map_file(design_map),
                            f"{design_map.model} model, h_p = {hp / MM:g} mm: w_dyn and f_r")


def sweep_widths(fem: dict, plate_width: float) -> np.ndarray:
    """Widths of the sweep [m]: the coarse range, the fine range around the plate's own width
    (``fine_width_min_mm`` to ``fine_width_max_mm`` every ``fine_width_step_mm``), and ``plate_width``."""
    step = fem["fine_width_step_mm"]
    if step <= 0:
        raise TactileError(f"fem.fine_width_step_mm must be positive, got {step!r}")
    fine_points = int(np.floor((fem["fine_width_max_mm"] - fem["fine_width_min_mm"]) / step + 1e-9)) + 1
    widths_mm = np.concatenate(
        [
            np.linspace(fem["width_min_mm"], fem["width_max_mm"], fem["width_points"]),
            fem["fine_width_min_mm"] + step * np.arange(max(fine_points, 0)),
            [plate_width / MM],
        ]
    )
    return np.unique(np.round(widths_mm, 9)) * MM


def fem_width_sweep(context: RunContext):
    """w(b) and f(b) of the original plate with the FEM, coarse and finely around its width."""
    from workflow.optimise.maps import width_sweep

    plate = build_plate(context.config)
    widths = sweep_widths(context.config["fem"], plate.width)
    return width_sweep(fem_model(context, accuracy="survey_accuracy"), plate, widths)


def width_sweep_figures(context: RunContext, sweep) -> None:
    from workflow.pipeline.figures.maps import WIDTH_SWEEP_FILE, width_sweep_figure

    design_width = context.config["design"]["width_mm"] * MM
    context.save_figure(width_sweep_figure(sweep, design_width=design_width), WIDTH_SWEEP_FILE,
                        "w(b) and f(b); transverse-mixed widths marked")


RUN_OUTPUTS = ("report.md", "simulated_campaign.csv", "simulated_ringdown.csv", "*.png", *(f"damping/{pattern}" for pattern in FIT_OUTPUTS),
               *(f"{loop.LOOP_FOLDER}/{pattern}" for pattern in loop.LOOP_OUTPUTS),
               *(f"{robust.CALIBRATION_FOLDER}/{name}" for name in CALIBRATION_OUTPUTS))
"""Glob patterns of the files ``tactile run`` writes into its output folder (:mod:`workflow.pipeline.outputs`)."""

STEPS: List[Step] = [
    Step("interferometer logs (simulated campaign unless --logs)", "logs", campaign_logs, cacheable=False),
    Step("analytical optimisation (constant Q)", "analytical_optima", analytical_optima, cacheable=False),
    Step("Q(v) fit (emcee)", "damping_fit", damping_fit, damping_fit_files),
    Step("design with Q(v) and posterior propagation", "damped_design", damped_design, damped_design_figures),
    Step("FEM of the original plate", "fem_original", fem_original, fem_original_figures, cacheable=False),
    Step("FEM responses of the original plate", "fem_responses", fem_responses, fem_responses_figures),
    Step("FEM optimum per h_p (space mapping)", "fem_optima", fem_optima, fem_optima_figures),
    Step("recommended design per h_p", "recommended_design", recommended_design, recommended_design_figures,
         cacheable=False),
    Step("calibration on the measured built plates (published P1, P2 and --built-plates)", "built_calibration",
         robust.built_calibration, robust.built_calibration_files),
    Step("robust design per h_p under that calibration", "robust_recommendation", robust.robust_recommendation),
    Step("texture rendering and electrical load per design", "texture_rendering", texture_rendering,
         texture_rendering_figures, cacheable=False),
    Step("calibrated predictions of the designs (--calibration)", "calibrated_designs", calibrated_designs, cacheable=False),
    Step("loop: plate #1 built and measured on the simulator", "loop_first_plate", loop.first_plate,
         loop.first_plate_figures, cacheable=False),
    Step("loop: calibration on plate #1 (emcee)", "loop_calibration", loop.loop_calibration, loop.loop_calibration_files),
    Step("loop: robust re-design under the calibration", "loop_redesign", loop.redesign),
    Step("loop: re-designed plate built and measured", "loop_second_plate", loop.second_plate, cacheable=False),
    Step("case study: P1 and P2 predict each other", "case_study", loop.case_study),
    Step("analytical maps", "analytical_maps", analytical_maps, maps_figures, cacheable=False),
    Step("FEM maps", "fem_maps", fem_maps, maps_figures),
    Step("FEM width sweep of the original plate", "width_sweep", fem_width_sweep, width_sweep_figures),
]
"""The steps in the order they run."""
