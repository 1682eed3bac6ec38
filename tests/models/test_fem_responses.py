"""Responses around the working mode: frequency response and switch-on transient."""

import numpy as np
import pytest

from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.responses import frequency_response, switch_on_response, transient_response
from workflow.models.plate import ORIGINAL_PLATE

SETTINGS = FemSettings(elements_per_ceramic=4, elements_per_layer=1, elements_across_half_width=4)


@pytest.fixture(scope="module")
def clean_result():
    return evaluate_fem(ORIGINAL_PLATE.with_(width=55e-3), 54.0, 15.0, SETTINGS)


@pytest.mark.parametrize("q", [20.0, 54.0])
def test_switch_on_time_constant_is_q_over_pi_f(clean_result, q):
    transient = transient_response(clean_result, q)
    assert transient.time_constant == pytest.approx(q / (np.pi * clean_result.frequency), rel=0.02)
    assert transient.time_constant == pytest.approx(transient.expected_time_constant, rel=0.02)
    assert transient.envelope[0] == pytest.approx(0.0, abs=1e-12)
    assert transient.envelope[-1] == pytest.approx(transient.steady_amplitude, rel=0.01)
    assert transient.steady_amplitude == pytest.approx(float(clean_result.deflection_at_q(q)), rel=1e-12)


def test_switch_on_starts_at_rest_and_reaches_unit_amplitude():
    time = np.linspace(0, 0.05, 200001)
    x, v = switch_on_response(time, 1000.0, 1000.0, 10.0)
    assert x[0] == pytest.approx(0.0, abs=1e-12) and v[0] == pytest.approx(0.0, abs=1e-9)
    assert np.gradient(x, time)[1000] == pytest.approx(v[1000], rel=1e-3)
    assert np.abs(x[-2000:]).max() == pytest.approx(1.0, rel=1e-3)


def test_frequency_response_peaks_at_the_working_mode(clean_result):
    response = frequency_response(clean_result, 54.0)
    peak = response.frequency[np.argmax(response.deflection)]
    assert peak == pytest.approx(clean_result.frequency, rel=2e-3)
    assert response.deflection.max() == pytest.approx(clean_result.deflection, rel=0.01)
    # half-power bandwidth ~ f_r / Q
    half = response.deflection >= response.deflection.max() / np.sqrt(2)
    bandwidth = np.ptp(response.frequency[half])
    assert bandwidth == pytest.approx(clean_result.frequency / 54.0, rel=0.15)


def test_figures_draw_the_responses(clean_result, tmp_path):
    from workflow.pipeline.figures.fem_responses import (
        frequency_response_figure,
        modes_figure,
        transient_figure,
    )

    figures = [
        modes_figure(clean_result),
        frequency_response_figure(frequency_response(clean_result, 54.0)),
        transient_figure(transient_response(clean_result, 54.0)),
    ]
    for index, figure in enumerate(figures):
        path = tmp_path / f"figure{index}.png"
        figure.savefig(path)
        assert path.stat().st_size > 10_000
        assert len(figure.axes[0].lines) >= 1
