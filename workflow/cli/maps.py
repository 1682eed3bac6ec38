"""``tactile maps``: w_dyn and f_r over (lambda, h_i) for one h_p, and the FEM width sweep."""

from pathlib import Path

from ..errors import TactileError
from ..evaluation_cache import EvaluationCache
from ..fem_optimum import optimise_fem
from ..maps import design_map, width_sweep
from ..optimize import analytical_model, optimise_analytical
from ..units import KHZ, MM, UM
from . import add_json_flag
from .options import (
    add_ceramic_option,
    add_hi_min_option,
    add_drive_options,
    add_model_option,
    add_width_option,
    design_problem,
)

DEFAULT_GRID = {"analytical": 81, "fem": 12}
"""Grid points per axis when --grid is not given."""
MAX_GRID = 400
"""Largest accepted --grid."""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "maps",
        help="contour maps of deflection and resonance over (lambda, h_i)",
        description="Evaluate the deflection and the resonance frequency on a grid over the whole "
        "Table 1 box of wavelength and resonator thickness for one ceramic thickness, mark the 25 kHz "
        "line, the h_i limit and the optimum, and write the maps as PNG. With --model fem the "
        "evaluations are cached on disk ($TACTILE_CACHE or .cache/tactile) and run on the local "
        "cores, or on a Dask cluster with --scheduler.",
    )
    add_model_option(parser)
    add_ceramic_option(parser, required=True)
    add_hi_min_option(parser)
    add_width_option(parser)
    add_drive_options(parser)
    parser.add_argument(
        "--grid",
        type=int,
        help=f"points per axis (default: {DEFAULT_GRID['analytical']} analytical, {DEFAULT_GRID['fem']} FEM)",
    )
    parser.add_argument("--scheduler", metavar="ADDRESS", help="tcp://host:port of a Dask scheduler (default: local cores)")
    parser.add_argument("--width-sweep", action="store_true", help="FEM only: also sweep the original plate's width 30-100 mm")
    parser.add_argument("--out", type=Path, default=Path("reports"), help="folder for the PNG figures (default: reports/)")
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args) -> dict:
    points = DEFAULT_GRID[args.model] if args.grid is None else args.grid
    if not 2 <= points <= MAX_GRID:
        raise TactileError(f"maps: --grid {points} must be between 2 and {MAX_GRID}")
    if args.width_sweep and args.model != "fem":
        raise TactileError("maps: --width-sweep needs --model fem (the beam model does not depend on b)")
    problem = design_problem(args, args.hp_mm * MM)
    if args.model == "analytical":
        model, optimum = analytical_model(args.q, args.voltage), optimise_analytical(problem, args.q)
    else:
        from ..fem_evaluations import FemModel

        model = FemModel(
            q=args.q, voltage=args.voltage, cache=EvaluationCache(), scheduler=args.scheduler, progress=not args.json
        )
        optimum = optimise_fem(problem, model, "space-mapping").optimum
    result = design_map(model, problem, points, args.model, optimum)
    from ..figures.maps import map_figure, width_sweep_figure

    args.out.mkdir(parents=True, exist_ok=True)
    figures = [_save(map_figure(result), args.out / f"map_{args.model}_hp{args.hp_mm:g}mm.png")]
    record = {
        "model": args.model,
        "h_p_mm": args.hp_mm,
        "b_mm": args.b_mm,
        "lambda_mm": (result.wavelength / MM).tolist(),
        "h_i_mm": (result.resonator_thickness / MM).tolist(),
        "w_dyn_um": (result.deflection / UM).tolist(),
        "f_r_khz": (result.frequency / KHZ).tolist(),
        "optimum": {
            "lambda_mm": optimum.plate.wavelength / MM,
            "h_i_mm": optimum.plate.resonator_thickness / MM,
            "w_dyn_um": optimum.deflection / UM,
            "f_r_khz": optimum.frequency / KHZ,
        },
        "figures": figures,
    }
    if args.width_sweep:
        sweep = width_sweep(model)
        figures.append(_save(width_sweep_figure(sweep), args.out / "width_sweep_fem.png"))
        record["width_sweep"] = {
            "b_mm": (sweep.width / MM).tolist(),
            "w_dyn_um": (sweep.deflection / UM).tolist(),
            "f_r_khz": (sweep.frequency / KHZ).tolist(),
            "transverse": sweep.transverse.tolist(),
        }
    if not args.json:
        o = record["optimum"]
        print(
            f"{args.model} map {points}x{points}, h_p {args.hp_mm:g} mm: optimum lambda {o['lambda_mm']:.3f} mm, "
            f"h_i {o['h_i_mm']:.3f} mm, w_dyn {o['w_dyn_um']:.3f} um at {o['f_r_khz']:.2f} kHz; figures: "
            + ", ".join(figures)
        )
    return record


def _save(figure, path: Path) -> str:
    import matplotlib.pyplot as plt

    figure.savefig(path, dpi=120)
    plt.close(figure)
    return str(path)
