"""Coverage of the Q(v) fit's 90 % band over hidden truths the fit's laws do not contain (issue 29).

Draws ``--truths`` hidden damping laws from a family wider than the fit's laws, in turn:

* ``power``: 1/Q = 1/Q0 + alpha v^p with p uniform in [1, 3];
* ``threshold``: Q flat below v_t and falling above it, 1/Q = 1/Q0 + alpha (s softplus((v - v_t)/s))^2, with the
  onset width s a random share (0.05 to 1, log-uniform) of v_t (the fit's threshold law fixed it at 0.2 before);
* ``spline``: 1/Q a monotone cubic (PCHIP) in v through random increasing values at random knots;

each with Q0 log-uniform in 80-300 and Q(0.25 m/s) = Q0 / r, r uniform in 1.5-4, and, independently with
probability 1/2 each, amplitude softening (kappa uniform in 0.03-0.1 s^2/m^2) and a drift of the resonance
(+-0.1 to 0.5 Hz/s).  Each truth's campaign is simulated with the bench simulator (the real campaign procedure
over the simulated instruments: 6 sweeps x 51 points, 2.5-15 V, 0.5 % noise, the procedures' defaults) and
fitted with the default options of ``tactile fit-damping`` (:func:`workflow.damping.fit.fit_damping` with its
defaults, the logs' stated noise).  Coverage: the share of 50 velocities spanning the measured antinode
velocities where the true Q lies inside the answer's 90 % band (``fit.json``'s ``q_of_v``); width: the median
of (p95 - p05) / p50 over them.  One JSON line per truth on stderr as they finish, the summary as one JSON
object on the last line of stdout.

    nice python bench/bench_damping_coverage.py [--truths 40] [--seed 2029] [--workers 2] 2> records.log
    python bench/bench_damping_coverage.py --records records.log   # the summary of the truths a run finished
"""

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import ClassVar

import numpy as np
from scipy.interpolate import PchipInterpolator

from instruments.procedures.simulated import simulate_campaign
from instruments.simulator.bench import default_bench_settings
from workflow.damping.fit import fit_damping, fit_summary
from workflow.damping.logs import drop_short_sweeps, read_logs
from workflow.damping.synthetic import PowerTruth
from workflow.pipeline.damping_files import stated_noise

FAMILIES = ("power", "threshold", "spline")
REFERENCE_VELOCITY = 0.25
"""Antinode velocity at which each truth's Q is Q0 / r [m/s]."""
SPLINE_TOP = 0.4
"""Last knot of a spline truth, above every measured velocity [m/s]."""
CAMPAIGN_GOALS = {"mean_coverage": 0.85, "campaign_coverage": 0.70, "campaign_share": 0.9, "median_width": 0.10}
"""Issue 29's goals: mean coverage, the coverage 9 campaigns in 10 must reach, that share, the band's median width."""


@dataclass(frozen=True)
class ThresholdTruth:
    """1/Q = 1/Q0 + alpha (s softplus((|v| - v_t) / s))^2 with its own onset width s [m/s]."""

    q0: float
    alpha: float
    v_t: float
    onset: float
    name: ClassVar[str] = "threshold"

    def quality_factor(self, velocity):
        excess = self.onset * np.logaddexp(0.0, (np.abs(velocity) - self.v_t) / self.onset)
        return 1.0 / (1.0 / self.q0 + self.alpha * excess**2)


@dataclass(frozen=True)
class SplineTruth:
    """1/Q monotone cubic (PCHIP) in |v| through ``losses`` at ``knots`` [m/s], continued linearly above the last."""

    knots: tuple
    losses: tuple
    name: ClassVar[str] = "spline"

    @cached_property
    def curve(self):
        return PchipInterpolator(self.knots, self.losses)

    def quality_factor(self, velocity):
        v = np.abs(np.asarray(velocity, dtype=float))
        top = self.knots[-1]
        slope = float(self.curve(top, 1))
        loss = np.where(v <= top, self.curve(np.minimum(v, top)), self.losses[-1] + slope * (v - top))
        return 1.0 / loss


@dataclass(frozen=True)
class Truth:
    """A hidden truth: the law, softening kappa [s^2/m^2], drift [Hz/s] and the campaign's noise seed."""

    index: int
    law: object
    softening: float
    drift_rate: float
    seed: int


