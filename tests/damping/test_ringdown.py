"""Ring-down: burst commands in the simulated generator and the driver, the envelope record, the resumable
procedure and its CLI, the closed-form decays, and Q(v) recovered from ring-downs alone and jointly with sweeps."""

import numpy as np
import pytest
from ports import ReplayPort

from instruments.drivers.errors import ConnectionLost, SafetyLimitError
from instruments.drivers.generator import FunctionGenerator
from instruments.procedures.ringdown import RingdownPlan, ringdown
from instruments.procedures.logwriter import format_value
from instruments.procedures.simulated import reopened_station, simulate_campaign, simulate_ringdown, simulated_station
from workflow import logformat
from instruments.simulator import FaultSettings, default_bench_settings
from instruments.simulator.generator import GeneratorDevice
from workflow.cli import main
from workflow.damping.fit import fit_law, parameter_summary, velocity_grid
from workflow.damping.laws import ConstantQ, LinearLoss, QuadraticLoss
from workflow.damping.logs import read_logs
from workflow.damping.ringdown import decay_velocity, integrated_decay


@pytest.mark.parametrize("law", [QuadraticLoss(150.0, 0.25), LinearLoss(120.0, 0.3), ConstantQ(80.0)])
def test_closed_form_decays_match_the_integrated_equation(law):
    time = np.linspace(0.0, 3e-3, 61)
    initial = np.array([[0.05], [0.3]])
    closed = decay_velocity(law, 31e3, initial, time)
    integrated = integrated_decay(law.quality_factor, 31e3, initial, time, nodes=512)
    assert np.allclose(closed, integrated, rtol=1e-6)
    assert np.allclose(closed, integrated_decay(law.quality_factor, 31e3, initial, time), rtol=1e-5)  # the default step
    assert np.all(np.diff(closed, axis=1) < 0)


@pytest.mark.parametrize("line, attribute, value", [
    ("BURS:STAT ON", "burst", True), ("SOUR1:BURSt:STATe 1", "burst", True), ("BURS:MODE GAT", "burst_mode", "GAT"),
    ("BURS:MODE TRIGGERED", "burst_mode", "TRIG"), ("BURS:NCYC 2000", "burst_cycles", 2000),
    ("BURS:INT:PER 2.5E-02", "burst_period", 0.025), ("TRIG:SOUR BUS", "trigger_source", "BUS"),
    ("TRIGger:SOURce EXTernal", "trigger_source", "EXT"), ("TRIG1:SOUR IMM", "trigger_source", "IMM"),
])
def test_burst_commands_parse_in_their_33500_forms(line, attribute, value):
    generator = GeneratorDevice(peak_voltage_limit=5.0)
    assert generator.handle_line(line) is None
    assert getattr(generator.state, attribute) == value
    assert generator.handle_line("SYST:ERR?") == '+0,"No error"'


def test_burst_queries_and_bad_values():
    generator = GeneratorDevice(peak_voltage_limit=5.0)
    generator.handle_line("BURS:STAT 1;:BURS:NCYC 10;:TRIG:SOUR BUS")
    assert generator.handle_line("BURS:STAT?;:BURS:MODE?;:BURS:NCYC?;:TRIG:SOUR?") == "1;TRIG;+1.00000000000000E+01;BUS"
    for bad, code in (("BURS:NCYC 2.5", "-222"), ("BURS:NCYC 0", "-222"), ("BURS:INT:PER 9000", "-222"),
                      ("BURS:MODE SOMETIMES", "-224"), ("TRIG:SOUR NOW", "-224"), ("*TRG 1", "-108")):
        generator.handle_line(bad)
        assert generator.handle_line("SYST:ERR?").startswith(code), bad
    assert generator.state.burst_cycles == 10


