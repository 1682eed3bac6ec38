"""``--damping POSTERIOR`` on ``tactile maps`` (beam and FEM) and ``tactile optimize --model fem``."""

import functools
import json
from pathlib import Path

import numpy as np
import pytest

from workflow.cli import main
from workflow.damping.laws import LAWS
from workflow.damping.posterior import DampingPosterior, save_posterior, stacked_posterior
from workflow.execution.cache import EvaluationCache
from workflow.models import materials
from workflow.models.fem import FemSettings
from workflow.models.plate import Plate
from workflow.models.analytical import beam_response
from workflow.optimise.damped import damped_deflection
from workflow.optimise.problem import analytical_model
from workflow.optimise.space_mapping import FREQUENCY_TOLERANCE
from workflow.units import KHZ, MM, UM

COARSE = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=3)


@pytest.fixture
def posterior_file(tmp_path):
    """A small quadratic-law posterior (Q(0) ~ 150, strong amplitude loss) written as fit-damping does."""
    rng = np.random.default_rng(0)
    n = 40
    posterior = DampingPosterior("quadratic", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(0.25, 0.005, n)})
    return save_posterior(posterior, tmp_path / "posterior.npz", np.zeros((n, 2)), ["q0", "alpha"])


@pytest.fixture
def coarse_fem(monkeypatch, tmp_path):
    """The commands' FEM on a coarse mesh, in process, cached under tmp_path."""
    import workflow.optimise.fem_model as fem_evaluations

    monkeypatch.setenv("TACTILE_CACHE", str(tmp_path / "cache"))
    model = fem_evaluations.FemModel

    def coarse(**options):  # the commands ask for their --accuracy: the coarse mesh replaces it
        return model(**{**options, "settings": COARSE, "scheduler": "synchronous"})

    monkeypatch.setattr(fem_evaluations, "FemModel", coarse)
    return functools.partial(fem_evaluations.FemModel, cache=EvaluationCache(tmp_path / "cache"))


def run_json(capsys, *argv) -> dict:
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def grid_plate(record) -> Plate:
    lam, h_i = np.meshgrid(np.array(record["lambda_mm"]) * MM, np.array(record["h_i_mm"]) * MM, indexing="ij")
    return Plate(wavelength=lam, resonator_thickness=h_i, ceramic_thickness=record["h_p_mm"] * MM, width=record["b_mm"] * MM)


def check_required_voltage(record, voltage=materials.DESIGN_VOLTAGE):
    """A point deflecting more than the target at the design voltage needs less than it, and vice versa."""
    w, needed = np.array(record["w_dyn_um"]), np.array(record["required_voltage_v"])
    assert np.all(np.sign(needed - voltage) == np.sign(record["target_um"] - w))
    p05, p95 = np.array(record["required_voltage_v_p05"]), np.array(record["required_voltage_v_p95"])
    assert np.all(p05 <= p95) and np.all(p05 > 0)


def test_analytical_maps_with_damping(tmp_path, capsys, posterior_file):
    record = run_json(capsys, "maps", "--hp-mm", "1", "--grid", "9", "--damping", str(posterior_file), "--out", str(tmp_path), "--json")
    shape = (9, 9)
    assert len(record["lambda_mm"]) == len(record["h_i_mm"]) == 9
    for key in ("w_dyn_um", "f_r_khz", "required_voltage_v", "required_voltage_v_p05", "required_voltage_v_p95"):
        assert np.shape(record[key]) == shape, key
    assert record["damping"]["law"] == "quadratic"
    plate = grid_plate(record)
    w = np.array(record["w_dyn_um"]) * UM
    law = LAWS["quadratic"](**record["damping"]["median"])
    np.testing.assert_allclose(w, damped_deflection(beam_response(plate, materials.DESIGN_VOLTAGE), law), rtol=1e-9)
    constant, _ = analytical_model(materials.PLATE_Q)(plate)
    # w = Q(v) k V: the gain over the constant-Q map is Q(v) / 54, falling with the antinode
    # velocity v = 2 pi f_r w as the response saturates
    gain = (w / constant).ravel()
    velocity = (2 * np.pi * np.array(record["f_r_khz"]) * KHZ * w).ravel()
    order = np.argsort(velocity)
    assert np.all(np.diff(gain[order]) < 1e-12) and gain[order[0]] > 1.1 * gain[order[-1]]
    check_required_voltage(record)
    optimum = record["optimum"]
    assert optimum["f_r_khz"] >= 25 * (1 - 1e-6)
    assert optimum["q"] < 150 and optimum["required_voltage_v"]["p05"] <= optimum["required_voltage_v"]["p95"]
    assert len(record["figures"]) == 2 and all(Path(name).exists() for name in record["figures"])


