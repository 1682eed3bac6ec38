"""``tactile maps``: w_dyn and f_r over (lambda, h_i) for one h_p, and the FEM width sweep.

With ``--damping POSTERIOR`` the deflection uses the posterior-median Q(v), solved
self-consistently at every grid point, and a map of the voltage for the target deflection
(median law, and p05/p95 over posterior draws) is added.
"""

from pathlib import Path

from workflow.cli.options import (
    add_ceramic_option,
    add_calibration_option,
    add_damping_option,
    add_drive_options,
    add_fem_options,
    add_force_option,
    add_hi_min_option,
    add_json_flag,
    add_model_option,
    add_width_option,
    bounded,
    build_plate,
    calibration_fem_model,
    design_model,
    design_problem,
    limit_text,
    load_calibration_option,
    load_damping,
)
from workflow.pipeline.design_models import DESIGN_MODELS
from workflow.errors import TactileError
from workflow.models.fem.accuracy import SURVEY_ACCURACY
from workflow.optimise.damped import map_draws
from workflow.optimise.maps import width_sweep
from workflow.models.limits import LIMITS
from workflow.pipeline.outputs import output_folder, save_figure
from workflow.pipeline.records import grid_record, point_record, q_of_v_record, width_sweep_record
from workflow.units import MM

OUTPUTS = ("*.png",)
"""Glob patterns of the files the command writes into --out (:mod:`workflow.pipeline.outputs`)."""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "maps",
        help="contour maps of deflection and resonance over (lambda, h_i)",
        description="Evaluate the deflection and the resonance frequency on a grid over the whole "
        "Table 1 box of wavelength and resonator thickness for one ceramic thickness, mark the 25 kHz "
        "line, the h_i limit and the optimum, and write the maps as PNG. With --model fem the "
        "evaluations are cached on disk ($TACTILE_CACHE, else the user cache folder, ~/.cache/tactile on Linux) and run on the local "
        "cores, or on a Dask cluster with --scheduler.",
    )
    add_model_option(parser)
    add_ceramic_option(parser, required=True)
    add_hi_min_option(parser)
    add_width_option(parser)
    add_drive_options(parser)
    add_damping_option(parser)
    add_calibration_option(parser)
    add_fem_options(parser, accuracy=SURVEY_ACCURACY)
    parser.add_argument(
        "--grid",
        type=bounded(int, *LIMITS["maps.grid"]),
        help=f"points per axis, {limit_text('maps.grid')} (default: "
        + ", ".join(f"{kind.default_grid} {kind.label}" for kind in DESIGN_MODELS.values()) + ")",
    )
    parser.add_argument("--scheduler", metavar="ADDRESS", help="tcp://host:port of a Dask scheduler (default: local cores)")
    parser.add_argument(
        "--width-sweep",
        action="store_true",
        help="FEM only: also sweep the original plate's width, 30-100 mm and every 1 mm over 45-56 mm "
        "(the widths of tactile run)",
    )
    parser.add_argument("--out", type=Path, default=Path("reports"), help="folder for the PNG figures (default: reports/)")
    add_force_option(parser)
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args) -> dict:
    model = design_model(args, args.scheduler)
    points = model.default_grid if args.grid is None else args.grid
    if args.width_sweep and not model.resolves_width:
        raise TactileError("maps: --width-sweep needs --model fem (the beam model does not depend on b)")
    problem = design_problem(args, args.hp_mm * MM)
    posterior = load_damping(args)
    calibration = load_calibration_option(args)
    if calibration is not None and (not model.calibrated or posterior is not None):
        raise TactileError("maps: --calibration corrects the FEM with a constant Q: give --model fem and no --damping")
    args.loaded_calibration = calibration
    with output_folder(args.out, OUTPUTS, force=args.force):
        record = _maps(args, model, problem, posterior, points)
    if not args.json:
        o = record["optimum"]
        damping = "" if posterior is None else f" with {posterior.description} Q(v)"
        voltage = "" if posterior is None else f", {o['required_voltage_v']['p50']:.3g} V for the target"
        print(
            f"{args.model} map {points}x{points}{damping}, h_p {args.hp_mm:g} mm: optimum lambda {o['lambda_mm']:.3f} mm, "
            f"h_i {o['h_i_mm']:.3f} mm, w_dyn {o['w_dyn_um']:.3f} µm at {o['f_r_khz']:.2f} kHz{voltage}; figures: "
            + ", ".join(record["figures"])
        )
    return record


