"""``tactile optimize``: the geometry of maximum deflection with f_r >= 25 kHz."""

from workflow.cli.options import (
    accuracy_line,
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
    design_problem,
    fem_accuracy,
    load_damping,
)
from workflow.optimise.damped import damped_fem_optimum, damped_optimum
from workflow.optimise.fem_optimum import METHODS, optimise_fem
from workflow.optimise.problem import optimise_analytical
from workflow.pipeline.records import damped_optimum_record, fem_accuracy_record, fem_damping_record, optimum_record

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
    add_fem_options(parser)
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def _fem_model(args):
    """The cached, parallel FEM at --q, --voltage and --accuracy."""
    from workflow.execution.cache import EvaluationCache
    from workflow.optimise.fem_model import FemModel

    return FemModel(q=args.q, voltage=args.voltage, settings=fem_accuracy(args), cache=EvaluationCache(), progress=True)


def run(args) -> dict:
    records = []
    posterior = load_damping(args)
    for ceramic_thickness in ceramic_thicknesses(args):
        problem = design_problem(args, ceramic_thickness)
        if args.model == "analytical" and posterior is not None:
            optimum = damped_optimum(posterior.median_law(), problem)
            extra = damped_optimum_record(posterior, optimum)
            records.append(optimum_record(optimum, coarse_evaluations=optimum.evaluations, **extra))
        elif args.model == "analytical":
            optimum = optimise_analytical(problem, q=args.q)
            records.append(optimum_record(optimum, coarse_evaluations=optimum.evaluations))
        else:
            extra = {}
            if posterior is None:
                found = optimise_fem(problem, _fem_model(args), args.method)
            else:
                found, result = damped_fem_optimum(posterior.median_law(), problem, _fem_model(args), args.method)
                extra = fem_damping_record(posterior, result)
            counts = dict(
                method=found.method, fine_evaluations=found.fine_evaluations, coarse_evaluations=found.coarse_evaluations
            )
            accuracy = {}
            if found.error is not None:
                accuracy = {
                    **fem_accuracy_record(found.error),
                    "verified": found.verified,
                    "verification_evaluations": found.verification_evaluations,
                }
            records.append({**optimum_record(found.optimum, **counts), **accuracy, **extra})
    if not args.json:
        for record in records:
            _print_human(record)
    return records[0] if len(records) == 1 else {"optima": records}


def _print_human(record: dict) -> None:
    """One optimum for people: geometry, deflection, resonance, evaluation counts, the Q(v) law if used."""
    names = (("fine_evaluations", "FEM"), ("verification_evaluations", "accurate FEM"), ("coarse_evaluations", "beam"))
    counts = [f"{record[key]} {name} evaluations" for key, name in names if key in record]
    method = f"{record['method']}: " if "method" in record else ""
    print(
        f"h_p {record['h_p_mm']:g} mm: lambda {record['lambda_mm']:.4f} mm, h_i {record['h_i_mm']:.4f} mm -> "
        f"w_dyn {record['w_dyn_um']:.4f} µm at f_r {record['f_r_khz']:.3f} kHz ({method}{', '.join(counts)})"
    )
    if "f_error_estimate" in record:
        print(accuracy_line(record))
        if not record["verified"]:
            print("  WARNING: f_r >= limit not verified on the converged model (see the accuracy line)")
    if "damping" in record:
        print(damping_line(record))
