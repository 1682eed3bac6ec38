"""``tactile run``: the whole job on embedded defaults."""

import sys
from pathlib import Path

from workflow.cli.options import (
    add_calibration_option,
    add_fem_options,
    add_force_option,
    add_json_flag,
    add_mixed_plates_option,
    load_calibration_option,
    override_config,
)
from workflow.execution.cache import EvaluationCache
from workflow.pipeline.config import load_config, to_toml
from workflow.pipeline.outputs import output_folder
from workflow.pipeline.report import write_report
from workflow.pipeline.robust_recommendation import own_plates
from workflow.pipeline.runner import RunContext, run_steps
from workflow.pipeline.steps import RUN_OUTPUTS, STEPS


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "run",
        help="the whole job: campaign, Q(v) fit, optimisation, maps, report",
        description="Run the whole workflow on the embedded defaults (no hardware needed): simulated "
        "campaign (or --logs), Q(v) fit, optimisation with constant Q and with Q(v), maps, FEM steps, "
        "and a markdown report with its figures.",
    )
    parser.add_argument("--config", type=Path, help="TOML file overriding the embedded defaults")
    parser.add_argument("--out", type=Path, default=Path("reports"), help="output folder (default: reports/)")
    add_force_option(parser)
    parser.add_argument("--logs", type=Path, nargs="+", help="interferometer logs to fit instead of a simulated campaign")
    parser.add_argument("--built-plates", type=Path, nargs="+", metavar="LOG",
                        help="built-plate logs of your plates (resonance search, and a deflection scan where there is "
                        "one) to calibrate the FEM on, besides the published P1 and P2; the recommended design per h_p "
                        "is then robust under that calibration (default: the configuration's [recommendation] "
                        "built_plates, none)")
    parser.add_argument("--scheduler", help="tcp://host:port of a Dask scheduler (default: local cores)")
    parser.add_argument("--print-config", action="store_true",
                        help="print the effective configuration (each key with its unit and what it sets) and exit")
    add_fem_options(parser, overrides=True)
    add_mixed_plates_option(parser, overrides=True)
    add_calibration_option(parser)
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args):
    config = override_config(load_config(args.config), args)
    if args.built_plates:
        config["recommendation"]["built_plates"] = [str(path) for path in args.built_plates]
        if not config["recommendation"]["robust"]:
            print("tactile run: warning: --built-plates is not used: the configuration's [recommendation] robust is "
                  "false", file=sys.stderr)
    if args.print_config:
        print(to_toml(config, comments=True), end="")
        return None
    load_calibration_option(args)  # a bad file fails before any step
    warnings = []
    own_plates(config, warnings)  # a bad built-plate log fails before any step
    for warning in warnings:
        print(f"tactile run: warning: {warning}", file=sys.stderr)
    with output_folder(args.out, RUN_OUTPUTS, force=args.force) as out:
        context = RunContext(
            config=config,
            out=out,
            scheduler=args.scheduler or config["run"]["scheduler"] or None,
            logs=list(args.logs or config["campaign"]["logs"]),
            cache=EvaluationCache() if config["run"]["cache"] else None,
            calibration=None if args.calibration is None else Path(args.calibration),
        )
        if context.scheduler is not None:
            from workflow.execution.parallel import connect

            connect(context.scheduler).close()  # fail before any step, not in the middle of the run
        run_steps(context, STEPS)
        report = write_report(context)
    print(f"report: {report}", file=sys.stderr if args.json else sys.stdout)
    return {
        "report": str(report),
        "figures": sorted(context.figures),
        "timings_s": {t.name: round(t.seconds, 3) for t in context.timings},
        "from_cache": [t.name for t in context.timings if t.cached],
    }
