"""The plate's heating within a sweep: the dissipated energy the fit counts, and its recovery from bench campaigns.

The recoveries here run through our own bench simulator (whose plate heats by its lumped thermal model,
instruments/simulator/thermal.py): they are consistency checks of the fit against the simulator, not validations.
"""

from dataclasses import replace

import numpy as np
import pytest

from instruments.procedures.simulated import simulate_campaign
from instruments.simulator import default_bench_settings
from workflow.damping.fit import map_fit
from workflow.damping.likelihood import ForwardModel, HeatData, fit_data
from workflow.damping.logs import read_logs
from workflow.damping.synthetic import simulate_campaign as synthetic_campaign
from workflow.errors import InputFileError

TRUE_Q0 = 150.0
"""Q0 of the bench's default law [-]."""


def test_the_energy_counted_is_what_each_row_dissipated_since_its_sweep_began():
    log = synthetic_campaign(seed=0, voltages=(5.0, 10.0), points_per_sweep=7)
    heat = HeatData.of(log)
    q = np.array([[50.0], [100.0]])
    energy = heat.energy(np.broadcast_to(q, (2, len(log.velocity))))
    for k in range(log.n_sweeps):
        rows = np.nonzero(log.sweep == k)[0]
        time = log.timestamp[rows]
        dt = np.r_[np.median(np.diff(time)), np.diff(time)]
        u = log.velocity[rows] / log.measurement_factor()[rows]
        expected = np.cumsum(np.pi * log.frequency[rows] * u**2 * dt)
        assert np.allclose(energy[:, rows], expected[None, :] / q, rtol=1e-12)  # restarts at each sweep


def heated_campaign(tmp_path, factor: float, seed: int = 1):
    """A bench campaign on the default plate whose frequency coefficient is ``factor`` times the literature value
    (0: no heating), and the plate's true heating coefficient h = |c| m_eff / C [kg/J]."""
    settings = default_bench_settings(seed=seed, heating=factor > 0)
    thermal = settings.response.thermal
    if thermal is not None:
        thermal = thermal.scaled(factor)
        settings = replace(settings, response=replace(settings.response, thermal=thermal))
    path = tmp_path / f"campaign{factor:g}.csv"
    simulate_campaign(path, settings=settings)
    truth = 0.0 if thermal is None else -thermal.frequency_coefficient * thermal.modal_mass / thermal.heat_capacity
    return read_logs([path]), truth


def fitted(log, heating: bool) -> dict:
    data, theta, _, _ = map_fit(log, "quadratic", forward=ForwardModel(softening=True, drift=True, heating=heating))
    return {name: float(values[0]) for name, values in data.layout.natural(theta).items()}


BENCH_DRIFT = default_bench_settings().response.drift_rate
"""The bench's own slow drift of the resonance [Hz/s] (the room)."""


def test_the_fit_recovers_the_simulated_plates_heating_and_no_longer_calls_it_a_drift(tmp_path):
    """Consistency check: a plate four times as temperature-sensitive as the default one.  With only a drift rate to
    follow its resonance the fit takes the heating for a drift of about -0.5 Hz/s (the bench's is -0.02); with the
    heating term, h within 10 % of the simulator's, the drift the bench's and Q0 within 1 % (seeds 1-4: h 0.93-1.02
    of the truth, drift -0.04 to 0.01 Hz/s, Q0 within 0.4 %)."""
    log, truth = heated_campaign(tmp_path, 4.0)
    without, with_heating = fitted(log, heating=False), fitted(log, heating=True)
    assert without["drift_rate"] < -0.3
    assert with_heating["heating"] == pytest.approx(truth, rel=0.1)
    assert with_heating["drift_rate"] == pytest.approx(BENCH_DRIFT, abs=0.1)
    assert with_heating["q0"] == pytest.approx(TRUE_Q0, rel=0.01)


def test_a_plate_that_does_not_heat_gets_little_heating(tmp_path):
    """Seeds 1-4 of a plate without heating: h 0.08-0.39 of the default plate's."""
    cold, _ = heated_campaign(tmp_path, 0.0)
    _, heated_truth = heated_campaign(tmp_path, 1.0)
    result = fitted(cold, heating=True)
    assert result["heating"] < 0.5 * heated_truth
    assert result["q0"] == pytest.approx(TRUE_Q0, rel=0.01)


def test_the_heating_needs_timestamps():
    log = synthetic_campaign(seed=0, voltages=(5.0,), points_per_sweep=7)
    untimed = type(log)(**{**vars(log), "timestamp": None})
    with pytest.raises(InputFileError, match="fitting the heating needs the 'timestamp_s' column"):
        fit_data(untimed, "quadratic", ForwardModel(heating=True))
