"""Benchmark of the damping step of ``tactile run`` (the Q(v) fit and its files); prints one JSON object.

The step as the run executes it (:func:`workflow.pipeline.steps.damping_fit` and
:func:`~workflow.pipeline.steps.damping_fit_files`): the run's simulated campaign (sweeps, then
ring-downs) for a configuration, fitted with softening and drift, every law's MAP, the laws' chains, LOO,
checks, the ring-down agreement, then ``posterior*.npz``, ``posterior*.nc``, ``fit.json`` and the figures.

Configurations: ``tiny`` (the test suite's tiny run, ``TINY`` of tests/pipeline/test_run.py: 2 sweeps x 21 points,
2 ring-downs x 40 samples, the quadratic law) and ``default`` (the embedded defaults: 6 sweeps x 51 points,
3 ring-downs x 100 samples, four laws screened).

With ``--reference DIR`` (a checkout of an earlier commit, e.g. ``git worktree add /tmp/damp-ref main``) the
same step runs on that code too, in a subprocess of the same run, and the ratios reference / this are given,
with both runs' answers (preferred law, selection, steps, tau_max, medians and 90 % intervals of the
preferred law's parameters, BIC of every law, checks, the agreement's largest |z|).

    python bench/bench_damping_step.py [--config tiny|default] [--reference DIR] [--seed N]
"""

import argparse
import ast
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TESTS_RUN = Path(__file__).resolve().parent.parent / "tests" / "test_run.py"


def tiny_configuration() -> str:
    """The TOML text ``TINY`` of tests/pipeline/test_run.py (read from the file: one source of truth)."""
    module = ast.parse(TESTS_RUN.read_text(encoding="utf-8"))
    for node in module.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "TINY" for t in node.targets):
            return ast.literal_eval(node.value)
    raise LookupError(f"{TESTS_RUN}: no TINY configuration")


def configuration(name: str, seed) -> dict:
    """The effective run configuration ``name`` (``tiny`` or ``default``), with the damping seed ``seed`` if given."""
    from workflow.pipeline.config import default_config, load_config

    if name == "tiny":
        with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as stream:
            stream.write(tiny_configuration())
        config = load_config(stream.name)
        os.unlink(stream.name)
    else:
        config = default_config()
    if seed is not None:
        config["damping"]["seed"] = seed
    return config


def measure(folder: Path, name: str, seed) -> dict:
    """Time the damping step of the code on ``sys.path`` and summarise its answer."""
    import numpy as np

    from workflow.damping.fit import parameter_summary
    from workflow.pipeline.runner import RunContext
    from workflow.pipeline.steps import campaign_logs, damping_fit, damping_fit_files

    context = RunContext(configuration(name, seed), folder)
    context.results.logs = campaign_logs(context)
    cpu, wall = time.process_time(), time.perf_counter()
    fit = damping_fit(context)
    fit_cpu, fit_wall = time.process_time() - cpu, time.perf_counter() - wall
    damping_fit_files(context, fit)
    result = {
        "fit_cpu_s": fit_cpu, "fit_wall_s": fit_wall,
        "step_cpu_s": time.process_time() - cpu, "step_wall_s": time.perf_counter() - wall,
        "preferred": fit.preferred, "selection": fit.selection,
        "sampled": sorted(fit.fits),
        "bic": {law: round(c["bic"], 2) for law, c in fit.map_criteria.items()},
        "checks_passed": {law: check.passed for law, check in fit.checks.items()},
        "agreement_max_abs_z": None if fit.agreement is None else float(np.max(np.abs(fit.agreement.z))),
    }
    for law, law_fit in fit.fits.items():
        summary = parameter_summary(law_fit)
        result[law] = {
            "n_steps": law_fit.diagnostics.n_steps, "tau_max": round(law_fit.diagnostics.tau_max, 1),
            "n_samples": len(law_fit.samples),
            "parameters": {key: [summary[key][q] for q in ("p05", "median", "p95")] for key in summary
                           if not key.startswith(("f_r_", "v0_"))},
        }
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", choices=("tiny", "default"), default="tiny")
    parser.add_argument("--seed", type=int, help="damping seed (default: the configuration's)")
    parser.add_argument("--reference", metavar="DIR", help="checkout of the code to compare with")
    parser.add_argument("--measure-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    options = ["--config", args.config] + ([] if args.seed is None else ["--seed", str(args.seed)])
    with tempfile.TemporaryDirectory() as folder:
        if args.measure_only:
            print(json.dumps(measure(Path(folder), args.config, args.seed)))
            return
        result = {"config": args.config}
        if args.reference:
            environment = dict(os.environ, PYTHONPATH=str(Path(args.reference).resolve()))
            reply = subprocess.run([sys.executable, __file__, "--measure-only", *options], env=environment,
                                   capture_output=True, text=True, check=True)
            result["reference"] = dict(json.loads(reply.stdout.strip().splitlines()[-1]), path=args.reference)
        result["this"] = measure(Path(folder), args.config, args.seed)
        if args.reference:
            result["ratio_reference_over_this"] = {
                key: result["reference"][key] / value for key, value in result["this"].items() if key.endswith("_s")
            }
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