def _maps(args, model, problem, posterior, points: int) -> dict:
    """The maps' record, their figures written into --out."""
    if posterior is None:
        record = _constant_q_record(args, problem, model, points)
    else:
        record = _damped_record(args, problem, model, points, posterior)
    if args.width_sweep:
        from workflow.pipeline.config import default_config
        from workflow.pipeline.figures.maps import WIDTH_SWEEP_FILE, width_sweep_figure
        from workflow.pipeline.steps import sweep_widths

        plate = build_plate(args)
        sweep = width_sweep(model.plate_model, plate, sweep_widths(default_config()["fem"], plate.width))
        figure = width_sweep_figure(sweep, design_width=args.b_mm * MM)
        record["figures"].append(save_figure(figure, args.out / WIDTH_SWEEP_FILE))
        record["width_sweep"] = width_sweep_record(sweep)
    return record


def _constant_q_record(args, problem, model, points: int) -> dict:
    """Map and optimum with the constant --q."""
    from workflow.pipeline.figures.maps import map_figure, map_file

    optimum = model.optimum(problem)
    result = model.design_map(problem, points, optimum)
    correction = {}
    if getattr(args, "loaded_calibration", None) is not None:
        result, optimum, correction = calibrated_map(args, result, optimum)
    figure = save_figure(map_figure(result), args.out / map_file(result))
    return {
        **grid_record(args.model, problem, result),
        "optimum": point_record(optimum),
        "figures": [figure],
        **correction,
    }


def calibrated_map(args, result, optimum):
    """The map and optimum scaled by the calibration's posterior-median over nominal f_r and w at the optimum,
    and the ``calibration`` key stating it (a relative correction from one geometry, docs/calibration.md)."""
    import dataclasses

    from workflow.calibration.calibration import predict
    from workflow.pipeline.calibration_files import calibrated_record

    model = calibration_fem_model(args.loaded_calibration, args.q, args.voltage)
    prediction = predict(args.loaded_calibration, optimum.plate, model.design_fem())
    record = calibrated_record(prediction, args.calibration)
    f_factor = prediction.frequency[1] / optimum.frequency
    w_factor = prediction.deflection[1] / optimum.deflection
    result = dataclasses.replace(result, frequency=result.frequency * f_factor, deflection=result.deflection * w_factor)
    optimum = dataclasses.replace(optimum, frequency=optimum.frequency * f_factor, deflection=optimum.deflection * w_factor)
    statement = (f"calibrated: every point scaled by the posterior-median / nominal FEM ratio at the nominal optimum "
                 f"(f_r x {f_factor:.4f}, w_dyn x {w_factor:.4f}); the optimum marked is the nominal one")
    return result, optimum, {"calibration": {**record["calibration"], "frequency_factor": f_factor,
                                             "deflection_factor": w_factor, "statement": statement,
                                             "optimum_f_r_khz_p05": record["f_r_khz_p05"],
                                             "optimum_f_r_khz_p95": record["f_r_khz_p95"]}}


def _damped_record(args, problem, model, points: int, posterior) -> dict:
    """Maps and optimum with the posterior-median Q(v), and the required-voltage map."""
    from workflow.pipeline.figures.damping import design_map_figure

    draws = map_draws(points)
    found, maps = model.damped(posterior, problem, points, draws)
    keys = q_of_v_record(found.q_of_v)
    stem = f"map_{args.model}_qv_hp{args.hp_mm:g}mm"
    figures = [
        save_figure(design_map_figure(maps, quantity, design_voltage=args.voltage), args.out / f"{stem}_{quantity}.png") for quantity in ("deflection", "voltage")
    ]
    p05, _, p95 = maps.required_voltage_interval
    return {
        **grid_record(args.model, problem, maps),
        "required_voltage_v": maps.required_voltage.tolist(),
        "required_voltage_v_p05": p05.tolist(),
        "required_voltage_v_p95": p95.tolist(),
        "target_um": keys["required_voltage_v"]["target_um"],
        "draws": draws,
        "damping": keys["damping"],
        "optimum": {**point_record(found.optimum), "q": keys["q"], "required_voltage_v": keys["required_voltage_v"]},
        "figures": figures,
    }
