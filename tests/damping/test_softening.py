"""Softening and drift: the branch-following solve, their recovery by the fit, and the measurement point on the mode."""

import json

import numpy as np
import pytest

from instruments.procedures.simulated import simulate_campaign as bench_campaign
from instruments.simulator import default_bench_settings
from workflow.damping.fit import fit_law, map_fit, parameter_summary
from workflow.damping.harmonic import single_valued, softened_amplitudes, softened_resonance
from workflow.damping.laws import QuadraticLoss
from workflow.damping.likelihood import ForwardModel, log_probability
from workflow.damping.logs import drop_short_sweeps, read_logs
from workflow.damping.mode_shape import BeamMode, effective_velocity, measurement_factor, modal_law
from workflow.damping.synthetic import TRUE_LAW, PowerTruth, simulate_campaign
from workflow.errors import InputFileError

STATIC = 1.42e-9 * 15
FREQUENCY = np.linspace(30170.0, 32170.0, 81)


def residual(w, f, kappa, law=TRUE_LAW, f_r0=31170.0):
    """u - ln T(e^u) of the softened single mode at the solution w (0 when solved)."""
    v = 2 * np.pi * f * w
    r2 = (f / softened_resonance(f_r0, kappa, v)) ** 2
    return np.log(w / STATIC) + 0.5 * np.log((1 - r2) ** 2 + r2 / law.quality_factor(v) ** 2)


def test_strong_softening_folds_the_curve_and_the_sweep_direction_picks_the_branch():
    up = softened_amplitudes(STATIC, FREQUENCY, 31170.0, 1.0, TRUE_LAW.quality_factor)
    down = softened_amplitudes(STATIC, FREQUENCY[::-1], 31170.0, 1.0, TRUE_LAW.quality_factor)[::-1]
    assert np.max(np.abs(residual(up, FREQUENCY, 1.0))) < 1e-9 and np.max(np.abs(residual(down, FREQUENCY, 1.0))) < 1e-9
    differ = np.abs(up / down - 1) > 0.05
    assert 2 <= differ.sum() < 40  # a hysteresis loop, only between the two jumps
    assert np.all(down[differ] > up[differ])  # a softening resonance: the down sweep stays on the upper branch
    assert not single_valued(STATIC, FREQUENCY, 31170.0, 1.0, TRUE_LAW.quality_factor)


def test_weak_softening_is_single_valued_and_order_free():
    kappa = np.array([[0.0], [0.05]])
    law = QuadraticLoss(np.array([[150.0], [150.0]]), np.array([[0.234], [0.234]]))
    args = (STATIC * np.array([[[0.5]], [[1.0]]]), FREQUENCY, 31170.0, kappa, law.quality_factor)
    assert np.all(single_valued(*args))
    followed = softened_amplitudes(*args)
    at_once = softened_amplitudes(*args, follow=False)
    reversed_sweep = softened_amplitudes(args[0], FREQUENCY[::-1], *args[2:])[..., ::-1]
    assert np.allclose(followed, at_once, rtol=1e-8) and np.allclose(followed, reversed_sweep, rtol=1e-8)
    assert FREQUENCY[np.argmax(followed[1, 0])] < FREQUENCY[np.argmax(followed[0, 0])]  # softening moves the peak down


def test_walkers_that_may_fold_and_those_that_cannot_are_solved_alike():
    log = simulate_campaign(seed=2, softening=0.3, voltages=(6.0, 15.0), points_per_sweep=30, alternate=True)
    data, theta, scale, _ = map_fit(log, "quadratic", forward=ForwardModel(softening=True))
    walkers = np.tile(theta, (3, 1))
    walkers[1, data.layout.names.index("kappa")] = 0.02
    one_by_one = np.array([log_probability(walker, data)[0] for walker in walkers])
    assert np.allclose(log_probability(walkers, data), one_by_one, rtol=1e-10)


def test_softening_and_drift_are_recovered_at_the_map():
    log = simulate_campaign(seed=7, softening=0.08, drift_rate=-0.5, alternate=True)
    data, theta, _, _ = map_fit(log, "quadratic", forward=ForwardModel(softening=True, drift=True))
    found = dict(zip(data.layout.names, theta))
    assert found["kappa"] == pytest.approx(0.08, rel=0.05)
    assert found["drift_rate"] == pytest.approx(-0.5, abs=0.3)  # about 2 posterior standard deviations
    assert np.exp(found["ln_q0"]) == pytest.approx(TRUE_LAW.q0, rel=0.05)