def draw_truth(index: int, rng: np.random.Generator) -> Truth:
    """Truth ``index`` of the family (the kinds in turn), its parameters from ``rng``."""
    kind = FAMILIES[index % len(FAMILIES)]
    q0 = float(np.exp(rng.uniform(np.log(80.0), np.log(300.0))))
    loss_at_reference = rng.uniform(1.5, 4.0) / q0
    rise = loss_at_reference - 1.0 / q0
    if kind == "power":
        p = float(rng.uniform(1.0, 3.0))
        law = PowerTruth(q0, rise / REFERENCE_VELOCITY**p, p)
    elif kind == "threshold":
        v_t = float(rng.uniform(0.03, 0.15))
        onset = float(v_t * np.exp(rng.uniform(np.log(0.05), np.log(1.0))))
        shape = ThresholdTruth(q0, 1.0, v_t, onset)
        law = ThresholdTruth(q0, rise / (1.0 / shape.quality_factor(REFERENCE_VELOCITY) - 1.0 / q0), v_t, onset)
    else:
        inner = np.sort(rng.uniform(0.02, 0.35, 3))
        knots = np.r_[0.0, inner, SPLINE_TOP]
        steps = rng.dirichlet(np.full(len(knots) - 1, 0.7))
        losses = 1.0 / q0 + np.r_[0.0, np.cumsum(steps)]
        shape = SplineTruth(tuple(knots), tuple(losses))
        scale = rise / (1.0 / shape.quality_factor(REFERENCE_VELOCITY) - 1.0 / q0)
        law = SplineTruth(tuple(float(k) for k in knots), tuple(float(1.0 / q0 + scale * (x - 1.0 / q0)) for x in losses))
    softening = float(rng.uniform(0.03, 0.1)) if rng.uniform() < 0.5 else 0.0
    drift = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 0.5)) if rng.uniform() < 0.5 else 0.0
    return Truth(index, law, softening, drift, int(rng.integers(2**31)))


def truths(n: int, seed: int) -> list:
    """The first ``n`` truths of the family for ``seed``."""
    rng = np.random.default_rng(seed)
    return [draw_truth(k, rng) for k in range(n)]


LAW_DRAWS = 1000
"""Draws of Q(v) per sampled law kept with ``--draws`` (to weigh other answer rules on the same fits) [-]."""


def study_truth(truth: Truth, max_steps: int = 20000, draws: Path | None = None, alternate: bool = False) -> dict:
    """Simulate the truth's campaign on the bench, fit it with the default options, and measure the band; with
    ``draws`` (a folder), keep :data:`LAW_DRAWS` draws of each sampled law's Q on the band's velocities and the
    comparison in ``truthNN.npz``; ``alternate``: the campaign's odd sweeps downward."""
    settings = default_bench_settings(law=truth.law, drift_rate=truth.drift_rate, softening=truth.softening,
                                      seed=truth.seed)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "campaign.csv"
        simulate_campaign(path, settings=settings, alternate=alternate)
        log = drop_short_sweeps(read_logs([path]))
        noise = stated_noise([path])
    start = time.perf_counter()
    fit = fit_damping(log, seed=truth.seed % 1000, stated_noise=noise, max_steps=max_steps)
    seconds = time.perf_counter() - start
    summary = fit_summary(fit)
    band = summary["q_of_v"]
    velocity = np.asarray(band["v_m_s"])
    low, mid, high = (np.asarray(band[key]) for key in ("q_p05", "q_p50", "q_p95"))
    true_q = truth.law.quality_factor(velocity)
    if draws is not None:
        rng = np.random.default_rng(0)
        arrays = {"velocity": velocity, "truth": true_q}
        for name, law_fit in fit.fits.items():
            q = law_fit.laws().quality_factor(velocity[None, :])
            arrays[f"q_{name}"] = q[rng.choice(len(q), size=min(LAW_DRAWS, len(q)), replace=False)].astype(np.float32)
        comparison = {"loo": fit.comparison.laws, "close": list(fit.comparison.close),
                      "passed": {name: c.passed for name, c in fit.checks.items()}, "preferred": fit.preferred}
        np.savez(draws / f"truth{truth.index:02d}.npz", comparison=json.dumps(comparison), **arrays)
    inside = (true_q >= low) & (true_q <= high)
    parameters = summary["parameters"]
    return {
        "truth": truth.index,
        "kind": truth.law.name,
        "law": {key: value for key, value in vars(truth.law).items() if key != "curve"},
        "softening": truth.softening,
        "drift_rate": truth.drift_rate,
        "heating": settings.response.thermal is not None,
        "alternate": alternate,
        "coverage": float(np.mean(inside)),
        "width": float(np.median((high - low) / mid)),
        "median_error": float(np.max(np.abs(mid / true_q - 1))),
        "velocity_range": [float(velocity[0]), float(velocity[-1])],
        "selection": summary["selection"],
        "design_law": summary["design_law"],
        "weights": summary["weights"],
        "sampled": sorted(fit.fits),
        "warning": summary["warning"],
        "forward_model": summary["forward_model"],
        "effects": summary.get("effects"),
        "shares": summary.get("shares"),
        "kappa": parameters.get("kappa"),
        "drift": parameters.get("drift_rate"),
        "fit_seconds": seconds,
        "band": {"v_m_s": velocity.tolist(), "q_p05": low.tolist(), "q_p50": mid.tolist(), "q_p95": high.tolist(),
                 "q_true": true_q.tolist()},
    }