def test_a_burst_above_the_drive_limit_is_refused_by_instrument_and_driver():
    generator = GeneratorDevice(peak_voltage_limit=1.5)
    generator.handle_line("OUTP:LOAD INF;:VOLT 2;:BURS:STAT ON;:TRIG:SOUR BUS;:OUTP ON")
    generator.handle_line("VOLT 4")  # 2 V peak in burst mode: over the 1.5 V limit
    assert generator.handle_line("SYST:ERR?").startswith("-222")
    assert generator.state.amplitude_vpp == 2.0 and generator.state.burst
    port = ReplayPort([("VOLT:OFFS?", b"+0.00000000000000E+00\n"), ("OUTP:LOAD?", b"+9.90000000000000E+37\n")])
    driver = FunctionGenerator(port, max_peak_voltage=1.5)
    with pytest.raises(SafetyLimitError):
        driver.amplitude_vpp = 4.0
    assert port.done()  # nothing but the two queries went out


def test_driver_configures_a_bus_triggered_burst_as_pymeasure_does():
    port = ReplayPort([("BURS:MODE TRIG", None), ("BURS:NCYC 2000", None), ("TRIG:SOUR BUS", None),
                       ("BURS:STAT 1", None), ("*TRG", None)])
    generator = FunctionGenerator(port, max_peak_voltage=5.0)
    generator.configure_burst(2000)
    generator.trigger()
    assert port.done()


def test_ringdown_record_over_range_steps_up_and_logs_temperature(tmp_path):
    result = simulate_ringdown(tmp_path / "r.csv", voltages=(5.0, 15.0), samples=40)
    log = read_logs([tmp_path / "r.csv"])
    decays = log.ringdown
    assert log.n_sweeps == 0 and decays.n_bursts == 2 and len(decays.velocity) == 80
    assert np.all(np.diff(decays.velocity[decays.burst == 1][::8]) < 0)
    assert decays.velocity[decays.burst == 1][0] > decays.velocity[decays.burst == 0][0] > 0.05  # above the first range
    assert np.all(np.isfinite(decays.temperature)) and result.summary["bursts"][0]["temperature_c"] > 20


def test_ringdown_log_states_the_lock_in_settings_of_its_capture_not_those_of_the_sweeps(tmp_path):
    from instruments.drivers.lockin import capture_time_constant
    from instruments.procedures.logwriter import read_log

    simulate_ringdown(tmp_path / "r.csv", voltages=(5.0,), samples=20)
    metadata = read_log(tmp_path / "r.csv", logformat.RINGDOWN_COLUMNS).metadata
    assert metadata["lockin_reference"].startswith("INT") and metadata["lockin_filter_db_oct"] == "24"
    interval = float(metadata["lockin_capture_interval_s"])
    assert float(metadata["lockin_time_constant_s"]) == pytest.approx(capture_time_constant(interval))
    assert "per reading" not in metadata["ranging"] and "per reading" not in metadata["lockin_sensitivity_v"]


def test_ringdown_resumes_after_a_disconnect_and_records_a_burst_cut_short_again(tmp_path):
    path = tmp_path / "r.csv"
    plan = RingdownPlan(32126.0, (4.0, 8.0, 12.0), samples=20)
    settings = default_bench_settings(faults=FaultSettings(disconnect_at=100))
    station, bench = simulated_station(settings, settle_time=0.0)
    with pytest.raises(ConnectionLost, match="disconnected"):
        ringdown(station, path, plan, fsync=False)
    partial = read_logs([path]).ringdown.n_bursts
    assert 1 <= partial < 3
    first, second = (format_value(logformat.DECAY_TIME, t) for t in plan.decay_times()[:2])
    with open(path, "a") as file:  # a burst cut short: two of its rows, then half a row
        file.write(f"2,9.000,{first},32126,12,0.1,22\n2,9.000,{second},32126,12,0.09,22\n2,9.0")
    before = path.read_bytes()
    result = ringdown(reopened_station(station, bench), path, plan, fsync=False)
    assert result.resumed == 20 * partial + 2 and result.measured == 20 * (3 - partial)
    assert result.truncated_bytes == len("2,9.0") and "kept as a comment" in result.warnings[0]
    after = path.read_bytes()  # nothing deleted: the half row became a comment line, the burst was recorded again
    assert after.startswith(before[: -len("2,9.0")]) and b"resume: 2,9.0\n" in after
    decays = read_logs([path]).ringdown
    assert sorted(np.bincount(decays.burst)) == [2, 20, 20, 20]  # the two kept rows read as a short decay


