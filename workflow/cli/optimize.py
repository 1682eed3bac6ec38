"""``tactile optimize``: the geometry of maximum deflection with f_r >= 25 kHz."""

from workflow.cli.options import (
    accuracy_line,
    add_calibration_option,
    bounded,
    calibration_fem_model,
    load_calibration_option,
    add_ceramic_option,
    add_damping_option,
    add_drive_options,
    add_fem_options,
    add_hi_min_option,
    add_json_flag,
    add_model_option,
    add_width_option,
    ceramic_thicknesses,
    damping_line,
    design_model,
    design_problem,
    limit_text,
    load_damping,
)
from workflow.pipeline.design_models import DESIGN_MODELS
from workflow.errors import TactileError
from workflow.models.limits import LIMITS
from workflow.optimise.robust import RobustSettings, Tolerances
from workflow.pipeline.records import design_optimum_record
from workflow.units import KHZ, MM, UM
from workflow.optimise.fem_optimum import METHODS

DEFAULT_METHOD = "space-mapping"
"""--method when not given: a handful of FEM evaluations instead of the direct run's dozens."""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "optimize",
        help="maximise the deflection subject to f_r >= 25 kHz",
        description="Maximise the antinode deflection at the drive voltage over the wavelength and the "
        "resonator thickness, subject to a resonance frequency of at least 25 kHz, for one ceramic "
        "thickness (or all of them when --hp-mm is omitted).",
    )
    add_model_option(parser)
    parser.add_argument(
        "--method",
        choices=METHODS,
        default=DEFAULT_METHOD,
        help="FEM only: space mapping, which steers the beam model with a few FEM evaluations (4 for h_p = 1 mm "
        "at b = 49 mm), or NLopt directly on the FEM from the beam optimum (54 FEM evaluations there, about five "
        f"times longer) (default: {DEFAULT_METHOD})",
    )
    add_ceramic_option(parser, required=False)
    add_hi_min_option(parser)
    add_width_option(parser)
    add_drive_options(parser)
    add_damping_option(parser)
    add_calibration_option(parser)
    robust = parser.add_argument_group("robust design (with --calibration and --model fem, docs/calibration.md)")
    defaults, tolerances = RobustSettings(), Tolerances()
    robust.add_argument("--reliability", type=bounded(float, *LIMITS["reliability"]), default=defaults.reliability,
                        help="required P(f_r >= 25 kHz) under the calibration posterior and the tolerances, "
                        f"{limit_text('reliability')} (default {defaults.reliability:g})")
    robust.add_argument("--stock-hi-mm", type=stock_list, default=DEFAULT_STOCK_MM, metavar="LIST",
                        help="comma-separated resonator thicknesses available [mm]; lambda is solved for each "
                        f"(default {','.join(f'{t:g}' for t in DEFAULT_STOCK_MM)})")
    for name, what, field in (("hi", "h_i", "resonator_thickness"), ("hp", "h_p", "ceramic_thickness"),
                              ("lambda", "lambda", "wavelength"), ("glue", "the glue", "glue_thickness")):
        default = getattr(tolerances, field) / UM
        robust.add_argument(f"--sigma-{name}-um", type=bounded(float, 0.0, 1000.0, "um"), default=default,
                            help=f"manufacturing standard deviation of {what} [um], 0 to 1000 (default {default:g})")
    robust.add_argument("--separation", type=bounded(float, 0.0, 0.5), default=defaults.separation,
                        help="no strongly transverse mode within this relative distance of the working frequency "
                        f"(default {defaults.separation:g})")
    robust.add_argument("--transverse-threshold", type=bounded(float, 0.0, 1.0), default=defaults.transverse_threshold,
                        help="transverse indicator above which a mode counts as transverse, 0 to 1 "
                        f"(default {defaults.transverse_threshold:g})")
    add_fem_options(parser)
    add_json_flag(parser)
    parser.set_defaults(handler=run)


DEFAULT_STOCK_MM = (0.5, 0.6, 0.7, 0.75, 0.8, 1.0)
"""Resonator thicknesses assumed in stock when --stock-hi-mm is not given [mm]."""


