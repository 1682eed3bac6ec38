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
    """In measuring order (a downward sweep too), over uneven steps, the first row of a sweep over its median step."""
    log = synthetic_campaign(seed=0, voltages=(5.0, 10.0), points_per_sweep=7, alternate=True)
    rng = np.random.default_rng(1)
    log = type(log)(**{**vars(log), "timestamp": np.cumsum(rng.uniform(0.3, 1.5, len(log.velocity)))})
    heat = HeatData.of(log)
    q = np.array([[50.0], [100.0]])
    energy = heat.energy(np.broadcast_to(q, (2, len(log.velocity))))
    assert np.all(np.diff(log.frequency[log.sweep == 1]) < 0)  # the second sweep runs downward
    for k in range(log.n_sweeps):
        rows = np.nonzero(log.sweep == k)[0]  # the log's order is the measuring order
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


def q0_and_heating(log, heating: bool):
    data, theta, _, _ = map_fit(log, "quadratic", forward=ForwardModel(softening=True, drift=True, heating=heating))
    natural = data.layout.natural(theta)
    return float(natural["q0"][0]), float(natural["heating"][0]) if heating else None


def test_the_fit_recovers_the_simulated_plates_heating_and_its_q0_no_longer_reads_high(tmp_path):
    """Consistency check: a plate four times as temperature-sensitive as the default one makes Q0 read 3 % high with
    only a drift rate to follow the resonance's shift (6 % when the drift's prior was flat in its box); with the
    heating term, Q0 within 1.5 % and h within 20 %."""
    log, truth = heated_campaign(tmp_path, 4.0)
    q0_without, _ = q0_and_heating(log, heating=False)
    q0_with, h = q0_and_heating(log, heating=True)
    assert q0_without / TRUE_Q0 - 1 > 0.025
    assert q0_with == pytest.approx(TRUE_Q0, rel=0.015)
    assert h == pytest.approx(truth, rel=0.2)


def test_a_plate_that_does_not_heat_gets_no_heating(tmp_path):
    """Seeds 1-4 of a plate without heating: h 0 at the MAP, Q0 within 1.5 %."""
    cold, _ = heated_campaign(tmp_path, 0.0)
    _, heated_truth = heated_campaign(tmp_path, 1.0)
    q0, h = q0_and_heating(cold, heating=True)
    assert h < 0.2 * heated_truth
    assert q0 == pytest.approx(TRUE_Q0, rel=0.015)


def test_the_heating_needs_timestamps():
    log = synthetic_campaign(seed=0, voltages=(5.0,), points_per_sweep=7)
    untimed = type(log)(**{**vars(log), "timestamp": None})
    with pytest.raises(InputFileError, match="fitting the heating needs the 'timestamp_s' column"):
        fit_data(untimed, "quadratic", ForwardModel(heating=True))