def test_cli_measure_ringdown_simulated_resumes(tmp_path, capsys):
    out = tmp_path / "r.csv"
    argv = ["measure", "ringdown", "--simulate", "--out", str(out), "--voltages", "4,8", "--samples", "30",
            "--frequency-hz", "32126"]
    assert main(argv + ["--disconnect-at", "80"]) != 0
    first = len(read_logs([out]).ringdown.velocity)
    assert main(argv) == 0
    assert f"{60 - first} points measured, {first} already logged" in capsys.readouterr().out
    assert np.array_equal(np.bincount(read_logs([out]).ringdown.burst), [30, 30])


def _inside(summary, name, truth):
    return summary[name]["p05"] <= truth <= summary[name]["p95"]


def test_ringdown_alone_recovers_q_of_v(tmp_path):
    settings = default_bench_settings(seed=2)
    simulate_ringdown(tmp_path / "r.csv", settings, voltages=(3.0, 6.0, 9.0, 12.0, 15.0), interval=40e-6)
    log = read_logs([tmp_path / "r.csv"])
    fit = fit_law(log, "quadratic", seed=1, max_steps=800)
    velocity = velocity_grid(log)
    median = fit.quality_factor_quantiles(velocity, (0.5,))[0]
    assert np.max(np.abs(median / settings.response.law.quality_factor(velocity) - 1)) < 0.01


@pytest.mark.slow
def test_joint_sweeps_and_ringdowns_recover_the_law_softening_and_drift(tmp_path):
    from workflow.damping.likelihood import ForwardModel

    # the plate's warming (issue 30) off: a known truth within the fit's model; the warming's effect on the intervals is
    # the subject of bench/bench_damping_coverage.py (issue 29)
    settings = default_bench_settings(seed=4, softening=0.08, drift_rate=-0.3, heating=False)
    simulate_campaign(tmp_path / "s.csv", settings)
    simulate_ringdown(tmp_path / "r.csv", settings, voltages=(3.0, 6.0, 9.0, 12.0, 15.0), interval=40e-6)
    log = read_logs([tmp_path / "s.csv", tmp_path / "r.csv"])
    fit = fit_law(log, "quadratic", seed=0, forward=ForwardModel(softening=True, drift=True))
    summary = parameter_summary(fit)
    law = settings.response.law
    assert fit.diagnostics.converged
    for name, truth in (("alpha", law.alpha), ("kappa", 0.08), ("drift_rate", -0.3)):
        assert _inside(summary, name, truth), (name, summary[name], truth)
    # Q0 is pinned to 0.1 % by the decays; its 90 % interval [150.003, 150.356] just misses the truth 150
    assert summary["q0"]["median"] == pytest.approx(law.q0, rel=0.003)


def test_laws_without_a_closed_form_decay_are_integrated():
    """The flexible law (the misfit fallback) has no alpha: its decay is computed segment by segment, not by the power
    laws' closed forms."""
    from workflow.damping.laws import MonotoneSpline, QuadraticLoss
    from workflow.damping.ringdown import decay_velocity

    # a spline through the quadratic law's 1/Q at its knots decays like it (it is the quadratic law, linear in v^2)
    quadratic = QuadraticLoss(q0=150.0, alpha=0.25)
    rises = np.diff(quadratic.loss(MonotoneSpline.knots(0.3)))
    flexible = MonotoneSpline(150.0, *rises, v_top=0.3)
    time = np.linspace(0, 5e-3, 11)
    expected = decay_velocity(quadratic, 25e3, 0.25, time)
    assert decay_velocity(flexible, 25e3, 0.25, time) == pytest.approx(expected, rel=0.05)


