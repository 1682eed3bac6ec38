"""The Q(v) answer's law uncertainty (issue 29): the threshold law's fitted onset width, the close laws mixed in
equal shares, the effects fitted by default where the logs can show them, old posterior files still read."""

import re

import numpy as np
import pytest

from instruments.procedures.simulated import simulate_campaign as simulate_bench_campaign
from instruments.procedures.simulated import simulate_ringdown
from workflow.damping.comparison import LawComparison, answer_shares
from workflow.damping.laws import StackedLaws, ThresholdLoss
from workflow.damping.likelihood import MAX_DRIFT_SHARE, ForwardModel, default_forward_model, fit_data
from workflow.damping.logs import read_logs
from workflow.damping.posterior import DampingPosterior, load_posterior, save_posterior, stacked_posterior
from workflow.damping.synthetic import simulate_campaign

SMALL = dict(voltages=(3.0, 9.0, 15.0), points_per_sweep=20)


def test_the_onset_width_shapes_the_threshold_and_its_old_value_is_the_default():
    sharp, default, broad = (ThresholdLoss(150.0, 0.5, 0.1, onset) for onset in (0.05, 0.2, 1.0))
    assert ThresholdLoss(150.0, 0.5, 0.1) == default
    v_t = np.array([0.1])
    excess = [law.loss(v_t)[0] - 1 / 150.0 for law in (sharp, default, broad)]
    assert excess == pytest.approx([0.5 * (s * 0.1 * np.log(2)) ** 2 for s in (0.05, 0.2, 1.0)])
    far = np.array([0.6])  # far above the onset every width gives the shifted quadratic
    assert sharp.loss(far) == pytest.approx(default.loss(far), rel=1e-6)


def test_a_posterior_file_written_before_the_onset_was_fitted_reads_with_the_old_fixed_onset(tmp_path):
    posterior = DampingPosterior("threshold", {"q0": np.full(5, 150.0), "alpha": np.full(5, 0.5), "v_t": np.full(5, 0.1)})
    loaded = load_posterior(save_posterior(posterior, tmp_path / "posterior.npz", np.zeros((1, 1)), ["x"]))
    assert np.all(loaded.parameters["onset"] == 0.2)
    stacked = stacked_posterior({"threshold": loaded, "flexible": DampingPosterior("flexible", {
        "q0": np.full(5, 90.0), **{f"d{k}": np.zeros(5) for k in range(1, 9)}, "v_top": np.full(5, 0.2),
        "v_first": np.full(5, 0.05)})}, {"threshold": 0.5, "flexible": 0.5}, 40, seed=0)
    names = [name for name in stacked.parameters if name != "threshold_onset"]
    old = DampingPosterior(StackedLaws.name, {name: stacked.parameters[name] for name in names})
    again = load_posterior(save_posterior(old, tmp_path / "stacked.npz", np.zeros((1, 1)), ["x"]))
    assert np.all(again.parameters["threshold_onset"] == 0.2)


def test_a_mixture_keeps_each_posterior_sample_whole():
    """Each draw takes all of a law's parameters from one posterior sample (their correlations are the posterior's:
    drawn column by column, a band of Q(v) came out 1.6 times too wide on the coverage study's truth 1)."""
    q0 = np.linspace(100.0, 200.0, 50)
    quadratic = DampingPosterior("quadratic", {"q0": q0, "alpha": q0 / 1000.0})
    threshold = DampingPosterior("threshold", {"q0": q0, "alpha": q0 / 500.0, "v_t": q0 / 2000.0, "onset": q0 / 400.0})
    stacked = stacked_posterior({"quadratic": quadratic, "threshold": threshold}, {"quadratic": 0.5, "threshold": 0.5},
                                200, seed=1)
    p = stacked.parameters
    assert np.allclose(p["quadratic_alpha"], p["quadratic_q0"] / 1000.0)
    assert np.allclose(p["threshold_v_t"], p["threshold_q0"] / 2000.0) and np.allclose(p["threshold_onset"], p["threshold_q0"] / 400.0)


def comparison(elpd: dict, dse: dict) -> LawComparison:
    best = max(elpd, key=elpd.get)
    laws = {name: {"elpd_loo": value, "elpd_diff": elpd[best] - value, "dse": dse.get(name, 0.0)} for name, value in elpd.items()}
    return LawComparison(laws, best, {name: 1.0 / len(elpd) for name in elpd})


def test_the_answer_mixes_in_equal_shares_the_laws_the_data_do_not_tell_apart_that_pass_their_checks():
    close = comparison({"threshold": 10.0, "flexible": 9.0, "quadratic": -40.0}, {"flexible": 2.0, "quadratic": 5.0})
    assert close.close == ("threshold", "flexible")
    assert answer_shares(close, {"threshold": True, "flexible": True, "quadratic": True}) == {"threshold": 0.5, "flexible": 0.5}
    assert answer_shares(close, {"threshold": True, "flexible": False, "quadratic": True}) == {"threshold": 1.0}
    apart = comparison({"threshold": 10.0, "flexible": 0.0}, {"flexible": 2.0})
    assert answer_shares(apart, {"threshold": True, "flexible": True}) == {"threshold": 1.0}


