"""The Q(v) fit: recovery of a known law, model comparison, the CLI and its bad input."""

import contextlib
import io
import json
import math
import os
import re

import numpy as np
import pytest
from user_facing import assert_readable, run_cli

from workflow import progress
from workflow.cli import main
from workflow.damping.fit import COMPARISON_TAUS, SHAPE_DISCREPANCY, fit_damping, fit_law, fit_summary, sweep_estimates
from workflow.damping.laws import QuadraticLoss
from workflow.damping.likelihood import fit_data, log_probability, log_probability_single
from workflow.damping.posterior import load_posterior
from workflow.damping.synthetic import TRUE_LAW, campaign_csv, simulate_campaign
from workflow.errors import InputFileError
from workflow.pipeline.outputs import RECORD

SMALL = dict(voltages=(3.0, 9.0, 15.0, 18.0), points_per_sweep=30)


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(seed=11, **SMALL)


@pytest.fixture(scope="module")
def fit(campaign):
    return fit_damping(campaign, laws=("quadratic", "linear"), seed=3, max_steps=2500)


def test_vectorised_log_probability_matches_the_single_walker_one(campaign):
    data = fit_data(campaign, "quadratic")
    rng = np.random.default_rng(0)
    theta = data.lower + (data.upper - data.lower) * rng.uniform(0.3, 0.7, (6, len(data.lower)))
    batch = log_probability(theta, data)
    assert np.allclose(batch, [log_probability_single(t, data) for t in theta])
    outside = theta[0].copy()
    outside[1] = -1.0  # alpha < 0
    assert log_probability_single(outside, data) == -np.inf


def test_recovers_the_true_law_within_the_credible_band(fit, campaign):
    quadratic = fit.fits["quadratic"]
    posterior = quadratic.posterior()
    for name, truth in (("q0", TRUE_LAW.q0), ("alpha", TRUE_LAW.alpha)):
        low, median, high = np.quantile(posterior.parameters[name], [0.005, 0.5, 0.995])
        assert low <= truth <= high, name
        assert median == pytest.approx(truth, rel=0.08), name
    velocity = np.linspace(0.02, campaign.velocity.max(), 7)
    q_low, q_high = quadratic.quality_factor_quantiles(velocity, (0.005, 0.995))
    truth = TRUE_LAW.quality_factor(velocity)
    assert np.all((q_low <= truth) & (truth <= q_high))


def test_chain_diagnostics_are_reported_honestly(fit):
    d = fit.fits["quadratic"].diagnostics
    assert 0.1 < d.acceptance < 0.7
    assert d.n_steps <= 2500
    assert len(d.tau) == fit.fits["quadratic"].data.layout.dimension
    # converged implies the chain is as many autocorrelation times long as the rule asks
    assert d.n_steps >= d.chain_taus * d.tau_max or not d.converged
    assert f"{d.chain_taus:g} tau_max" in fit_summary(fit)["diagnostics"]["rule"]


def test_quadratic_data_prefer_the_quadratic_law(fit):
    assert fit.preferred == "quadratic"
    criteria = fit.map_criteria
    assert criteria["quadratic"]["bic"] < criteria["linear"]["bic"] < criteria["constant"]["bic"]


def test_summary_has_the_contract_keys(fit):
    summary = json.loads(json.dumps(fit_summary(fit), default=lambda a: a.tolist()))
    q = summary["q_of_v"]
    assert len(q["v_m_s"]) == len(q["q_p05"]) == len(q["q_p50"]) == len(q["q_p95"]) > 10
    assert np.all(np.array(q["q_p05"]) <= np.array(q["q_p50"])) and np.all(np.array(q["q_p50"]) <= np.array(q["q_p95"]))
    for key in ("tau_max", "n_steps", "acceptance", "converged"):
        assert key in summary["diagnostics"]
    assert {"median", "p05", "p95"} <= set(summary["parameters"]["q0"])
    assert "PSIS-LOO" in summary["comparison"]["criterion"]
    assert summary["selection"] in ("best", "mixture", "fallback") and summary["checks"][summary["law"]]["passed"]