def _ringdown_interval_hits(seed, tmp_path, max_steps=20000):
    """Whether the 90 % intervals of Q0 and alpha from the ring-downs alone of bench seed ``seed`` hold the truth."""
    settings = default_bench_settings(seed=100 + seed, softening=0.08, drift_rate=-0.3, heating=False)
    simulate_ringdown(tmp_path / f"r{seed}.csv", settings, voltages=(3.0, 6.0, 9.0, 12.0, 15.0), interval=40e-6)
    fit = fit_law(read_logs([tmp_path / f"r{seed}.csv"]), "quadratic", seed=seed, max_steps=max_steps, chain_taus=25)
    summary, law = parameter_summary(fit), settings.response.law
    return _inside(summary, "q0", law.q0), _inside(summary, "alpha", law.alpha)


def test_ringdown_intervals_hold_the_truth(tmp_path):
    """The white-noise envelope likelihood matches the simulated record: its 90 % intervals hold the truth (seeded).

    1000 steps (was 3000): the truth sits at the same place in the intervals on fit seeds 0-4 at 1000, 1500 and 3000
    steps (Q0 at 0.10-0.13 of the way from p05 to p95, alpha at 0.25-0.30; measured): the record sets it, not the chain."""
    assert _ringdown_interval_hits(0, tmp_path, max_steps=1000) == (True, True)


@pytest.mark.slow
def test_ringdown_intervals_cover_the_truth_over_ten_seeds(tmp_path):
    """Coverage of the 90 % intervals over 10 noise seeds: at least 7 of 10 each (a binomial(10, 0.9) falls below 7
    with probability 0.013; intervals twice too narrow would give ~6).  Measured 10/10 for Q0 and 9/10 for alpha before
    the lock-in readout; since then it fails (9/10 and 6/10 with the magnitude reading's floor in the likelihood; over
    40 seeds 85 % and 75 %, bench/bench_ringdown_coverage.py): open in issue 29, docs/damping.md."""
    hits = np.array([_ringdown_interval_hits(seed, tmp_path) for seed in range(10)])
    assert np.all(hits.sum(axis=0) >= 7), hits


def test_burst_decays_integrate_each_burst_once_and_match_the_closed_form():
    """The integrated path (laws without a closed form) gives each sample its burst's decay, as the closed form does."""
    from workflow.damping.laws import ThresholdLoss
    from workflow.damping.ringdown import burst_decays

    law = QuadraticLoss(np.array([[150.0], [120.0]]), np.array([[0.25], [0.3]]))
    burst = np.repeat([0, 1, 2], 20)
    time = np.tile(np.linspace(0.0, 2e-3, 20), 3)
    frequency, initial = np.array([31e3, 31.1e3, 30.9e3]), np.array([[0.1, 0.2, 0.3], [0.05, 0.15, 0.25]])
    closed = burst_decays(law, frequency, initial, burst, time)
    quadratic_like = ThresholdLoss(law.q0, law.alpha, v_t=np.full((2, 1), 1e-9))  # not a closed form: integrated
    assert closed.shape == (2, 60)
    assert np.allclose(burst_decays(quadratic_like, frequency, initial, burst, time), closed, rtol=1e-3)


def _tight_decay(quality_factor, frequency, initial, time):
    """ln v(t) of dv/dt = -pi f v / Q(v) by an explicit 8th-order Runge-Kutta at rtol 1e-12 (the reference)."""
    from scipy.integrate import solve_ivp

    solution = solve_ivp(lambda _, y: -np.pi * frequency / quality_factor(np.exp(y)), (0.0, time[-1]), [np.log(initial)],
                         t_eval=time, rtol=1e-12, atol=1e-13, method="DOP853")
    return solution.y[0]