@pytest.mark.slow
def test_softening_and_drift_are_recovered_within_the_90_percent_interval():
    log = simulate_campaign(seed=3, softening=0.08, drift_rate=-0.05, alternate=True)
    fit = fit_law(log, "quadratic", seed=0, forward=ForwardModel(softening=True, drift=True))
    summary = parameter_summary(fit)
    assert fit.diagnostics.converged
    for name, truth in (("kappa", 0.08), ("drift_rate", -0.05), ("q0", TRUE_LAW.q0), ("alpha", TRUE_LAW.alpha)):
        assert summary[name]["p05"] <= truth <= summary[name]["p95"], (name, summary[name])
    assert summary["kappa"]["p05"] > 0.07  # resolved, not just allowed


def test_without_the_softening_parameter_the_noise_is_inflated():
    log = simulate_campaign(seed=7, softening=0.08, alternate=True, voltages=(3.0, 9.0, 15.0, 18.0), points_per_sweep=30)
    sigma = {}
    for softening in (False, True):
        data, theta, _, _ = map_fit(log, "quadratic", forward=ForwardModel(softening=softening))
        sigma[softening] = np.exp(theta[data.layout.names.index("ln_sigma_rel")])
    assert sigma[True] < 0.03 < sigma[False]


def test_beam_mode_moments_and_the_modal_law():
    mode = BeamMode(24e-3)
    assert mode.moment(4) == pytest.approx(0.75, abs=0.02)  # <cos^4> / <cos^2> over a near-whole number of waves
    assert effective_velocity(mode, 0.2) == pytest.approx(0.2 * np.sqrt(mode.moment(4)))
    local = QuadraticLoss(150.0, 0.3)
    modal = modal_law(local, mode)
    assert modal.quality_factor(0.2) == pytest.approx(local.quality_factor(effective_velocity(mode, 0.2)))
    assert measurement_factor(mode, 4e-3, 0.0) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="node"):
        measurement_factor(mode, 6e-3, 0.0)


def test_an_off_antinode_campaign_gives_the_same_law(tmp_path):
    fitted = {}
    for name, point in (("antinode", (0.0, 0.0)), ("off", (4e-3, 2e-3))):
        path = tmp_path / f"{name}.csv"
        bench_campaign(path, default_bench_settings(seed=3, measurement_point=point), voltages=(3.0, 9.0, 15.0))
        log = read_logs([path])
        data, theta, _, _ = map_fit(log, "quadratic")
        fitted[name] = np.exp(theta[0]), theta[1]
    assert np.max(log.velocity) < 0.6 * 0.25  # read at |phi| = 0.5
    assert fitted["off"] == pytest.approx(fitted["antinode"], rel=0.03)
    truth = default_bench_settings().response.law
    assert fitted["off"] == pytest.approx((truth.q0, truth.alpha), rel=0.05)
    text = path.read_text().replace("# lambda_mm", "# other")
    (tmp_path / "no-lambda.csv").write_text(text)
    unmapped = read_logs([tmp_path / "no-lambda.csv"])
    assert unmapped.mode_factor is None and "lambda_mm" in unmapped.warnings[0]
    (tmp_path / "node.csv").write_text(path.read_text().replace("# x_mm: 4", "# x_mm: 6"))
    with pytest.raises(InputFileError, match="node"):
        read_logs([tmp_path / "node.csv"])