def test_half_power_estimates_fall_with_voltage(campaign):
    estimates = sweep_estimates(campaign)
    assert np.all(np.diff(estimates.quality_factor) < 0)
    assert np.all(np.diff(estimates.peak_velocity) > 0)


@pytest.fixture(scope="module")
def cli_fit(tmp_path_factory):
    """One ``tactile fit-damping`` run for the two tests below (quadratic law, 600 steps, figures; stderr piped, its
    progress shown at every check): a campaign with a vibrometer dropout, the log's bytes and mtime before the run,
    the output folder, the exit status, stdout and stderr."""
    folder = tmp_path_factory.mktemp("cli-fit")
    text = campaign_csv(simulate_campaign(seed=5, **SMALL))
    lines = text.splitlines(keepends=True)
    lines[10] = lines[10].rsplit(",", 1)[0] + ",nan\n"  # a vibrometer dropout
    log = folder / "campaign.csv"
    log.write_text("".join(lines))
    before = (log.read_bytes(), os.stat(log).st_mtime_ns)
    out_dir = folder / "fit"
    stdout, stderr = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        patch.setattr(progress, "LINE_INTERVAL", 0.0)  # a short chain, yet every 10 % shown
        patch.setattr(progress, "QUIET_TASK", 0.0)
        try:
            status = main(["fit-damping", str(log), "--out", str(out_dir), "--law", "quadratic", "--max-steps", "600", "--json"])
        except SystemExit as exit_:
            status = exit_.code
    return {"log": log, "before": before, "out_dir": out_dir, "status": status, "out": stdout.getvalue(),
            "err": stderr.getvalue()}


def test_cli_writes_posterior_figures_and_leaves_the_log_alone(cli_fit):
    log, out_dir, status, out, err = (cli_fit[key] for key in ("log", "out_dir", "status", "out", "err"))
    assert status == 0, err
    assert (log.read_bytes(), os.stat(log).st_mtime_ns) == cli_fit["before"]
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "dropped 1 row" in warnings[0]
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["law"] == "quadratic"
    for name in ("posterior.npz", "fit.json", "q_of_v.png", "resonance_curves.png", "corner_quadratic.png", "trace_quadratic.png"):
        assert (out_dir / name).is_file(), name
    posterior = load_posterior(out_dir)
    assert isinstance(posterior.median_law(), QuadraticLoss)
    # the answer carries the law-shape discrepancy (each sample's Q scaled by a factor of median 1): its median Q0 is
    # the sampled law's within a fraction of that discrepancy
    assert posterior.median_law().q0 == pytest.approx(summary["parameters"]["q0"]["median"], rel=SHAPE_DISCREPANCY / 2)
    written = {path.name for path in out_dir.iterdir() if path.name != RECORD}
    assert set(json.loads((out_dir / RECORD).read_text())["files"]) == written  # a rerun may overwrite them all


def test_cli_shows_the_chain_progress_towards_convergence_on_a_piped_stderr(cli_fit):
    """Not a terminal: plain lines counting the steps run against the 25 tau the rule needs, not the cap (the run of
    ``cli_fit``, which draws its figures after the chain: the progress is still the last thing on stderr)."""
    status, out, err = cli_fit["status"], cli_fit["out"], cli_fit["err"]
    assert status == 0, err
    chain = json.loads(out.strip().splitlines()[-1])["diagnostics"]
    shown = [tuple(map(int, m)) for m in re.findall(r"^emcee, quadratic law: (\d+)/(\d+) steps", err, re.M)]
    assert len(shown) >= 3, err
    steps = [run for run, _ in shown]
    assert steps == sorted(steps) and steps[-1] == chain["n_steps"] == 600
    assert not chain["converged"] and COMPARISON_TAUS * chain["tau_max"] > 600
    assert shown[-1][1] == math.ceil(COMPARISON_TAUS * chain["tau_max"])  # the length convergence needs, not the cap
    assert f"{COMPARISON_TAUS} tau needed" in err.splitlines()[-1]