ISSUE_RANGE = (0.08, 0.23)
"""Antinode velocities of the issue's table [m/s]: from about the lowest sweep peak to the working point."""


def coverage_within(record: dict, low: float, high: float) -> float:
    """A record's coverage over the band's velocities within [low, high] [m/s] (NaN where it has none)."""
    band = record["band"]
    v = np.asarray(band["v_m_s"])
    chosen = (v >= low) & (v <= high)
    truth = np.asarray(band["q_true"])[chosen]
    inside = (truth >= np.asarray(band["q_p05"])[chosen]) & (truth <= np.asarray(band["q_p95"])[chosen])
    return float(np.mean(inside)) if chosen.any() else float("nan")


def summarise(records: list) -> dict:
    """Mean coverage, the share of campaigns at or above 70 %, the median width, per kind and for the effects."""
    coverage = np.array([r["coverage"] for r in records])
    width = np.array([r["width"] for r in records])
    goals = CAMPAIGN_GOALS

    def effect(name, truth_key):
        carried = [r for r in records if r.get(truth_key)]
        absent = [r for r in records if not r.get(truth_key)]

        def detected(chosen):
            return sum(bool((r.get("effects") or {}).get(name, {}).get("detected")) for r in chosen)

        return {"campaigns_carrying_it": len(carried),
                "fitted_when_carried": sum(bool(r["forward_model"].get(name)) for r in carried),
                "fitted_when_absent": sum(bool(r["forward_model"].get(name)) for r in absent),
                "detected_when_carried": detected(carried),
                "detected_when_absent": detected(absent)}

    return {
        "campaigns": len(records),
        "mean_coverage": float(coverage.mean()),
        "share_at_or_above_70": float(np.mean(coverage >= goals["campaign_coverage"])),
        "lowest_coverages": sorted(float(c) for c in coverage)[:5],
        "median_width": float(np.median(width)),
        "within_issue_range": _within(records, *ISSUE_RANGE),
        "goals_met": bool(coverage.mean() >= goals["mean_coverage"]
                          and np.mean(coverage >= goals["campaign_coverage"]) >= goals["campaign_share"]
                          and np.median(width) < goals["median_width"]),
        "by_kind": {kind: {"campaigns": int(sum(r["kind"] == kind for r in records)),
                           "mean_coverage": float(np.mean([r["coverage"] for r in records if r["kind"] == kind])),
                           "median_width": float(np.median([r["width"] for r in records if r["kind"] == kind]))}
                    for kind in FAMILIES if any(r["kind"] == kind for r in records)},
        "softening": effect("softening", "softening"),
        "drift": effect("drift", "drift_rate"),
        "heating": effect("heating", "heating"),
        "fit_seconds_median": float(np.median([r["fit_seconds"] for r in records])),
        "goals": goals,
    }