def test_cli_fits_softening_and_drift_and_draws_its_figures(tmp_path, capsys):
    from workflow.cli import main
    from workflow.damping.synthetic import campaign_csv

    log = tmp_path / "soft.csv"
    log.write_text(campaign_csv(simulate_campaign(seed=1, softening=0.08, drift_rate=-0.5, alternate=True,
                                                  voltages=(3.0, 15.0), points_per_sweep=20)))
    out = tmp_path / "fit"
    assert main(["fit-damping", str(log), "--out", str(out), "--law", "quadratic", "--softening", "--drift",
                 "--max-steps", "100", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert {"kappa", "drift_rate"} <= set(summary["parameters"]) and "antinode" in summary["velocity_convention"]
    assert (out / "resonance_curves.png").exists()


@pytest.mark.parametrize("softening", [True, False], ids=["softened", "not softened"])
def test_warm_started_solves_give_the_cold_log_probability(softening):
    """Walkers started from the nearest walker already solved (WarmStarts, as in a chain or a MAP search) reach the same
    roots, unique where they are solved at once: the log-probability equals the cold one within the solve's tolerance,
    for near walkers and for walkers far from every one held."""
    from workflow.damping.likelihood import WarmStarts

    log = simulate_campaign(seed=2, softening=0.08, voltages=(6.0, 15.0), points_per_sweep=30, alternate=True)
    data, theta, scale, _ = map_fit(log, "quadratic", forward=ForwardModel(softening=softening))
    rng = np.random.default_rng(0)
    warm = WarmStarts()
    log_probability(theta + 0.3 * scale * rng.standard_normal((6, len(theta))), data, warm)
    assert warm.held == 6
    for spread in (0.3, 3.0):
        walkers = np.clip(theta + spread * scale * rng.standard_normal((6, len(theta))), data.lower, data.upper)
        cold = log_probability(walkers, data)
        assert np.all(np.isfinite(cold))
        assert np.allclose(log_probability(walkers, data, warm), cold, rtol=1e-9, atol=1e-6), spread


def test_the_drift_rate_has_a_gaussian_prior_of_the_declared_scale():
    from workflow.damping import likelihood

    log = simulate_campaign(seed=7, softening=0.08, drift_rate=0.0)
    data, theta, _, _ = map_fit(log, "quadratic", forward=ForwardModel(softening=True, drift=True))
    column = data.layout.names.index("drift_rate")
    moved = np.array(theta, dtype=float)
    moved[column] += 1.0
    step = likelihood.log_prior(moved, data.layout) - likelihood.log_prior(theta, data.layout)
    expected = -0.5 * ((theta[column] + 1.0) ** 2 - theta[column] ** 2) / likelihood.DRIFT_SCALE**2
    assert step == pytest.approx(expected, rel=1e-9) and expected < 0


def test_noise_does_not_carry_the_drift_and_q_with_it_when_every_sweep_goes_up(tmp_path):
    """Consistency check on the bench simulator (the coverage study's truth 24, seed 2029): a plate without drift,
    its sweeps all upward.  Under the flat box prior the noise took the drift to +1.5 Hz/s and Q 2.2 % high with it
    (the drift trades against the width); the drift's prior (DRIFT_SCALE) keeps both near the truth."""
    truth = PowerTruth(89.80380622853049, 0.27511537559035054, 2.3076803423304963)
    settings = default_bench_settings(law=truth, drift_rate=0.0, softening=0.0, seed=1860608715)
    path = tmp_path / "campaign.csv"
    bench_campaign(path, settings=settings)
    data, theta, _, _ = map_fit(drop_short_sweeps(read_logs([path])), "flexible", forward=ForwardModel(True, True, True))
    velocity = np.array([0.05, 0.1, 0.15, 0.2])
    error = data.layout.law(theta).quality_factor(velocity)[0] / truth.quality_factor(velocity) - 1
    assert np.max(np.abs(error)) < 0.012, error
    assert abs(data.layout.natural(theta)["drift_rate"][0]) < 0.7


def test_the_band_says_a_drift_beyond_its_prior_is_not_in_it():
    from types import SimpleNamespace

    from workflow.damping.fit import band_contents

    def fit(forward):
        return SimpleNamespace(shares={"quadratic": 1.0}, best=SimpleNamespace(
            data=SimpleNamespace(layout=SimpleNamespace(forward=forward))))

    with_drift = band_contents(fit(ForwardModel(softening=True, drift=True, heating=True)))["does_not_contain"]
    assert any("beyond its prior's scale (0.5 Hz/s" in item for item in with_drift)
    without = band_contents(fit(ForwardModel(softening=True)))["does_not_contain"]
    assert not any("prior's scale" in item for item in without)
