"""The threshold and flexible Q(v) laws, PSIS-LOO comparison, stacking, misfit checks and posterior.nc."""

import numpy as np
import pytest

from workflow.damping.checks import misfit_check, runs_test
from workflow.damping.comparison import compare_laws
from workflow.damping.fit import fit_damping, fit_law, fit_summary, map_fit, sweep_estimates, velocity_grid
from workflow.damping.inference_data import load_inference_data, save_inference_data
from workflow.damping.laws import STACKED_COMPONENTS, MonotoneSpline, QuadraticLoss, StackedLaws, ThresholdLoss
from workflow.damping.likelihood import ForwardModel
from workflow.damping.posterior import DampingPosterior, load_posterior, save_posterior, stacked_posterior
from workflow.damping.synthetic import TRUE_LAW, simulate_campaign
from workflow.errors import InputFileError

THRESHOLD_TRUTH = ThresholdLoss(q0=140.0, alpha=0.45, v_t=0.1)
FLEXIBLE_TRUTH = MonotoneSpline(q0=160.0, d1=0.0005, d2=0.001, d3=0.003, d4=0.004, d5=0.004, d6=0.004, d7=0.003, d8=0.003,
                                v_top=0.27, v_first=0.1)
NOISE = 0.02


def coverage(law_fit_or_posterior, truth, velocity):
    """Fraction of ``velocity`` where the truth lies in the 90 % band."""
    law = law_fit_or_posterior.law_from_samples()
    q05, q95 = np.quantile(law.quality_factor(velocity[:, None]), (0.05, 0.95), axis=1)
    true_q = truth.quality_factor(velocity)
    return float(np.mean((true_q >= q05) & (true_q <= q95)))


@pytest.mark.parametrize("law", [THRESHOLD_TRUTH, FLEXIBLE_TRUTH, TRUE_LAW, StackedLaws(
    component=np.array([0, 2, 3]), quadratic_q0=150.0, quadratic_alpha=0.2, linear_q0=100.0, linear_alpha=0.0,
    threshold_q0=np.array([1e3, 120.0, 1e3]), threshold_alpha=0.5, threshold_v_t=0.05, threshold_onset=np.array([0.2, 0.05, 1.0]), flexible_q0=90.0,
    flexible_d1=0.001, flexible_d2=0.0, flexible_d3=0.004, flexible_d4=0.0, flexible_d5=0.002, flexible_d6=0.001, flexible_d7=0.0,
    flexible_d8=0.002, flexible_v_top=0.2, flexible_v_first=0.05)])
def test_every_law_is_non_increasing_in_speed(law):
    velocity = np.linspace(0.0, 0.5, 401)[:, None]
    q = law.quality_factor(velocity)
    assert np.all(np.diff(q, axis=0) <= 1e-12 * q[:-1])
    assert np.allclose(law.quality_factor(-velocity), q)


def test_threshold_law_is_flat_below_and_quadratic_well_above_its_threshold():
    law = ThresholdLoss(q0=140.0, alpha=0.45, v_t=0.1)
    assert law.quality_factor(0.02) == pytest.approx(140.0, rel=1e-4)
    shifted = QuadraticLoss(q0=140.0, alpha=0.45)
    assert 1 / law.quality_factor(0.5) == pytest.approx(1 / shifted.quality_factor(0.4), rel=1e-6)


def test_flexible_law_interpolates_its_knots_linearly_in_v_squared_and_continues_the_last_slope():
    law = FLEXIBLE_TRUTH
    knots = MonotoneSpline.knots(law.v_top, law.v_first)
    assert knots[1] == law.v_first and knots[-1] == law.v_top and np.allclose(np.diff(knots[1:]), (0.27 - 0.1) / 7)
    rises = np.cumsum([0.0] + [getattr(law, name) for name in MonotoneSpline.INCREMENTS])
    assert np.allclose(1 / law.quality_factor(knots), 1 / law.q0 + rises)
    assert 1 / law.quality_factor(law.v_first / 2) == pytest.approx(1 / law.q0 + law.d1 / 4, rel=1e-12)  # a parabola below u_1
    beyond = np.sqrt(2 * knots[-1] ** 2 - knots[-2] ** 2)  # one segment (in v^2) past the last knot
    assert 1 / law.quality_factor(beyond) == pytest.approx(1 / law.q0 + rises[-1] + law.d8, rel=1e-12)
    quadratic = QuadraticLoss(q0=150.0, alpha=0.234)  # equal slopes in v^2: the quadratic law exactly
    spline = MonotoneSpline(150.0, *np.diff(quadratic.loss(knots)), v_top=law.v_top, v_first=law.v_first)
    velocity = np.linspace(0.0, 0.4, 41)
    assert np.allclose(spline.quality_factor(velocity), quadratic.quality_factor(velocity), rtol=1e-12)