def stock_list(text: str) -> tuple:
    """argparse type: comma-separated positive thicknesses [mm]."""
    import argparse

    try:
        values = tuple(float(item) for item in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated thicknesses in mm, got {text!r}") from None
    if not values or any(not (0 < v < 100) for v in values):
        raise argparse.ArgumentTypeError(f"thicknesses must be positive numbers of mm, got {text!r}")
    return values


def run(args) -> dict:
    calibration = load_calibration_option(args)
    if calibration is not None:
        return _robust(args, calibration)
    posterior = load_damping(args)
    model = design_model(args)
    optima = [model.design_optimum(design_problem(args, h_p), posterior, args.method) for h_p in ceramic_thicknesses(args)]
    if not args.json:
        for found in optima:
            _print_human(found)
    records = [design_optimum_record(found) for found in optima]
    return records[0] if len(records) == 1 else {"optima": records}


def _print_human(found) -> None:
    """One optimum for people: geometry, deflection, resonance, evaluation counts, the Q(v) law if used."""
    optimum, search, damped = found.optimum, found.fem_search, found.q_of_v
    counts = [] if search is None else [f"{search.fine_evaluations} FEM evaluations"]
    if search is not None and search.error is not None:
        counts.append(f"{search.verification_evaluations} accurate FEM evaluations")
    counts.append(f"{found.coarse_evaluations} beam evaluations")
    method = "" if search is None else f"{search.method}: "
    deflection = optimum.deflection if damped is None else damped.deflection
    print(
        f"h_p {optimum.plate.ceramic_thickness / MM:g} mm: lambda {optimum.plate.wavelength / MM:.4f} mm, "
        f"h_i {optimum.plate.resonator_thickness / MM:.4f} mm -> w_dyn {deflection / UM:.4f} µm at "
        f"f_r {optimum.frequency / KHZ:.3f} kHz ({method}{', '.join(counts)})"
    )
    if search is not None and search.error is not None:
        print(accuracy_line(search.error))
        if not search.verified:
            print("  WARNING: f_r >= limit not verified on the converged model (see the accuracy line)")
    if damped is not None:
        print(damping_line(damped))


def _robust(args, calibration) -> dict:
    """The robust optimum under --calibration for each h_p asked for."""
    import time

    from workflow.models.plate import check_design_space
    from workflow.optimise.robust import robust_design
    from workflow.pipeline.calibration_files import robust_record

    if not DESIGN_MODELS[args.model].calibrated:
        raise TactileError("--calibration corrects the FEM: give --model fem")
    if args.damping is not None:
        raise TactileError("--calibration and --damping cannot be combined yet: the robust design uses the constant --q")
    settings = RobustSettings(
        reliability=args.reliability,
        separation=args.separation,
        transverse_threshold=args.transverse_threshold,
        tolerances=Tolerances(args.sigma_hi_um * UM, args.sigma_hp_um * UM, args.sigma_lambda_um * UM, args.sigma_glue_um * UM),
    )
    model = calibration_fem_model(calibration, args.q, args.voltage)
    records = []
    for ceramic_thickness in ceramic_thicknesses(args):
        problem = design_problem(args, ceramic_thickness)
        stock = [t * MM for t in args.stock_hi_mm]
        for thickness in stock:
            if thickness < problem.min_resonator_thickness - 1e-12:
                raise TactileError(f"--stock-hi-mm {thickness / MM:g} is below --hi-min-mm {args.hi_min_mm:g}")
        nominal = check_design_space(problem.build.with_(ceramic_thickness=ceramic_thickness, width=problem.width,
                                                          resonator_thickness=stock[0]))
        started = time.perf_counter()
        design = robust_design(calibration, nominal, stock, settings, model.design_fem(), args.q)
        records.append({**robust_record(design, args.reliability, time.perf_counter() - started), "calibration": args.calibration})
    if not args.json:
        for record in records:
            _print_robust(record)
    return records[0] if len(records) == 1 else {"optima": records}


def _print_robust(record: dict) -> None:
    print(f"robust optimum, h_p {record['h_p_mm']:g} mm: h_i {record['h_i_mm']:g} mm (stock), lambda {record['lambda_mm']:.3f} mm "
          f"-> f_r {record['f_r_khz']:.3f} kHz (p05 {record['f_r_khz_p05']:.3f}), w_dyn {record['w_dyn_um']:.4f} µm; "
          f"P(f_r >= 25 kHz) = {record['probability']:.3f} ± {record['probability_se']:.3f} "
          f"({record['probability_draws']} draws), margin {record['margin_khz'] * 1e3:+.0f} Hz; "
          f"{record['fine_evaluations']} FEM evaluations, {record['wall_time_s']:.0f} s")
    for c in record["candidates"]:
        nearest = c["nearest_transverse"]
        separation = "no transverse mode near" if nearest is None else (
            f"transverse mode at {nearest['f_khz']:.3f} kHz ({nearest['relative_distance'] * 100:.1f} % away)")
        print(f"  h_i {c['h_i_mm']:g} mm: lambda {c['lambda_mm']:.3f} mm, f_r {c['f_r_khz']:.3f} kHz (p05 {c['f_r_khz_p05']:.3f}), "
              f"w_dyn {c['w_dyn_um']:.4f} µm, P {c['probability']:.3f}, {separation}"
              f"{'' if c['separated'] else ' (REJECTED)'}, |w| spread {c['homogeneity_cv'] * 100:.0f} %")