def test_softening_drift_and_heating_are_fitted_by_default_where_the_logs_can_show_them_and_the_drift_is_bounded(tmp_path):
    campaign = simulate_campaign(seed=1, **SMALL)
    assert default_forward_model(campaign) == ForwardModel(softening=True, drift=True, heating=True)
    untimed = type(campaign)(**{**vars(campaign), "timestamp": None})
    assert default_forward_model(untimed) == ForwardModel(softening=True, drift=False, heating=False)
    data = fit_data(campaign, "quadratic", default_forward_model(campaign))
    sweep_rate = 2 * 1000.0 / (SMALL["points_per_sweep"] - 1)  # the synthetic sweeps: 2 kHz at one point a second
    bound = data.upper[data.layout.names.index("drift_rate")]
    assert bound == pytest.approx(MAX_DRIFT_SHARE * sweep_rate, rel=1e-6)
    simulate_bench_campaign(tmp_path / "c.csv", points_per_sweep=11, voltages=(5.0,))
    simulate_ringdown(tmp_path / "r.csv", voltages=(5.0,), samples=20)
    assert default_forward_model(read_logs([tmp_path / "r.csv"])) == ForwardModel()
    assert default_forward_model(read_logs([tmp_path / "c.csv"])).drift


def test_a_mixture_describes_itself_by_its_laws_shares():
    rng = np.random.default_rng(0)
    n = 1000
    quadratic = DampingPosterior("quadratic", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(0.25, 0.005, n)})
    linear = DampingPosterior("linear", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(0.04, 0.001, n)})
    assert quadratic.description == "quadratic"
    mixed = stacked_posterior({"quadratic": quadratic, "linear": linear}, {"quadratic": 0.25, "linear": 0.75}, 4000)
    assert re.fullmatch(r"mixture of linear 7\d %, quadratic 2\d %", mixed.description), mixed.description


@pytest.mark.parametrize("stacked", [False, True])
def test_the_shape_discrepancy_scales_each_samples_q_at_every_velocity_and_keeps_the_median(stacked):
    from workflow.damping.posterior import with_shape_discrepancy

    rng = np.random.default_rng(3)
    n = 4000
    quadratic = DampingPosterior("quadratic", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(0.25, 0.01, n)})
    threshold = DampingPosterior("threshold", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(2.0, 0.1, n),
                                               "v_t": rng.normal(0.1, 0.005, n), "onset": np.full(n, 0.3)})
    posterior = (stacked_posterior({"quadratic": quadratic, "threshold": threshold}, {"quadratic": 0.5, "threshold": 0.5}, n)
                 if stacked else quadratic)
    widened = with_shape_discrepancy(posterior, 0.01, seed=5)
    velocity = np.array([0.0, 0.05, 0.12, 0.25])[:, None]
    before = posterior.law_from_samples().quality_factor(velocity)
    after = widened.law_from_samples().quality_factor(velocity)
    ratio = after / before
    np.testing.assert_allclose(ratio, np.broadcast_to(ratio[:1], ratio.shape), rtol=1e-12)  # one factor per sample, the same at every velocity
    assert np.std(np.log(ratio[0])) == pytest.approx(0.01, rel=0.05)
    assert abs(np.median(np.log(ratio[0]))) < 0.001
    assert with_shape_discrepancy(posterior, 0.0) is posterior
    if stacked:
        np.testing.assert_array_equal(widened.parameters["component"], posterior.parameters["component"])
        assert widened.parameters["threshold_v_t"] is posterior.parameters["threshold_v_t"]


def test_a_posterior_at_the_q0_bound_still_reads_back_with_the_shape_discrepancy(tmp_path):
    """A flexible law whose Q0 sits at the prior's upper bound (the data not reaching low velocities) is scaled within
    the accepted range, so that the file fit-damping writes is one --damping reads."""
    from workflow.damping.likelihood import Q0_RANGE
    from workflow.damping.posterior import with_shape_discrepancy

    n = 200
    posterior = DampingPosterior("quadratic", {"q0": np.full(n, Q0_RANGE[1] * 0.999), "alpha": np.full(n, 0.25)})
    widened = with_shape_discrepancy(posterior, 0.01, seed=1)
    assert widened.parameters["q0"].max() == Q0_RANGE[1] and widened.parameters["q0"].min() < Q0_RANGE[1] * 0.99
    path = save_posterior(widened, tmp_path / "posterior.npz", np.zeros((n, 1)), ["q0"])
    np.testing.assert_array_equal(load_posterior(path).parameters["q0"], widened.parameters["q0"])