def test_the_flexible_law_decays_exactly_segment_by_segment():
    """Linear in v^2 on each segment, the flexible law's decay has a closed form per segment: a spline through the
    quadratic law decays as the quadratic law to rounding, and a kinked spline as a tight ODE solution (the RK4 it
    replaced was 6e-5 off in ln v across the kinks)."""
    from workflow.damping.laws import MonotoneSpline
    from workflow.damping.ringdown import burst_decays

    quadratic = QuadraticLoss(q0=150.0, alpha=0.25)
    knots = MonotoneSpline.knots(0.45, 0.12)
    through = MonotoneSpline(150.0, *np.diff(quadratic.loss(knots)), v_top=0.45, v_first=0.12)
    time = np.linspace(0.0, 4e-3, 101)
    initial = np.array([0.05, 0.2, 0.45, 0.6])  # below the first knot, inside, at the last knot, above it
    closed = decay_velocity(quadratic, 25e3, initial[:, None], time)
    assert np.allclose(decay_velocity(through, 25e3, initial[:, None], time), closed, rtol=1e-12, atol=0)
    kinked = MonotoneSpline(150.0, *(np.diff(quadratic.loss(knots)) * [1, 1.5, 0.3, 2, 1, 0.2, 1, 1]), v_top=0.45, v_first=0.12)
    for v0 in initial:
        exact = _tight_decay(kinked.quality_factor, 25e3, v0, time)
        assert np.max(np.abs(np.log(decay_velocity(kinked, 25e3, v0, time)) - exact)) < 1e-9, v0
    # walkers and bursts: each sample reads its burst's decay
    walkers = MonotoneSpline(np.array([[150.0], [120.0]]), *(np.diff(quadratic.loss(knots))[:, None, None] * [[1.0], [2.0]]),
                             v_top=0.45, v_first=0.12)
    burst = np.repeat([0, 1], 20)
    samples = np.tile(np.linspace(0.0, 2e-3, 20), 2)
    frequency, v0 = np.array([25e3, 25.1e3]), np.array([[0.3, 0.1], [0.2, 0.4]])
    per_sample = decay_velocity(walkers, frequency[burst], v0[:, burst], samples)
    assert np.allclose(burst_decays(walkers, frequency, v0, burst, samples), per_sample, rtol=1e-14)


@pytest.mark.parametrize("initial", [0.05, 0.2, 0.45, 0.9])
def test_the_tabulated_decay_matches_a_tight_ode_solution(initial):
    """A law without a closed form (threshold): t(v) by quadrature in ln v, inverted, within 1e-6 in ln v of a tight
    ODE solution over a record that falls by up to e^-5 (the RK4 it replaced: 8e-7)."""
    from workflow.damping.laws import ThresholdLoss

    law = ThresholdLoss(q0=140.0, alpha=0.45, v_t=0.1)
    time = np.linspace(0.0, 4e-3, 101)
    tabulated = decay_velocity(law, 25e3, initial, time)
    assert np.max(np.abs(np.log(tabulated) - _tight_decay(law.quality_factor, 25e3, initial, time))) < 1e-6
    assert np.all(np.diff(tabulated) < 0)


def test_a_decay_far_out_in_the_prior_stays_finite_and_falls():
    """Q of 1-2 (alpha at its prior bound): the decay falls far below the table's depth and continues at its last rate."""
    from workflow.damping.laws import ThresholdLoss
    from workflow.damping.ringdown import MAX_DROP, integrated_decay

    law = ThresholdLoss(q0=np.array([[140.0], [2.0]]), alpha=np.array([[0.45], [300.0]]), v_t=np.array([[0.1], [0.02]]))
    time = np.linspace(0.0, 4e-3, 41)
    decay = integrated_decay(law.quality_factor, 25e3, 0.3, time)
    assert np.all(np.isfinite(decay)) and np.all(decay >= 0) and np.all(np.diff(decay, axis=-1) <= 0)
    assert decay[1, -1] < 0.3 * np.exp(-MAX_DROP)