def test_optimize_with_a_mixture_of_laws_names_the_law_it_describes(tmp_path, capsys):
    """A fit whose answer mixes laws (the default when they cannot be told apart) writes a stacked posterior: the
    optimum's line describes the mixture's most frequent law at its median (it once failed on the mixture's name),
    and the voltage's interval comes from draws of the whole mixture."""
    rng = np.random.default_rng(1)
    n = 400
    quadratic = DampingPosterior("quadratic", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(0.25, 0.005, n)})
    linear = DampingPosterior("linear", {"q0": rng.normal(150, 3, n), "alpha": rng.normal(0.04, 0.001, n)})
    mixed = stacked_posterior({"quadratic": quadratic, "linear": linear}, {"quadratic": 0.7, "linear": 0.3}, n)
    path = save_posterior(mixed, tmp_path / "posterior.npz", np.zeros((n, 1)), ["component"])
    record = run_json(capsys, "optimize", "--hp-mm", "1", "--damping", str(path), "--json")
    assert record["damping"]["law"] == "quadratic" and record["damping"]["posterior_law"] == "stacking"
    assert record["damping"]["median"]["q0"] == pytest.approx(150, abs=1)
    voltage = record["required_voltage_v"]
    assert voltage["p05"] < voltage["p50"] < voltage["p95"]
    assert main(["optimize", "--hp-mm", "1", "--damping", str(path)]) == 0
    line = capsys.readouterr().out.splitlines()[1]
    assert line.startswith("  Q(v) used: quadratic law, Q0 1") and "the mixture's most frequent law" in line


def test_fem_maps_with_damping(tmp_path, capsys, posterior_file, coarse_fem):
    record = run_json(
        capsys, "maps", "--model", "fem", "--hp-mm", "1", "--grid", "2", "--damping", str(posterior_file), "--out", str(tmp_path), "--json"
    )
    assert np.shape(record["w_dyn_um"]) == np.shape(record["required_voltage_v"]) == (2, 2)
    results = coarse_fem().results(grid_plate(record))
    law = LAWS["quadratic"](**record["damping"]["median"])
    w = np.array(record["w_dyn_um"]).ravel() * UM
    np.testing.assert_allclose(w, [damped_deflection(r, law) for r in results], rtol=1e-9)
    assert not np.allclose(w, [r.deflection for r in results], rtol=0.05)  # Q(v) is not the constant Q
    np.testing.assert_allclose(np.array(record["f_r_khz"]).ravel() * KHZ, [r.frequency for r in results])
    check_required_voltage(record)
    assert record["optimum"]["f_r_khz"] >= 25 * (1 - FREQUENCY_TOLERANCE)  # the space-mapping optimum


def test_fem_optimize_with_damping_is_feasible_and_self_consistent(capsys, posterior_file, coarse_fem):
    damped = run_json(capsys, "optimize", "--model", "fem", "--hp-mm", "1", "--method", "space-mapping", "--damping", str(posterior_file), "--json")
    constant = run_json(capsys, "optimize", "--model", "fem", "--hp-mm", "1", "--method", "space-mapping", "--json")
    assert damped["method"] == "space-mapping" and damped["fine_evaluations"] >= 1
    assert damped["f_r_khz"] >= 25 * (1 - FREQUENCY_TOLERANCE) and damped["constraint_active"]
    assert damped["damping"]["law"] == "quadratic"
    # the deflection is the best mode's, with the Q it settles at
    plate = Plate(
        wavelength=damped["lambda_mm"] * MM,
        resonator_thickness=damped["h_i_mm"] * MM,
        ceramic_thickness=damped["h_p_mm"] * MM,
        width=damped["b_mm"] * MM,
    )
    (result,) = coarse_fem().results(plate)
    assert damped["w_dyn_um"] * UM == pytest.approx(float(result.deflection_at_q(damped["q"])), rel=1e-6)
    assert damped["w_dyn_um"] != pytest.approx(constant["w_dyn_um"], rel=0.05)
    # the optimum geometry barely moves with Q(v) (the paper, docs/damping.md)
    assert damped["lambda_mm"] == pytest.approx(constant["lambda_mm"], rel=0.02)
    v = damped["required_voltage_v"]
    assert v["p05"] <= v["p50"] <= v["p95"]
    assert np.sign(v["p50"] - materials.DESIGN_VOLTAGE) == np.sign(v["target_um"] - damped["w_dyn_um"])
