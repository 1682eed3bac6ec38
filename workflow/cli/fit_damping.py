"""``tactile fit-damping``: Bayesian fit of Q(v) to interferometer logs (SPEC sections 6, 8).

Also the ``--damping POSTERIOR`` option shared by ``evaluate``, ``optimize`` and ``maps``:
:func:`add_damping_option` and :func:`load_damping`.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from ..analytical import resonance_frequency
from ..damping.design import damped_deflection, damped_model, fem_damped_deflection, fem_required_voltage, required_voltage
from ..damping.fit import fit_damping, fit_summary
from ..damping.laws import LAWS, law_parameters
from ..damping.logs import drop_short_sweeps, read_logs
from ..damping.posterior import load_posterior
from ..damping_files import output_folder, write_fit
from ..materials import TARGET_DEFLECTION
from ..optimize import maximise_deflection
from ..units import UM
from . import add_json_flag

SAMPLED_LAWS = tuple(name for name in LAWS if name != "constant")
"""Laws ``--law`` accepts; the constant-Q baseline is always in the comparison (BIC at the MAP)."""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "fit-damping",
        help="fit Q(v) to interferometer logs with emcee",
        description="Infer the amplitude-dependent quality factor Q(v) from frequency sweeps at several "
        "drive voltages (interferometer logs, SPEC section 7), with the resonance of each sweep, the "
        "drive-to-deflection gain and the noise as nuisance parameters.  Laws are compared with WAIC "
        "(BIC at the MAP also reported).  Writes posterior.npz (what --damping reads), fit.json and "
        "figures into --out.",
    )
    parser.add_argument("logs", nargs="+", metavar="LOG.csv", help="interferometer log(s), SPEC section 7 format")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    parser.add_argument(
        "--law",
        choices=SAMPLED_LAWS + ("all",),
        default="all",
        help=f"Q(v) law to sample; 'all' samples {', '.join(SAMPLED_LAWS)} and keeps the best by WAIC (default: all)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed of the walkers and the sampler (default: 0)")
    parser.add_argument("--max-steps", type=_positive_int, default=20000, help="cap on each chain's length (default: 20000)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    add_json_flag(parser)
    parser.set_defaults(handler=run)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def run(args) -> dict:
    log = drop_short_sweeps(read_logs(args.logs))
    for warning in log.warnings:
        print(f"tactile fit-damping: warning: {warning}", file=sys.stderr)
    out = output_folder(args.out)
    input_paths = {Path(p).resolve() for p in args.logs}
    laws = SAMPLED_LAWS if args.law == "all" else (args.law,)
    fit = fit_damping(log, laws=laws, seed=args.seed, max_steps=args.max_steps, progress=sys.stderr.isatty())
    summary = dict(fit_summary(fit), files=write_fit(fit, out, figures=not args.no_figures, protect=input_paths))
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
    for name, c in summary["comparison"]["laws"].items():
        waic = f"WAIC {c['waic']:.1f}, " if "waic" in c else ""
        print(f"  {name:10s} {waic}BIC {c['bic']:.1f}")
    print(f"  preferred by WAIC: {summary['comparison']['preferred']}; posterior: {summary['files']['posterior']}")


def add_damping_option(parser: argparse.ArgumentParser) -> None:
    """The ``--damping POSTERIOR`` option: design with the fitted Q(v) instead of a constant Q."""
    parser.add_argument(
        "--damping",
        metavar="POSTERIOR",
        help="posterior.npz (or its folder) from 'tactile fit-damping': use the posterior-median Q(v) law, "
        "solved self-consistently, instead of a constant Q",
    )


def load_damping(args):
    """The :class:`~workflow.damping.posterior.DampingPosterior` named by ``--damping``, or None."""
    path = getattr(args, "damping", None)
    return None if path is None else load_posterior(path)


def damping_record(posterior, plate, voltage: float, draws: int = 200) -> dict:
    """JSON keys for a beam-model evaluation with Q(v): the posterior-median law's deflection,
    the Q it settles at, 90 % intervals over posterior draws and the voltage for the target."""
    law, drawn = posterior.median_law(), posterior.draws(draws)
    deflection = float(damped_deflection(plate, voltage, law))
    w05, w95 = np.quantile(damped_deflection(plate, voltage, drawn), [0.05, 0.95])
    return {
        "w_dyn_um_p05": w05 / UM,
        "w_dyn_um_p95": w95 / UM,
        **_damping_keys(posterior, deflection, float(resonance_frequency(plate)), required_voltage(plate, drawn)),
    }


def fem_damping_record(posterior, result, draws: int = 200) -> dict:
    """JSON keys for a FEM evaluation with Q(v): the best mode's self-consistent deflection with
    the posterior-median law, the Q it settles at, and the voltage for the target deflection."""
    deflection = float(fem_damped_deflection(result, posterior.median_law()))
    voltages = fem_required_voltage(result, posterior.draws(draws))
    return _damping_keys(posterior, deflection, result.frequency, voltages)


def damped_optimum(posterior, problem, draws: int = 200):
    """The beam optimum with the posterior-median Q(v), and JSON keys on the damping:
    the voltage for the target deflection there (median law and 90 % interval over draws)."""
    law = posterior.median_law()
    optimum = maximise_deflection(damped_model(law, problem.voltage), problem)
    voltages = required_voltage(optimum.plate, posterior.draws(draws))
    keys = _damping_keys(posterior, optimum.deflection, optimum.frequency, voltages)
    del keys["w_dyn_um"]
    return optimum, keys


def _damping_keys(posterior, deflection: float, frequency: float, required_voltages) -> dict:
    """Deflection [um] and the Q it settles at, the voltage for the target deflection (median
    and 90 % over posterior draws) and the law used."""
    law = posterior.median_law()
    v05, v50, v95 = np.quantile(required_voltages, [0.05, 0.5, 0.95])
    return {
        "w_dyn_um": deflection / UM,
        "q": float(law.quality_factor(2 * np.pi * frequency * deflection)),
        "required_voltage_v": {"target_um": TARGET_DEFLECTION / UM, "p05": v05, "p50": v50, "p95": v95},
        "damping": {"law": posterior.law_name, "median": law_parameters(law), "posterior": posterior.source},
    }