def test_flexible_law_knots_sit_on_the_measured_velocities(threshold_campaign):
    fixed = dict(map_fit(threshold_campaign, "flexible")[0].layout.fixed)
    peaks = [threshold_campaign.velocity[threshold_campaign.sweep == k].max() for k in range(threshold_campaign.n_sweeps)]
    assert fixed["v_top"] == threshold_campaign.velocity.max() and fixed["v_first"] == pytest.approx(min(peaks))


def test_runs_test_flags_runs_and_passes_alternation():
    assert runs_test(np.r_[np.ones(20), -np.ones(20)])[1] < 1e-6
    assert runs_test(np.tile([1.0, -1.0], 20))[1] > 0.99


@pytest.fixture(scope="module")
def threshold_campaign():
    return simulate_campaign(law=THRESHOLD_TRUTH, relative_noise=NOISE, seed=1)


@pytest.fixture(scope="module")
def threshold_fit(threshold_campaign):
    """A short chain (1000 steps, ~20 tau; was 3000): on fit seeds 2-6 the truth sits at the 22nd-29th (q0), 72nd-81st
    (alpha) and 79th-85th (v_t) percentiles, the band covers it at every velocity, and the misfit and LOO tests below
    pass with the quadratic fit's 600 steps (measured)."""
    return fit_law(threshold_campaign, "threshold", seed=2, max_steps=1000)


@pytest.fixture(scope="module")
def quadratic_fit(threshold_campaign):
    """The wrong law on the threshold campaign, one fit for the misfit check and the LOO comparison (600 steps; they
    ran 1500 and 800 steps: the quadratic law's misfit and its LOO deficit, 4.9 dse, are the same on seeds 2-6)."""
    return fit_law(threshold_campaign, "quadratic", seed=2, max_steps=600)


def test_threshold_law_recovers_its_own_truth(threshold_fit, threshold_campaign):
    posterior = threshold_fit.posterior()
    for name in ("q0", "alpha", "v_t"):
        low, high = np.quantile(posterior.parameters[name], [0.005, 0.995])
        assert low <= getattr(THRESHOLD_TRUTH, name) <= high, name
    velocity = np.linspace(0.0, threshold_campaign.velocity.max(), 50)
    assert coverage(posterior, THRESHOLD_TRUTH, velocity) >= 0.9


def test_posterior_nc_reads_back_and_arviz_loo_works_on_it(threshold_fit, tmp_path):
    import arviz as az

    path = save_inference_data(threshold_fit.inference_data, tmp_path / "posterior.nc")
    idata = load_inference_data(path)
    assert {"posterior", "sample_stats", "log_likelihood", "observed_data"} <= set(idata.groups())
    assert idata.log_likelihood["velocity"].shape[-1] == len(threshold_fit.data.velocity)
    loo = az.loo(idata)
    assert np.isfinite(loo.elpd_loo) and loo.se > 0
    assert idata.posterior["v_t"].median() == pytest.approx(np.median(threshold_fit.posterior().parameters["v_t"]), rel=0.05)
    (tmp_path / "bad.nc").write_text("not netCDF")
    with pytest.raises(InputFileError, match="bad.nc"):
        load_inference_data(tmp_path / "bad.nc")


def test_misfit_check_flags_the_quadratic_law_on_a_threshold_campaign_and_passes_the_true_law(quadratic_fit, threshold_fit):
    quadratic = quadratic_fit
    wrong = misfit_check(quadratic.samples, quadratic.data, stated_noise=NOISE)
    right = misfit_check(threshold_fit.samples, threshold_fit.data, stated_noise=NOISE)
    assert not wrong.passed and any("absorbed as noise" in reason for reason in wrong.reasons)
    assert right.passed, right.reasons
    unstated = misfit_check(threshold_fit.samples, threshold_fit.data)
    assert unstated.passed and "skipped" in unstated.reasons[0]