BAD_LOGS = {
    "empty": b"",
    "header only": b"frequency_hz,drive_voltage_v,velocity_m_s\n",
    "missing column": b"frequency_hz,velocity_m_s\n31000,0.1\n",
    "ambiguous column": b"frequency_hz,drive_voltage_v,velocity_m_s,velocity_m_s\n31000,5,0.1,0.2\n",
    "non-numeric": b"frequency_hz,drive_voltage_v,velocity_m_s\n31000,5,abc\n",
    "negative frequency": b"frequency_hz,drive_voltage_v,velocity_m_s\n-5,5,0.1\n",
    "binary": bytes(range(256)),
    "non-utf8": b"frequency_hz,drive_voltage_v,velocity_m_s\n31000,5,0.1\xff\n",
}


@pytest.mark.parametrize("content", BAD_LOGS.values(), ids=BAD_LOGS.keys())
def test_cli_bad_log_is_one_line_without_traceback(tmp_path, capsys, content):
    log = tmp_path / "bad.csv"
    log.write_bytes(content)
    before = os.stat(log).st_mtime_ns
    status, out, err = run_cli(capsys, "fit-damping", log, "--out", tmp_path / "fit", "--json")
    assert status != 0
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err and str(log) in err
    assert log.read_bytes() == content and os.stat(log).st_mtime_ns == before
    assert not (tmp_path / "fit").exists()


def test_cli_missing_log_is_one_line(tmp_path, capsys):
    status, _, err = run_cli(capsys, "fit-damping", tmp_path / "absent.csv", "--out", tmp_path / "fit")
    assert status != 0 and len(err.strip().splitlines()) == 1 and "absent.csv" in err


def test_a_bad_posterior_file_is_an_input_error(tmp_path):
    garbage = tmp_path / "posterior.npz"
    garbage.write_bytes(b"not a zip")
    with pytest.raises(InputFileError, match="posterior"):
        load_posterior(garbage)
    with pytest.raises(InputFileError, match="no such posterior"):
        load_posterior(tmp_path / "missing.npz")


@pytest.mark.slow
def test_coverage_of_the_90_percent_interval_over_seeds():
    hits, seeds = [], range(8)
    for seed in seeds:
        campaign = simulate_campaign(seed=100 + seed, **SMALL)
        law_fit = fit_law(campaign, "quadratic", seed=seed, max_steps=4000)
        samples = law_fit.posterior().parameters
        for name, truth in (("q0", TRUE_LAW.q0), ("alpha", TRUE_LAW.alpha)):
            low, high = np.quantile(samples[name], [0.05, 0.95])
            hits.append(low <= truth <= high)
    # 16 Bernoulli(0.9) trials: fewer than 11 hits has probability < 2 %.
    assert sum(hits) >= 11, hits


def _write_posterior(path, law):
    from workflow.damping.posterior import DampingPosterior, save_posterior

    rng = np.random.default_rng(0)
    parameters = {"q0": law.q0 * (1 + 0.01 * rng.standard_normal(50)), "alpha": law.alpha * (1 + 0.01 * rng.standard_normal(50))}
    parameters["q0"][0], parameters["alpha"][0] = law.q0, law.alpha
    posterior = DampingPosterior("quadratic", parameters)
    return save_posterior(posterior, path, np.zeros((50, 1)), ["unused"])


