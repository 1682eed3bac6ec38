"""Calibration to built plates: surrogate accuracy against fresh FEM, recovery of known deviations,
the calibrate CLI contract and its bad inputs, predictions with --calibration, the case study."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from calibration_setup import (
    BEAM_FEM,
    FAST,
    FEM_RECORD,
    P1,
    P2,
    SHORT,
    SHORT_CONFIG,
    TRUTH,
    BeamResult,
    beam_calibration,
)

from workflow.calibration.calibration import Calibration, MeasuredPlate, calibrate, nominal_theta, predict
from workflow.calibration.case_study import cross_predictions
from workflow.calibration.logs import read_built_plate
from workflow.resonance import log_parabolic_peak_frequency
from workflow.calibration.parameters import default_settings, deviated_plate, load_settings
from workflow.calibration.plate_surrogate import DesignFem, build_plate_surrogate
from workflow.calibration.surrogate import fit_response_surface, latin_hypercube
from workflow.cli import main
from workflow.errors import InputFileError
from workflow.models.plate import Plate
from workflow.units import KHZ, MM, UM


def built_plate_frequency(model, plate, theta=TRUTH) -> float:
    """The 'measured' f_r of a built plate: the FEM of the nominal plate with the hidden deviations [Hz]."""
    (result,) = model.evaluate_plates([deviated_plate(plate, default_settings().names, theta)])
    return result.frequency


def write_log(path: Path, plate: Plate, frequency: float, metadata: dict | None = None, q: float = 60.0) -> Path:
    """A format-1 built-plate log: geometry metadata and one resonance sweep (Lorentzian velocity) around f_r, its
    amplitude made up (``# amplitude: synthesised``: no deflection per volt)."""
    meta = {"lambda_mm": plate.wavelength / MM, "h_i_mm": plate.resonator_thickness / MM,
            "h_p_mm": plate.ceramic_thickness / MM, "b_mm": plate.width / MM, "amplitude": "synthesised"}
    meta.update(metadata or {})
    f = np.linspace(frequency * 0.97, frequency * 1.03, 61)
    v = 0.1 / np.sqrt(1 + (q * (f / frequency - frequency / f)) ** 2)
    lines = ["# built plate (test)"] + [f"# {k}: {v}" for k, v in meta.items() if v is not None]
    lines += ["frequency_hz,drive_voltage_v,velocity_m_s,sweep"] + [f"{a:.3f},5.0,{b:.6e},0" for a, b in zip(f, v)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_response_surface_is_exact_on_a_quadratic_and_its_loo_error_sees_a_wrong_degree():
    bounds = np.array([[0.8, 1.2], [0.0, 60e-6], [-60e-6, 60e-6]])
    points = latin_hypercube(20, bounds, seed=3)
    quadratic = lambda x: 1 + 2 * x[..., 0] ** 2 + 3e3 * x[..., 1] - 1e8 * x[..., 1] * x[..., 2]  # noqa: E731
    exact = fit_response_surface(points, quadratic(points), bounds, degree=2)
    fresh = latin_hypercube(7, bounds, seed=4)
    assert np.allclose(exact(fresh), quadratic(fresh), rtol=1e-9)
    assert exact.loo_rms < 1e-9
    linear = fit_response_surface(points, quadratic(points), bounds, degree=1)
    assert linear.loo_rms > 1e-3


def test_peak_of_a_sweep_is_located_between_its_points():
    f = np.linspace(24e3, 26e3, 41)
    v = 1 / np.sqrt(1 + (50 * (f / 25_013.0 - 25_013.0 / f)) ** 2)
    assert log_parabolic_peak_frequency(f, v) == pytest.approx(25_013.0, abs=5.0)
    assert log_parabolic_peak_frequency(f, f) is None


def test_surrogate_error_against_fresh_fem_evaluations(coarse_model):
    settings = FAST
    surrogate = build_plate_surrogate(P1, settings.names, settings.bounds, coarse_model.design_fem(),
                                      settings.surrogate_points, 2, seed=settings.surrogate_seed)
    fresh = latin_hypercube(6, settings.bounds, seed=11)[1:]
    results = coarse_model.evaluate_plates([deviated_plate(P1, settings.names, theta) for theta in fresh])
    errors = surrogate.frequency(fresh) / np.array([r.frequency for r in results]) - 1
    assert np.max(np.abs(errors)) < 4e-3
    assert np.sqrt(np.mean(errors**2)) < 4 * surrogate.log_frequency.loo_rms + 5e-4
    deflection_errors = surrogate.deflection(fresh) / np.array([r.deflection for r in results]) - 1
    assert np.max(np.abs(deflection_errors)) < 0.03


def test_known_deviations_are_recovered_along_the_constrained_directions(coarse_model):
    """Two built plates simulated with hidden deviations: the truth lies within the posterior along the combinations
    the data constrain, and each plate's measured frequency within its posterior predictive interval."""
    plates = [MeasuredPlate(name, plate, built_plate_frequency(coarse_model, plate)) for name, plate in (("P1", P1), ("P2", P2))]
    calibration = calibrate(plates, FAST, coarse_model.design_fem(), {})
    assert calibration.diagnostics.converged
    identified = calibration.identifiability()
    constrained = [d for d in identified["directions"] if d["constrained"]]
    assert 1 <= len(constrained) < 4, "two frequencies cannot pin four parameters"
    mean, sd = calibration.settings.prior_scale()
    for direction in constrained:
        weights = np.array([direction["weights"][n] for n in calibration.settings.names])
        projected = ((calibration.samples - mean) / sd) @ weights
        truth = ((TRUTH - mean) / sd) @ weights
        low, high = np.percentile(projected, [1, 99])
        assert low <= truth <= high
    for plate, surrogate in zip(plates, calibration.surrogates):
        p05, _, p95 = predict(calibration, plate.plate, None, surrogate).frequency
        assert p05 <= plate.frequency <= p95
    nominal = [built_plate_frequency(coarse_model, p.plate, nominal_theta(FAST.names, p.plate)) for p in plates]
    assert all(n > p.frequency for n, p in zip(nominal, plates)), "the deviations lower both frequencies"


def test_calibrate_cli_contract_and_evaluate_with_the_calibration(tmp_path, capsys, coarse_cli, coarse_model):
    measured = built_plate_frequency(coarse_model, P1)
    log = write_log(tmp_path / "p1.csv", P1, measured)
    before = log.read_bytes()
    config = tmp_path / "fast.toml"
    config.write_text(SHORT_CONFIG, encoding="utf-8")
    assert main(["calibrate", str(log), "--out", str(tmp_path / "cal"), "--config", str(config), "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert log.read_bytes() == before
    assert set(record["parameters"]) == set(FAST.names)
    for summary in record["parameters"].values():
        assert summary["p05"] <= summary["median"] <= summary["p95"]
    (plate,) = record["plates"]
    assert plate["log"] == str(log) and plate["data_used"] == ["resonance frequency"]
    assert plate["measured_f_khz"] == pytest.approx(measured / KHZ, rel=2e-4)
    assert plate["predicted_f_khz_p05"] <= plate["measured_f_khz"] <= plate["predicted_f_khz_p95"]
    assert plate["nominal_f_khz"] > plate["measured_f_khz"]
    assert Path(record["calibration"]).is_file() and all(Path(f).is_file() for f in record["figures"])
    assert {"tau_max", "n_steps", "acceptance", "converged", "steps_per_tau"} <= set(record["diagnostics"])
    assert record["identifiability"]["constrained"] == 1 and "trade off" in record["identifiability"]["statement"]
    assert record["fem_evaluations"] == FAST.surrogate_points + 1

    assert main(["evaluate", "--model", "fem", "--lambda-mm", "20.56", "--hi-mm", "0.75", "--hp-mm", "1", "--accuracy",
                 "0.05", "--calibration", str(tmp_path / "cal"), "--json"]) == 0
    evaluated = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert evaluated["f_r_khz_p05"] <= evaluated["f_r_khz"] <= evaluated["f_r_khz_p95"]
    assert evaluated["w_dyn_um_p05"] <= evaluated["w_dyn_um"] <= evaluated["w_dyn_um_p95"]
    assert evaluated["f_r_khz_p05"] <= measured / KHZ <= evaluated["f_r_khz_p95"]
    assert evaluated["calibration"]["fem_evaluations"] == 12
    assert main(["evaluate", "--model", "fem", "--lambda-mm", "20.56", "--hi-mm", "0.75", "--hp-mm", "1", "--accuracy",
                 "0.05", "--calibration", str(tmp_path / "cal")]) == 0
    lines = capsys.readouterr().out.splitlines()
    # people read the nominal FEM first, then the calibrated prediction with its band
    assert f"at f_r {evaluated['nominal_f_r_khz']:.3f} kHz" in lines[0]
    (calibrated,) = [line for line in lines if line.startswith("  calibrated (")]
    assert (f"f_r {evaluated['f_r_khz']:.3f} kHz (90 %: {evaluated['f_r_khz_p05']:.3f} to "
            f"{evaluated['f_r_khz_p95']:.3f})") in calibrated


@pytest.mark.parametrize(
    "metadata, message",
    [({"lambda_mm": None}, "lambda_mm"), ({"h_p_mm": "thick"}, "h_p_mm"), ({"ceramic": "unobtainium"}, "not a material record")],
)
def test_calibrate_refuses_a_log_without_a_usable_geometry(tmp_path, capsys, metadata, message):
    log = write_log(tmp_path / "bad.csv", P1, 23e3, metadata)
    assert main(["calibrate", str(log), "--out", str(tmp_path / "out"), "--json"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and str(log) in error and message in error


def test_calibrate_refuses_a_bad_settings_file_and_a_missing_calibration(tmp_path, capsys):
    config = tmp_path / "bad.toml"
    config.write_text("[parameter.glue_um]\nprior = \"uniform\"\nlow = 60\nhigh = 0\n", encoding="utf-8")
    with pytest.raises(InputFileError, match="bad.toml.*low must be below high"):
        load_settings(config)
    log = write_log(tmp_path / "p1.csv", P1, 23e3)
    assert main(["calibrate", str(log), "--out", str(tmp_path / "out"), "--config", str(config)]) == 2
    assert "low must be below high" in capsys.readouterr().err
    assert main(["evaluate", "--model", "fem", "--lambda-mm", "20", "--hi-mm", "0.7", "--hp-mm", "1",
                 "--calibration", str(tmp_path / "none.json"), "--damping", str(tmp_path / "none.npz")]) == 2
    assert "cannot be combined" in capsys.readouterr().err  # the calibrated band and Q(v)'s would share keys
    assert main(["evaluate", "--model", "fem", "--lambda-mm", "20", "--hi-mm", "0.7", "--hp-mm", "1",
                 "--calibration", str(tmp_path / "none.json")]) == 2
    assert "--calibration" in capsys.readouterr().err
    (tmp_path / "other.json").write_text('{"format": "something else"}', encoding="utf-8")
    assert main(["evaluate", "--model", "fem", "--lambda-mm", "20", "--hi-mm", "0.7", "--hp-mm", "1",
                 "--calibration", str(tmp_path / "other.json")]) == 2
    assert "not a calibration file" in capsys.readouterr().err


def test_calibration_file_round_trips(coarse_model):
    plate = MeasuredPlate("P1", P1, built_plate_frequency(coarse_model, P1))
    calibration = calibrate([plate], replace(FAST, steps=300, kept_samples=200), coarse_model.design_fem(), FEM_RECORD)
    again = Calibration.from_dict(json.loads(json.dumps(calibration.to_dict())))
    assert np.array_equal(again.samples, calibration.samples)
    assert again.surrogates[0].log_frequency(TRUTH) == pytest.approx(calibration.surrogates[0].log_frequency(TRUTH))
    assert again.plates[0].plate.wavelength == P1.wavelength and again.settings == calibration.settings


def test_case_study_predicts_one_built_plate_from_the_other(coarse_model):
    """Built plates sharing the hidden deviations: each calibrated alone predicts the other inside its interval."""
    first = MeasuredPlate("P1", P1, built_plate_frequency(coarse_model, P1))
    second = MeasuredPlate("P2", P2, built_plate_frequency(coarse_model, P2))
    directions = cross_predictions(first, second, SHORT, coarse_model.design_fem(), {})
    assert [d.predicted for d in directions] == ["P2", "P1"]
    for d in directions:
        assert d.inside, d
        assert d.band[0] < d.band[1] < d.band[2]
        assert abs(d.error) < 0.02
        source = first if d.calibrated_on == "P1" else second
        assert d.source_fit == pytest.approx(source.frequency, rel=3e-3)


def test_read_built_plate_takes_materials_and_glue_from_the_metadata(tmp_path):
    log = read_built_plate(write_log(tmp_path / "p.csv", P2, 24e3, {"ceramic": "PZT-5A", "glue_um": 20}))
    assert log.plate.ceramic.name == "PZT-5A" and log.plate.glue_thickness == pytest.approx(20 * UM)
    assert log.frequency == pytest.approx(24e3, rel=1e-4)


def _calibrate_on_p1(tmp_path, capsys, coarse_model) -> None:
    """``tactile calibrate`` on P1's simulated resonance log (2000 steps, 18 surrogate points) into tmp_path / cal."""
    log = write_log(tmp_path / "p1.csv", P1, built_plate_frequency(coarse_model, P1))
    config = tmp_path / "fast.toml"
    config.write_text("[sampler]\nsteps = 2000\n[surrogate]\npoints = 18\n", encoding="utf-8")
    assert main(["calibrate", str(log), "--out", str(tmp_path / "cal"), "--config", str(config), "--no-figures"]) == 0
    capsys.readouterr()


@pytest.mark.slow
def test_robust_optimum_probability_checked_by_direct_fem_sampling(tmp_path, capsys, coarse_cli, coarse_model):
    """The robust optimum of 'optimize --calibration' meets 25 kHz on most direct FEM draws of posterior and scatter."""
    from workflow.optimise.robust import Tolerances, robust_inputs, scattered_draws

    _calibrate_on_p1(tmp_path, capsys, coarse_model)
    assert main(["optimize", "--model", "fem", "--hp-mm", "1", "--calibration", str(tmp_path / "cal"),
                 "--stock-hi-mm", "0.75,1.0", "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert record["probability"] == pytest.approx(0.95, abs=4 * record["probability_se"] + 0.01)
    assert record["f_r_khz_p05"] == pytest.approx(25.0, abs=0.05)
    assert {c["h_i_mm"] for c in record["candidates"]} == {0.75, 1.0} and record["h_i_mm"] in (0.75, 1.0)
    best = max((c for c in record["candidates"] if c["separated"]), key=lambda c: c["w_dyn_um"])
    assert best["h_i_mm"] == record["h_i_mm"]

    from workflow.pipeline.calibration_files import load_calibration

    calibration = load_calibration(tmp_path / "cal")
    design = P1.with_(wavelength=record["lambda_mm"] * MM, resonator_thickness=record["h_i_mm"] * MM)
    draws = scattered_draws(calibration, design, Tolerances(), 12, seed=5)
    names = robust_inputs(calibration)  # columns: ln lambda, these parameters, h_p offset, discrepancy of ln f and ln w
    k = len(names)
    plates = [deviated_plate(design.with_(wavelength=design.wavelength * np.exp(d[0]),
                                          ceramic_thickness=design.ceramic_thickness + d[1 + k]), names, d[1 : 1 + k])
              for d in draws]
    frequencies = np.array([r.frequency for r in coarse_model.evaluate_plates(plates)]) * np.exp(draws[:, 2 + k])
    assert np.sum(frequencies >= 25e3) >= 10, frequencies  # P(at most 9 of 12 | p = 0.95) = 2 %


@pytest.mark.slow
def test_maps_with_a_calibration_scale_and_state_it(tmp_path, capsys, coarse_cli, coarse_model):
    _calibrate_on_p1(tmp_path, capsys, coarse_model)
    assert main(["maps", "--model", "fem", "--hp-mm", "1", "--grid", "2", "--out", str(tmp_path / "maps"),
                 "--calibration", str(tmp_path / "cal"), "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    correction = record["calibration"]
    assert correction["frequency_factor"] < 1 and "scaled" in correction["statement"]
    assert correction["optimum_f_r_khz_p05"] <= record["optimum"]["f_r_khz"] <= correction["optimum_f_r_khz_p95"]


def test_robust_candidate_meets_the_reliability_on_a_known_model():
    """With the beam model as 'FEM' (fast, exact surrogate inputs), the solved lambda puts the 5 % quantile of f_r
    on 25 kHz, the fresh-draw probability is 0.95 within its Monte Carlo error, and a transverse mode 2 % away
    is flagged."""
    from workflow.optimise.robust import RobustSettings, robust_candidate

    calibration = beam_calibration(3000)
    candidate = robust_candidate(calibration, P1, RobustSettings(), BEAM_FEM, 54.0)
    assert candidate.frequency[0] == pytest.approx(25e3, rel=2e-3)
    assert candidate.probability >= 0.95 - candidate.probability_error, "the solve is conservative by its own MC error"
    assert candidate.probability < 0.95 + 6 * candidate.probability_error, "but not wastefully so"
    assert candidate.margin == pytest.approx(candidate.frequency[0] - 25e3)
    assert not candidate.separated and candidate.nearest_transverse["relative_distance"] == pytest.approx(0.02)
    assert candidate.homogeneity == pytest.approx(0.0, abs=1e-12) and not candidate.lambda_at_edge


class _CosineSurface:
    """A stand-in for the top-face modes: a cosine along x whose wavelength follows the plate's."""

    def __init__(self, plate):
        self.wavelength = float(plate.wavelength)

    def deflection(self, x, y, frequency, q):
        return np.cos(2 * np.pi * x / self.wavelength) * (1 + 0.1 * y / 0.02) + 0j


def test_prior_surrogates_evaluate_all_plates_in_one_batch_per_kind_each_surrogate_as_if_alone():
    from workflow.calibration.calibration import prior_surrogates
    from workflow.calibration.measurements import ScanShape

    settings = replace(default_settings(), surrogate_points=18)
    scan = ScanShape((0.0, 0.004, 0.008), (0.0, 0.0, 0.01), (1.0, 0.5, -0.3), 0.03, None, "scan")
    calls = []

    def evaluate(plates):
        calls.append(("fem", len(plates)))
        return [BeamResult(p) for p in plates]

    def evaluate_surfaces(plates):
        calls.append(("surfaces", len(plates)))
        return [BeamResult(p) for p in plates], [_CosineSurface(p) for p in plates]

    plates, scans = (P1, P2, P1.with_(width=40 * MM)), (None, scan, None)
    surrogates = prior_surrogates(plates, settings, DesignFem(evaluate, evaluate_surfaces), scans)
    assert calls == [("fem", 36), ("surfaces", 18)]
    for plate, found, shape in zip(plates, surrogates, scans):
        points = None if shape is None else (np.array(shape.x), np.array(shape.y))
        stand_in = DesignFem(lambda ps: [BeamResult(p) for p in ps],
                             lambda ps: ([BeamResult(p) for p in ps], [_CosineSurface(p) for p in ps]))
        alone = build_plate_surrogate(plate, settings.names, settings.bounds, stand_in, 18, settings.surrogate_degree,
                                      settings.surrogate_seed, points)
        assert found == alone and (found.shape is None) == (shape is None)


def test_robust_design_evaluates_every_stock_in_two_batches_with_the_candidates_of_one_stock_each():
    """All stocks' surrogate designs go to the FEM in one batch and their median checks in a second (a pool's
    workers stay busy across the stocks); each candidate is the one its stock gives alone."""
    from workflow.optimise.robust import RobustSettings, robust_candidate, robust_design

    calibration = beam_calibration(500)
    batches = []

    def evaluate(plates):
        batches.append(len(plates))
        return [BeamResult(p) for p in plates]

    stock = (0.5e-3, 0.75e-3, 1e-3)
    design = robust_design(calibration, P1, stock, RobustSettings(separation=0.01), DesignFem(evaluate), 54.0)
    per_stock = design.candidates[0].evaluations - 1
    assert batches == [3 * per_stock, 3]
    for h, candidate in zip(stock, design.candidates):
        alone = robust_candidate(calibration, P1.with_(resonator_thickness=h), RobustSettings(separation=0.01),
                                 BEAM_FEM, 54.0)
        assert candidate == alone


def test_run_step_predicts_the_recommended_designs_with_the_calibration(tmp_path, coarse_cli, coarse_model):
    """``tactile run --calibration``: the step's predictions and the report section that states them."""
    from types import SimpleNamespace

    from workflow.pipeline.calibration_files import write_calibration
    from workflow.pipeline.config import default_config
    from workflow.pipeline.report import _calibrated_designs
    from workflow.pipeline.runner import RunResults
    from workflow.pipeline.steps import calibrated_designs

    plate = MeasuredPlate("P1", P1, built_plate_frequency(coarse_model, P1))
    calibration = calibrate([plate], SHORT, coarse_model.design_fem(), {**FEM_RECORD, "accuracy": 0.05})
    files = write_calibration(calibration, tmp_path, figures=False)
    designs = {1e-3: SimpleNamespace(plate=P1, frequency=25.1e3)}
    context = SimpleNamespace(calibration=Path(files["calibration"]), config=default_config(), cache=None, scheduler=None,
                              results=RunResults(recommended_design=SimpleNamespace(designs=designs)))
    predicted = calibrated_designs(context)[1e-3]
    low, median, high = predicted.frequency
    assert low <= plate.frequency <= high
    section = _calibrated_designs(context, {1e-3: predicted})
    assert "as the calibration predicts them" in section and str(context.calibration) in section
    assert f"| 1 | 25.100 | {median / KHZ:.3f} ({low / KHZ:.3f} to {high / KHZ:.3f}) |" in section
    assert calibrated_designs(SimpleNamespace(calibration=None)) == {}


def test_a_resonance_search_log_gives_its_fine_sweeps_peak(tmp_path):
    """The coarse sweep of a resonance search (wide spacing, peak off by up to a step) does not bias f_r."""
    header = "# lambda_mm: 20.56\n# h_i_mm: 0.75\n# h_p_mm: 1.0\n# b_mm: 49\nfrequency_hz,drive_voltage_v,velocity_m_s,sweep\n"
    rows = []
    for sweep, (start, stop, n) in enumerate(((22000.0, 24000.0, 11), (22900.0, 23200.0, 61))):
        for f in np.linspace(start, stop, n):
            rows.append(f"{f},5,{0.1 / (1 + ((f - 23057.0) / 60.0) ** 2)},{sweep}")
    path = tmp_path / "search.csv"
    path.write_text(header + "\n".join(rows) + "\n")
    log = read_built_plate(path)
    assert len(log.sweep_frequencies) == 2
    assert log.frequency == pytest.approx(23057.0, abs=2.0)
    assert abs(log.sweep_frequencies[0] - 23057.0) > abs(log.frequency - 23057.0)