def test_loo_prefers_the_threshold_law_over_the_quadratic_on_a_threshold_campaign(quadratic_fit, threshold_fit):
    comparison = compare_laws({"quadratic": quadratic_fit.inference_data, "threshold": threshold_fit.inference_data})
    assert comparison.best == "threshold" and comparison.close == ("threshold",)
    assert comparison.laws["quadratic"]["elpd_diff"] > 2 * comparison.laws["quadratic"]["dse"]
    assert sum(comparison.weights.values()) == pytest.approx(1.0)


def test_stacked_posterior_mixes_the_laws_by_weight_and_round_trips_through_the_file(threshold_fit, tmp_path):
    quadratic = QuadraticLoss(q0=np.full(50, 150.0), alpha=np.linspace(0.1, 0.3, 50))
    posteriors = {
        "threshold": threshold_fit.posterior(),
        "quadratic": DampingPosterior("quadratic", {"q0": quadratic.q0, "alpha": quadratic.alpha}),
    }
    stacked = stacked_posterior(posteriors, {"threshold": 0.75, "quadratic": 0.25}, 4000, seed=0)
    share = np.mean(stacked.parameters["component"] == STACKED_COMPONENTS.index("threshold"))
    assert share == pytest.approx(0.75, abs=0.03)
    path = save_posterior(stacked, tmp_path / "posterior.npz", np.zeros((1, 1)), ["x"])
    loaded = load_posterior(path)
    drawn = loaded.draws(64, seed=1)
    assert isinstance(drawn, StackedLaws) and drawn.quality_factor(np.array([0.0, 0.1])[:, None]).shape == (2, 64)
    assert isinstance(loaded.median_law(), ThresholdLoss)


@pytest.mark.slow  # 16 s; the misfit check behind the fallback stays in the default suite (test_misfit_check_flags_...)
def test_a_wrong_only_law_is_flagged_and_the_answer_falls_back_to_the_flexible_law(threshold_campaign):
    fit = fit_damping(threshold_campaign, laws=("quadratic",), seed=2, max_steps=1500, stated_noise=NOISE,
                      forward=ForwardModel())
    summary = fit_summary(fit)
    assert fit.selection == "fallback" and fit.answer.law_name == "flexible"
    assert not summary["checks"]["quadratic"]["passed"] and summary["warning"].startswith("the quadratic law fails")
    assert summary["design_law"] == "flexible"
    assert summary["checks"]["quadratic"]["flexible_law_likelihood_ratio_p"] < 1e-6
    velocity = np.linspace(0.0, threshold_campaign.velocity.max(), 50)
    # a short chain (1500 steps): the flexible band holds the truth far more often than the quadratic one
    assert coverage(fit.answer, THRESHOLD_TRUTH, velocity) >= 0.6 > 0.3 >= coverage(fit.best.posterior(), THRESHOLD_TRUTH, velocity)


@pytest.mark.slow
@pytest.mark.parametrize("truth", [THRESHOLD_TRUTH, TRUE_LAW], ids=["threshold", "quadratic"])
def test_flexible_law_covers_a_threshold_and_a_quadratic_truth_over_the_measured_range(truth):
    """A short chain (2000 steps) on seed 1; the converged chains on more seeds are the slow test below."""
    log = simulate_campaign(law=truth, relative_noise=NOISE, seed=1)
    law_fit = fit_law(log, "flexible", seed=1, max_steps=2000)
    assert coverage(law_fit.posterior(), truth, velocity_grid(log)) >= 0.9


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 4])
@pytest.mark.parametrize("truth", [THRESHOLD_TRUTH, TRUE_LAW, FLEXIBLE_TRUTH], ids=["threshold", "quadratic", "flexible"])
def test_flexible_law_converges_and_covers_the_truth_over_the_measured_range(truth, seed):
    # measured (docs/damping.md): seeds 0-4 cover the threshold truth at 0.82-0.98 and the quadratic one at 0.80-1.00;
    # the true laws' own bands cover them at 0.52-1.00 (on seeds 0 and 3 the noise pulls every band off the truth)
    log = simulate_campaign(law=truth, relative_noise=NOISE, seed=seed)
    law_fit = fit_law(log, "flexible", seed=seed)
    assert law_fit.diagnostics.converged
    assert coverage(law_fit.posterior(), truth, velocity_grid(log)) >= 0.9


