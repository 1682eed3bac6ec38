"""``tactile calibrate``: infer the uncertain model parameters from built plates' measured resonances."""

import sys
import time
from pathlib import Path

from workflow.calibration.calibration import calibrate
from workflow.calibration.parameters import load_settings
from workflow.cli.options import (
    add_fem_options,
    add_force_option,
    add_json_flag,
    add_mixed_plates_option,
    command_fem_model,
    fem_accuracy,
)
from workflow.models import materials
from workflow.pipeline.calibration_files import CALIBRATION_OUTPUTS, calibration_summary, measured_plates, write_calibration
from workflow.pipeline.outputs import output_folder


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "calibrate",
        help="calibrate the FEM to built plates (emcee over a surrogate)",
        description="Infer the ceramic and resonator moduli (as factors), the glue thickness and a resonator "
        "thickness offset from the measured resonance of one or more built plates (logs whose metadata name the "
        "nominal geometry, docs/log-format.md), their deflection per volt (the lowest-drive sweep's peak over its Q) "
        "and, for a plate whose deflection scan (x_mm, y_mm columns) is given too, its mode shape.  A surrogate of the FEM is built at each plate from a design of FEM "
        "evaluations (cached); its error, the FEM's and the measurement's enter the likelihood.  Writes "
        "calibration.json (what --calibration reads) and a pairs figure into --out (docs/calibration.md).",
    )
    parser.add_argument("logs", nargs="+", metavar="LOG.csv",
                        help="built-plate log(s) with a resonance sweep, and optionally a scan log of the same plate")
    parser.add_argument("--no-deflection", action="store_true",
                        help="calibrate on the resonance frequencies (and scans) only, without the deflection per volt")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    add_force_option(parser)
    add_mixed_plates_option(parser)
    parser.add_argument("--config", metavar="FILE",
                        help="TOML overriding the priors, likelihood, surrogate and sampler settings (docs/calibration.md)")
    add_fem_options(parser, build=False)
    parser.add_argument("--no-figures", action="store_true", help="skip the pairs figure")
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args) -> dict:
    started = time.perf_counter()
    settings = load_settings(args.config)
    warnings = []
    plates = measured_plates(args.logs, settings, not args.no_deflection, args.mixed_plates, warnings)
    for warning in warnings:
        print(f"tactile calibrate: warning: {warning}", file=sys.stderr)
    fem = {"q": materials.PLATE_Q, "voltage_v": materials.DESIGN_VOLTAGE, "accuracy": args.accuracy, "piezo": args.piezo}
    model = command_fem_model(fem["q"], fem["voltage_v"], fem_accuracy(args))
    input_paths = {Path(p).resolve() for p in args.logs}
    with output_folder(args.out, CALIBRATION_OUTPUTS, force=args.force) as out:
        nominal = [r.frequency for r in model.evaluate_plates([plate.plate for plate in plates])]
        calibration = calibrate(plates, settings, model.design_fem(), fem)
        files = write_calibration(calibration, out, figures=not args.no_figures, protect=input_paths)
        summary = calibration_summary(calibration, nominal, files, time.perf_counter() - started)
    if not summary["diagnostics"]["converged"]:
        print("tactile calibrate: warning: the chain is shorter than 50 autocorrelation times or its acceptance is "
              "outside 0.1-0.9; raise [sampler] steps", file=sys.stderr)
    if not args.json:
        _print_human(summary)
    return summary


def _print_human(summary: dict) -> None:
    for plate in summary["plates"]:
        print(f"{plate['log']}: measured {plate['measured_f_khz']:.3f} kHz, nominal FEM {plate['nominal_f_khz']:.3f} kHz, "
              f"calibrated {plate['predicted_f_khz']:.3f} kHz (90 %: {plate['predicted_f_khz_p05']:.3f} to "
              f"{plate['predicted_f_khz_p95']:.3f}); surrogate error {plate['surrogate_error'] * 100:.2f} %; "
              f"data: {', '.join(plate['data_used'])}")
    for name, p in summary["parameters"].items():
        print(f"  {name:26s} {p['median']:8.4g}  [{p['p05']:.4g}, {p['p95']:.4g}] {p['unit']}  (median, 90 %)")
    d = summary["diagnostics"]
    print(f"  chain: {d['n_steps']} steps x {d['n_walkers']} walkers, tau_max {d['tau_max']:.1f} "
          f"({d['steps_per_tau']:.0f} tau), acceptance {d['acceptance']:.2f}, "
          f"{'converged' if d['converged'] else 'NOT converged'}")
    print(f"  identifiability: {summary['identifiability']['statement']}")
    print(f"  posterior-predictive check: {summary['check']['statement']}")
    print(f"  a prediction's 90 % band contains {'; '.join(summary['intervals']['contains'])}; "
          f"not {'; '.join(summary['intervals']['does_not_contain'])}")
    for name, where in summary["at_prior_bound"].items():
        print(f"  {name}: {where} (the prior, not the data, limits it)")
    print(f"  {summary['fem_evaluations']} FEM evaluations, {summary['wall_time_s']:.0f} s; calibration: {summary['calibration']}")
