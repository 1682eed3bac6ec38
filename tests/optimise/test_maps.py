"""Design maps, width sweep and the maps command."""

import json

import numpy as np
import pytest
from user_facing import run_cli

from workflow.execution.cache import EvaluationCache
from workflow.models.fem import FemSettings
from workflow.models.plate import ORIGINAL_PLATE
from workflow.optimise.fem_model import FemModel
from workflow.optimise.maps import design_map, width_sweep
from workflow.optimise.problem import DesignProblem, analytical_model, optimise_analytical

TINY = FemSettings(elements_per_ceramic=2, elements_across_half_width=2, elements_per_layer=1, n_modes=3)


def test_analytical_map_brackets_the_optimum():
    problem = DesignProblem(1e-3)
    optimum = optimise_analytical(problem)
    result = design_map(analytical_model(), problem, 41, "analytical", optimum)
    assert result.deflection.shape == result.frequency.shape == (41, 41)
    feasible = (result.frequency >= problem.min_frequency) & (result.resonator_thickness[None, :] >= problem.min_resonator_thickness)
    # no feasible grid point beats the optimiser, and the best one is close to it
    assert result.deflection[feasible].max() <= optimum.deflection * (1 + 1e-9)
    assert result.deflection[feasible].max() > 0.95 * optimum.deflection
    assert np.all(np.diff(result.frequency, axis=0) < 0)  # longer wavelength, lower resonance


def test_fem_map_has_modes_and_uses_the_cache(tmp_path):
    problem = DesignProblem(1e-3)
    model = FemModel(settings=TINY, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    result = design_map(model, problem, 2, "fem", results=model.results)
    assert result.modes is not None and len(result.modes) == 4
    assert all(len(modes) == 3 for modes in result.modes)
    assert result.frequency[0, 1] > result.frequency[1, 1]
    cached = FemModel(settings=TINY, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    again = design_map(cached, problem, 2, "fem", results=cached.results)
    np.testing.assert_array_equal(again.deflection, result.deflection)


def test_width_sweep_marks_transverse_points(tmp_path):
    model = FemModel(settings=TINY, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    sweep = width_sweep(model, ORIGINAL_PLATE, np.array([30e-3, 55e-3]))
    assert sweep.deflection.shape == sweep.transverse.shape == (2,)
    assert np.all((sweep.transverse_indicator >= 0) & (sweep.transverse_indicator <= 1))


def test_maps_command_json_shape(tmp_path, capsys):
    code, out, _ = run_cli(capsys, "maps", "--hp-mm", "2", "--grid", "7", "--out", str(tmp_path), "--json")
    assert code == 0
    record = json.loads(out.strip().splitlines()[-1])
    assert len(record["lambda_mm"]) == len(record["h_i_mm"]) == 7
    assert np.shape(record["w_dyn_um"]) == np.shape(record["f_r_khz"]) == (7, 7)
    assert record["lambda_mm"][0] == pytest.approx(15) and record["h_i_mm"][-1] == pytest.approx(3)
    assert record["optimum"]["f_r_khz"] == pytest.approx(25, rel=1e-4)
    assert all((tmp_path / name).stat().st_size > 10_000 for name in [p.split("/")[-1] for p in record["figures"]])


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--hp-mm", "0.7"], "not a commercial size"),
        (["--hp-mm", "1", "--grid", "1"], "--grid"),
        (["--hp-mm", "1", "--width-sweep"], "--width-sweep needs --model fem"),
        (["--hp-mm", "1", "--b-mm", "120"], "--b-mm: 120 is outside the accepted range 30 to 100 mm"),
    ],
)
def test_maps_bad_input_is_one_line(argv, message, tmp_path, capsys):
    code, _, err = run_cli(capsys, "maps", *argv, "--out", str(tmp_path))
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