def coverage_figure(records: list, before: list, examples: int = 4, labels=("before (main)", "after")):
    """Top: each truth's coverage and band width, after (``records``) and before (``before``, may be empty), with the
    goals; bottom: the band against the truth of the ``examples`` truths with the lowest coverage.  ``labels``: the
    legend's names of the two runs."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    shown = sorted(records, key=lambda r: r["coverage"])[:examples]
    examples = len(shown)
    figure, axes = plt.subplot_mosaic([["coverage"] * examples, ["width"] * examples, [f"band{k}" for k in range(examples)]],
                                      figsize=(12, 9.5), height_ratios=(1, 0.7, 1), layout="constrained")
    markers = {"power": "o", "threshold": "s", "spline": "^"}
    for label, chosen, colour, shift in ((labels[0], before, "tab:grey", -0.15), (labels[1], records, "tab:blue", 0.15)):
        for kind, marker in markers.items():
            own = [r for r in chosen if r["kind"] == kind]
            if own:
                index = np.array([r["truth"] for r in own]) + shift
                axes["coverage"].plot(index, [100 * r["coverage"] for r in own], marker, color=colour, ls="none",
                                      label=f"{label}: {kind}")
                axes["width"].plot(index, [100 * r["width"] for r in own], marker, color=colour, ls="none")
    goals = CAMPAIGN_GOALS
    axes["coverage"].axhline(100 * goals["campaign_coverage"], color="tab:red", ls="--", lw=1,
                             label="70 %: 9 campaigns in 10 at or above")
    axes["coverage"].axhline(90, color="k", ls=":", lw=1, label="nominal 90 %")
    axes["coverage"].set(ylabel="truth inside the 90 % band\n[% of velocities]", ylim=(-3, 103))
    axes["coverage"].legend(fontsize=7, ncol=4, loc="lower left")
    axes["width"].axhline(100 * goals["median_width"], color="tab:red", ls="--", lw=1)
    axes["width"].set(ylabel="median band width\n(p95 - p05) / p50 [%]", xlabel="hidden truth", yscale="log")
    plain = FuncFormatter(lambda value, _: f"{value:g}")
    axes["width"].yaxis.set_major_formatter(plain)
    axes["width"].yaxis.set_minor_formatter(plain)
    for k, r in enumerate(shown):
        ax, band = axes[f"band{k}"], r["band"]
        v = np.asarray(band["v_m_s"])
        ax.fill_between(v, band["q_p05"], band["q_p95"], color="tab:blue", alpha=0.3, label="90 % band")
        ax.plot(v, band["q_p50"], color="tab:blue", lw=1, label="median")
        ax.plot(v, band["q_true"], "k--", lw=1.2, label="hidden truth")
        effects = "+".join(name for name, key in (("softening", "softening"), ("drift", "drift_rate")) if r[key])
        ax.set(title=f"truth {r['truth']}: {r['kind']}{' + ' + effects if effects else ''}\n"
               f"coverage {100 * r['coverage']:.0f} %, width {100 * r['width']:.1f} %", xlabel="v [m/s]")
        ax.title.set_fontsize(8)
    axes["band0"].set_ylabel("Q")
    axes["band0"].legend(fontsize=7)
    return figure


def read_records(path: Path) -> list:
    """The per-truth JSON lines of a run's stderr."""
    return [json.loads(line) for line in path.read_text().splitlines() if line.startswith('{"truth"')]


def _within(records: list, low: float, high: float) -> dict | None:
    """Mean coverage and the share of campaigns at or above 70 % over [low, high] m/s (records with their bands)."""
    values = np.array([coverage_within(r, low, high) for r in records if "band" in r])
    values = values[np.isfinite(values)]
    if not len(values):
        return None
    return {"v_m_s": [low, high], "campaigns": len(values), "mean_coverage": float(values.mean()),
            "share_at_or_above_70": float(np.mean(values >= CAMPAIGN_GOALS["campaign_coverage"]))}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=40, help="hidden truths (default 40)")
    parser.add_argument("--seed", type=int, default=2029, help="seed of the truths and their campaigns (default 2029)")
    parser.add_argument("--workers", type=int, default=1, help="campaigns fitted side by side (default 1)")
    parser.add_argument("--max-steps", type=int, default=20000, help="cap on each chain (default 20000)")
    parser.add_argument("--records", type=Path, metavar="LOG",
                        help="summarise the per-truth JSON lines of an earlier run (its stderr) instead of fitting")
    parser.add_argument("--alternate", action="store_true", help="the campaigns' odd sweeps downward (measure campaign "
                        "--alternate)")
    parser.add_argument("--draws", type=Path, metavar="DIR",
                        help="keep each sampled law's draws of Q(v) and the comparison per truth in DIR (truthNN.npz)")
    parser.add_argument("--figure", type=Path, metavar="PNG", help="draw the study's figure from --records")
    parser.add_argument("--before", type=Path, metavar="LOG", help="with --figure: the records of the fit before")
    parser.add_argument("--labels", nargs=2, metavar=("BEFORE", "AFTER"), default=("before (main)", "after"),
                        help="with --figure: the legend's names of the two runs")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    if args.records:
        records = read_records(args.records)
        if args.figure:
            before = read_records(args.before) if args.before else []
            coverage_figure(records, before, labels=args.labels).savefig(args.figure, dpi=100)
    else:
        if args.draws:
            args.draws.mkdir(parents=True, exist_ok=True)
        records = []
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            futures = [pool.submit(study_truth, truth, args.max_steps, args.draws, args.alternate)
                       for truth in truths(args.truths, args.seed)]
            for future in as_completed(futures):
                records.append(future.result())
                print(json.dumps(records[-1]), file=sys.stderr, flush=True)
    records.sort(key=lambda r: r["truth"])
    result = {"seed": args.seed, **summarise(records), "wall_s": time.perf_counter() - start,
              "coverage_by_truth": [round(r["coverage"], 3) for r in records]}
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
