"""``tactile fit-damping``: Bayesian fit of Q(v) to interferometer logs."""

import argparse
import sys
from functools import partial
from pathlib import Path

from workflow.cli.options import add_force_option, add_json_flag, add_mixed_plates_option, bounded, limit_text, seed_option
from workflow.damping.fit import fit_damping, fit_summary
from workflow.damping.laws import SAMPLED_LAWS
from workflow.damping.likelihood import ForwardModel, default_forward_model
from workflow.damping.logs import drop_short_sweeps, read_logs
from workflow.execution.parallel import map_evaluations
from workflow.models.limits import LIMITS
from workflow.pipeline.damping_files import FIT_OUTPUTS, stated_noise, write_fit
from workflow.pipeline.outputs import output_folder


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "fit-damping",
        help="fit Q(v) to interferometer logs with emcee",
        description="Infer the amplitude-dependent quality factor Q(v) from frequency sweeps at several "
        "drive voltages (interferometer logs, format in docs/log-format.md), with the resonance of each sweep, the "
        "drive-to-deflection gain and the noise as nuisance parameters.  Laws are screened at the MAP, "
        "compared by PSIS-LOO and checked for misfit; the design uses the best law, the laws the data do not tell "
        "apart mixed in equal shares, or the flexible law (docs/damping.md).  Writes posterior.npz (what --damping reads), posterior.nc "
        "(ArviZ), fit.json and figures into --out.",
    )
    parser.add_argument("logs", nargs="+", metavar="LOG.csv",
                        help="interferometer log(s): sweep logs and/or ring-down logs, fitted jointly (docs/log-format.md)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    add_force_option(parser)
    add_mixed_plates_option(parser)
    parser.add_argument(
        "--law",
        choices=SAMPLED_LAWS + ("all",),
        default="all",
        help=f"Q(v) law to fit; 'all' screens {', '.join(SAMPLED_LAWS)} and compares them by PSIS-LOO (default: all)",
    )
    seed_option(parser, 0, "random seed of the walkers and the sampler")
    parser.add_argument("--max-steps", type=bounded(int, *LIMITS["damping.max_steps"]), default=20000,
                        help=f"cap on each chain's length, {limit_text('damping.max_steps')} (default: 20000)")
    parser.add_argument("--softening", action=argparse.BooleanOptionalAction, default=None,
                        help="fit the resonance's amplitude softening f_r0 (1 - kappa v^2), each sweep solved in its "
                        "measuring order (up and down sweeps differ when the resonance folds over); default: fitted "
                        "whenever the logs have sweeps (its prior includes none), --no-softening leaves it out")
    parser.add_argument("--drift", action=argparse.BooleanOptionalAction, default=None,
                        help="fit a drift rate of the resonance within each sweep (needs timestamp_s); default: fitted "
                        "whenever the sweep logs have timestamp_s, --no-drift leaves it out")
    parser.add_argument("--heating", action=argparse.BooleanOptionalAction, default=None,
                        help="fit the fall of the resonance with the energy the plate has dissipated since its sweep "
                        "began (its heating while driven; needs timestamp_s); default: fitted whenever the sweep logs "
                        "have timestamp_s, --no-heating leaves it out")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def run(args) -> dict:
    log = drop_short_sweeps(read_logs(args.logs, args.mixed_plates))
    for warning in log.warnings:
        print(f"tactile fit-damping: warning: {warning}", file=sys.stderr)
    input_paths = {Path(p).resolve() for p in args.logs}
    laws = SAMPLED_LAWS if args.law == "all" else (args.law,)
    with output_folder(args.out, FIT_OUTPUTS, force=args.force) as out:
        noise = stated_noise(args.logs)
        automatic = default_forward_model(log)
        forward = ForwardModel(softening=automatic.softening if args.softening is None else args.softening,
                               drift=automatic.drift if args.drift is None else args.drift,
                               heating=automatic.heating if args.heating is None else args.heating)
        fit = fit_damping(log, laws=laws, seed=args.seed, max_steps=args.max_steps, progress=True, forward=forward,
                          stated_noise=noise, mapper=partial(map_evaluations, description="laws sampled"))
        summary = dict(fit_summary(fit), files=write_fit(fit, out, figures=not args.no_figures, protect=input_paths))
    if fit.warning:
        print(f"tactile fit-damping: warning: {fit.warning}", file=sys.stderr)
    if not args.json:
        _print_human(summary)
    return summary


def _print_human(summary: dict) -> None:
    d = summary["diagnostics"]
    print(f"Q(v) law: {summary['law']} ({summary['n_points']} points, {summary['n_sweeps']} sweeps)")
    for name, p in summary["parameters"].items():
        if not name.startswith("f_r_"):
            print(f"  {name:10s} {p['median']:.5g}  [{p['p05']:.5g}, {p['p95']:.5g}] {p['unit']}  (median, 90 %)")
    print(
        f"  chain: {d['n_steps']} steps x {d['n_walkers']} walkers, tau_max {d['tau_max']:.1f}, "
        f"acceptance {d['acceptance']:.2f}, {'converged' if d['converged'] else 'NOT converged'} ({d['seconds']:.1f} s)"
    )
    loo = summary["comparison"]["loo"]
    for name, c in summary["comparison"]["laws"].items():
        sampled = (
            f"elpd_loo {loo[name]['elpd_loo']:.1f} (se {loo[name]['se']:.1f}, diff {loo[name]['elpd_diff']:.1f} "
            f"dse {loo[name]['dse']:.1f}), weight {loo[name]['weight']:.2f}, Pareto k > 0.7: {loo[name]['n_pareto_k_bad']}, "
            if name in loo else "not sampled (screened at the MAP), "
        )
        print(f"  {name:10s} {sampled}AIC {c['aic']:.1f}, BIC {c['bic']:.1f}")
    for name, check in summary["checks"].items():
        print(f"  checks {name:10s} {'passed' if check['passed'] else 'FAILED'}: binned chi2 p {check['binned_chi2_p']:.2g}, "
              f"runs p {check['runs_test_combined_p']:.2g}, flexible-law likelihood ratio p "
              f"{_number(check['flexible_law_likelihood_ratio_p'])}" + "".join(f"; {note}" for note in check["notes"]))
    for name, effect in summary["effects"].items():
        state = ("not fitted" + (f" ({effect['not_fitted_because']})" if "not_fitted_because" in effect else "")
                 if not effect["fitted"]
                 else "fitted, " + ("shown by the logs" if effect["detected"] else "not resolved by the logs")
                 + f" (shown when {effect['rule']})")
        print(f"  {name}: {state}")
    print(f"  velocity convention: {summary['velocity_convention']}")
    shares = ", ".join(f"{name} {share:.2g}" for name, share in summary["shares"].items())
    print(f"  preferred by PSIS-LOO: {summary['law']}; design uses: {summary['selection']} ({shares}); "
          f"posterior: {summary['files']['posterior']}")
    interval = summary["q_of_v"]["interval"]
    print(f"  the 90 % band of Q(v) contains {'; '.join(interval['contains'])}; not {'; '.join(interval['does_not_contain'])}")


def _number(value) -> str:
    """A p-value in two significant digits, or "not tested"."""
    return "not tested" if value is None else f"{value:.2g}"