def test_map_screening_finds_the_flexible_law_close_to_the_threshold_truth(threshold_campaign):
    sweeps = sweep_estimates(threshold_campaign)
    log_likelihood = {name: map_fit(threshold_campaign, name, sweeps)[3] for name in ("quadratic", "threshold", "flexible")}
    assert log_likelihood["threshold"] - log_likelihood["quadratic"] > 20
    assert log_likelihood["flexible"] > log_likelihood["threshold"] - 3


def test_the_flexible_law_summed_as_hinges_is_its_clipped_segments():
    """The loss is summed as hinges on cached segments; written out segment by segment (clipped shares of each rise,
    the last continued), for walker-shaped rises and velocities beyond v_top, it is the same law."""
    rng = np.random.default_rng(3)
    rises = rng.uniform(0.0, 0.01, (8, 5, 1))
    law = MonotoneSpline(rng.uniform(80.0, 300.0, (5, 1)), *rises, v_top=0.3, v_first=0.08)
    velocity = np.linspace(0.0, 0.5, 101)
    squared = np.square(MonotoneSpline.knots(0.3, 0.08))
    expected = 1 / law.q0 + sum(
        rise * np.clip((velocity**2 - low) / (high - low), 0.0, np.inf if j == 7 else 1.0)
        for j, (rise, low, high) in enumerate(zip(rises, squared, squared[1:]))
    )
    assert np.allclose(law.loss(velocity), expected, rtol=1e-13, atol=0)


def test_each_law_carries_the_units_of_its_parameters_and_the_exponent_of_its_loss():
    """One place for a law's facts: its units name exactly its parameters, and its loss grows as |v|^p with its own
    exponent p (the threshold law's far above its threshold); the fit's parameter units are the law's."""
    from workflow.damping.fit import parameter_unit
    from workflow.damping.laws import LAWS, ConstantQ, LinearLoss, QuadraticLoss, ThresholdLoss, parameter_names

    for law in LAWS.values():
        assert set(law.units) == set(parameter_names(law)), law.name
        assert all(parameter_unit(law.name, name) == unit for name, unit in law.units.items())
    for law in (QuadraticLoss(50.0, 30.0), LinearLoss(50.0, 3.0), ThresholdLoss(50.0, 30.0, 1e-4, 0.05)):
        extra = [law.loss(v) - 1 / 50.0 for v in (0.2, 0.4)]
        assert extra[1] / extra[0] == pytest.approx(2.0**law.velocity_exponent, rel=2e-3), law.name
    assert ConstantQ.velocity_exponent == 0


def test_each_law_carries_the_prior_box_of_the_coordinates_it_is_sampled_in():
    """The law, not the likelihood, says where its parameters may go: a box for every sampled coordinate but ln Q0,
    low below high; the loss coefficient stops where the loss term alone brings Q at the highest velocity down to
    MIN_Q_AT_MAX_VELOCITY; the fit's prior box is the law's."""
    from workflow.damping.laws import LAWS, MIN_Q_AT_MAX_VELOCITY, LinearLoss, QuadraticLoss, parameter_names
    from workflow.damping.likelihood import SAMPLED_LAW_PARAMETERS, fit_data
    from workflow.damping.synthetic import simulate_campaign

    v_max = 0.3
    for law in LAWS.values():
        box = law.prior_box(v_max)
        sampled = {SAMPLED_LAW_PARAMETERS[name] for name in parameter_names(law) if name in SAMPLED_LAW_PARAMETERS}
        assert set(box) == sampled - {"ln_q0"}, law.name
        assert all(low < high for low, high in box.values()), law.name
    for law in (QuadraticLoss, LinearLoss):
        strongest = law(q0=np.inf, alpha=law.prior_box(v_max)["alpha"][1])
        assert strongest.quality_factor(v_max) == pytest.approx(MIN_Q_AT_MAX_VELOCITY)
    log = simulate_campaign(seed=1)  # measured at the antinode: the largest velocity is the antinode's
    data = fit_data(log, "threshold")
    for name, (low, high) in LAWS["threshold"].prior_box(float(np.max(log.velocity))).items():
        i = data.layout.names.index(name)
        assert (data.lower[i], data.upper[i]) == pytest.approx((low, high)), name