def test_damping_option_on_evaluate_and_optimize(tmp_path, capsys):
    from workflow.damping.laws import quadratic_law_through
    from workflow.models import analytical
    from workflow.models.plate import ORIGINAL_PLATE

    w_54 = float(analytical.dynamic_deflection(ORIGINAL_PLATE, 15.0, 54.0))
    v_work = 2 * np.pi * float(analytical.resonance_frequency(ORIGINAL_PLATE)) * w_54
    path = _write_posterior(tmp_path / "posterior.npz", quadratic_law_through(150.0, 54.0, v_work))
    status, out, err = run_cli(capsys, "evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1", "--damping", path, "--json")
    assert status == 0, err
    record = json.loads(out.strip().splitlines()[-1])
    assert record["w_dyn_um"] == pytest.approx(w_54 / 1e-6, rel=2e-3)  # the original plate keeps its deflection
    assert record["q"] == pytest.approx(54.0, rel=2e-3)
    assert record["required_voltage_v"]["p05"] <= record["required_voltage_v"]["p50"] <= record["required_voltage_v"]["p95"]
    status, out, err = run_cli(capsys, "optimize", "--hp-mm", "1", "--damping", tmp_path, "--json")
    assert status == 0, err
    record = json.loads(out.strip().splitlines()[-1])
    assert record["f_r_khz"] >= 25.0 * (1 - 1e-6) and record["damping"]["law"] == "quadratic"
    for command in (["optimize", "--hp-mm", "1"], ["evaluate", "--lambda-mm", "24", "--hi-mm", "2", "--hp-mm", "1"]):
        status, out, err = run_cli(capsys, *command, "--damping", path)
        assert status == 0, err
        assert "Q(v) used: quadratic law, Q0 150" in out and "Q settles at" in out
        assert_readable(out)
    status, _, err = run_cli(capsys, "optimize", "--hp-mm", "1", "--damping", tmp_path / "missing.npz")
    assert status != 0 and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_autocorrelation_times_are_emcee_s_over_every_lag_or_the_lags_the_window_needs():
    from emcee.autocorr import integrated_time

    from workflow.sampling import autocorrelation_times

    rng = np.random.default_rng(0)
    noise = rng.standard_normal((3000, 12, 3))
    chain = np.empty_like(noise)
    chain[0] = noise[0]
    for step in range(1, len(chain)):
        chain[step] = np.array([0.5, 0.9, 0.98]) * chain[step - 1] + noise[step]
    full = autocorrelation_times(chain)
    assert np.allclose(full, integrated_time(chain, tol=0), rtol=1e-5)
    assert np.allclose(autocorrelation_times(chain, lags=int(20 * full.max())), full, rtol=1e-5)
    assert np.allclose(autocorrelation_times(chain, lags=5), full, rtol=1e-5)  # window beyond the lags: every lag


def test_the_preconditioned_map_search_converges_the_flexible_law_to_at_least_the_quadratic_optimum(campaign):
    """The flexible law holds the quadratic law exactly (equal slopes in v^2): its MAP cannot be worse than the
    quadratic one's, unless the search stopped early (the unpreconditioned one crawled for ~850 iterations)."""
    from workflow.damping.fit import map_fit

    sweeps = sweep_estimates(campaign)
    quadratic, flexible = (map_fit(campaign, name, sweeps) for name in ("quadratic", "flexible"))
    assert flexible[3] >= quadratic[3] - 1e-3


def test_the_answer_carries_the_law_shape_discrepancy_and_says_so(fit):
    """The design's draws are the sampled posterior's, each Q(v) scaled by its own factor exp(N(0, sd^2)) at every
    velocity: the answer's band is the sampled laws' widened by the discrepancy, its median unmoved."""
    velocity = np.array([0.05, 0.1, 0.2])[:, None]
    assert fit.answer.law_name == fit.preferred  # one law: the answer is that law's samples, scaled
    ratio = (fit.answer.law_from_samples().quality_factor(velocity)
             / fit.fits[fit.preferred].posterior().law_from_samples().quality_factor(velocity))
    np.testing.assert_allclose(ratio, np.broadcast_to(ratio[:1], ratio.shape), rtol=1e-12)
    assert np.std(np.log(ratio[0])) == pytest.approx(SHAPE_DISCREPANCY, rel=0.1)
    assert abs(np.median(np.log(ratio[0]))) < SHAPE_DISCREPANCY / 5
    assert any(f"within {100 * SHAPE_DISCREPANCY:g} %" in item for item in fit_summary(fit)["q_of_v"]["interval"]["contains"])
