"""The recommended design that holds when built (issue 29, point 5): the calibration on the built plates, the robust
design per h_p beside the nominal optimum, the report's first table, and the run's options for it.

The FEM is stood in for by the beam model (:class:`calibration_setup.BeamResult`: one longitudinal mode and a
transverse one 2 % above it), so that the machinery is checked in seconds; the run's own figures are in
docs/calibration.md."""

import re
import shutil
import types
from dataclasses import replace
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from calibration_setup import P1, SHORT, BeamResult, beam_calibration
from user_facing import run_cli

from workflow.calibration import parameters
from workflow.calibration.plate_surrogate import DesignFem
from workflow.execution.cache import EvaluationCache
from workflow.models.response import ScaledResponse
from workflow.optimise.problem import DesignProblem
from workflow.optimise.robust import RobustSettings, beam_wavelength, robust_candidates
from workflow.pipeline import loop
from workflow.pipeline import robust_recommendation as robust
from workflow.pipeline.config import default_config, merge
from workflow.errors import InputFileError
from workflow.pipeline.robust_report import robust_section
from workflow.pipeline.runner import RunContext
from workflow.units import KHZ, MM

def on_the_limit(plate):
    """The plate with the wavelength that puts its beam model on 25 kHz."""
    return plate.with_(wavelength=beam_wavelength(plate, 25 * KHZ))


NOMINAL = on_the_limit(P1)
"""A nominal optimum on the 25 kHz limit (the beam model as its FEM)."""
SEPARATED = RobustSettings(separation=0.01)
"""The stand-in's transverse mode sits 2 % above the working one: separated at 1 %, not at the default 3 %."""


def beam_evaluate(batches: list) -> DesignFem:
    def evaluate(plates):
        batches.append(len(plates))
        return [BeamResult(p) for p in plates]
    return DesignFem(evaluate)


def test_the_stocks_tried_are_those_nearest_the_nominal_thickness():
    stock = [t * MM for t in robust.STOCK_HI_MM]
    assert robust.nearest_stocks(0.916 * MM, stock, 2) == [0.8 * MM, 1.0 * MM]
    assert robust.nearest_stocks(0.5 * MM, stock, 2) == [0.5 * MM, 0.6 * MM]
    assert robust.nearest_stocks(1.9 * MM, stock, 3) == [1.5 * MM, 2.0 * MM, 2.5 * MM]
    assert robust.nearest_stocks(2.29 * MM, stock, 2) == [2.0 * MM, 2.5 * MM]


def test_robust_choices_batch_every_hp_and_check_the_nominal_at_its_own_wavelength():
    """Under a calibration that lowers f_r (factors 0.95 and 0.97), the nominal optimum on the limit would mostly
    miss it; the robust design at the same stock shortens λ until P(f_r >= 25 kHz) reaches the reliability."""
    calibration = beam_calibration(800)
    batches = []
    nominals = {1 * MM: NOMINAL, 2 * MM: on_the_limit(P1.with_(ceramic_thickness=2 * MM))}
    stock = [t * MM for t in robust.STOCK_HI_MM]
    choices = robust.robust_choices(calibration, nominals, stock, 2, SEPARATED, beam_evaluate(batches), 54.0)
    per_candidate = choices[1 * MM].nominal.evaluations - 1
    assert batches == [2 * 3 * per_candidate, 2 * 3], "one batch of surrogates, one of median checks, for every h_p"
    for hp, choice in choices.items():
        assert [float(c.plate.resonator_thickness) for c in choice.candidates] == [0.75 * MM, 0.8 * MM]
        assert choice.nominal.plate == nominals[hp] and not choice.nominal.lambda_at_edge
        assert choice.nominal.probability < 0.5 and choice.nominal.frequency[1] < 25 * KHZ
        assert choice.best is not None and choice.reason is None
        assert choice.best.probability >= SEPARATED.reliability - choice.best.probability_error
        assert choice.best.frequency[0] == pytest.approx(25 * KHZ, rel=2e-3)
        same_stock = choice.candidates[0]
        assert float(same_stock.plate.wavelength) < float(nominals[hp].wavelength)
    alone = robust_candidates(calibration, [NOMINAL], SEPARATED, beam_evaluate([]), 54.0, [False])[0]
    assert alone == choices[1 * MM].nominal, "each check as if alone"


def test_an_hp_without_a_robust_design_says_why_and_keeps_its_nominal_check():
    calibration = beam_calibration(300)
    choices = robust.robust_choices(calibration, {1 * MM: NOMINAL}, [0.75 * MM, 1 * MM], 2, RobustSettings(),
                                    beam_evaluate([]), 54.0)
    choice = choices[1 * MM]
    assert choice.best is None and "no stock thickness gives a robust design" in choice.reason
    assert choice.nominal.plate == NOMINAL and len(choice.candidates) == 2


@pytest.fixture
def beam_run(tmp_path, monkeypatch):
    """A run context whose calibration model is the beam stand-in and whose sampler is short; a copy of the published
    P1 log is the user's own built plate."""
    own = tmp_path / "my_plate.csv"
    with resources.as_file(resources.files("workflow.calibration.published") / "paper_P1.csv") as path:
        shutil.copy(path, own)
    batches = []
    fem = beam_evaluate(batches)
    model = types.SimpleNamespace(design_fem=lambda: fem)
    monkeypatch.setattr(loop, "calibration_model", lambda context: (model, {}))
    monkeypatch.setattr(parameters, "load_settings", lambda *args: SHORT)
    config = default_config()
    config["recommendation"].update(built_plates=[str(own)], stock_hi_mm=[0.75, 1.0])
    run = RunContext(config=config, out=tmp_path / "run", cache=EvaluationCache(tmp_path / "cache"))
    run.results.recommended_design = types.SimpleNamespace(designs={1 * MM: types.SimpleNamespace(plate=NOMINAL, model="fem")})
    return run, batches


def test_the_run_calibrates_on_the_published_and_the_users_plates_and_the_case_study_reuses_them(beam_run):
    run, batches = beam_run
    built = robust.built_calibration(run)
    assert built.names == ("P1", "P2", "my_plate.csv") and len(built.calibration.plates) == 3
    assert batches == [3 * SHORT.surrogate_points], "the three plates' surrogates in one batch"
    run.results.built_calibration = built
    run.step = "built_calibration"
    robust.built_calibration_files(run, built)
    assert (run.out / "calibration" / "calibration.json").is_file()
    assert run.figures_of("built_calibration")[0].name == "calibration/calibration_pairs.png"
    directions = loop.case_study(run)
    assert batches == [3 * SHORT.surrogate_points], "the case study evaluates nothing more"
    assert [d.calibrated_on for d in directions] == ["P1", "P2"]


def test_robust_step_without_a_separated_stock_and_without_built_plates(beam_run):
    run, _ = beam_run
    run.config["recommendation"].update(built_plates=[], published_plates=False)
    assert robust.built_calibration(run) is None, "no built plate: no calibration"
    run.results.built_calibration = robust.BuiltCalibration(beam_calibration(300))
    recommendation = robust.robust_recommendation(run)
    (choice,) = recommendation.choices.values()
    assert choice.best is None, "the stand-in's transverse mode is 2 % away: not separated at the default 3 %"
    assert [float(c.plate.resonator_thickness) for c in choice.candidates] == [0.75 * MM, 1.0 * MM]
    text = robust_section(run, recommendation)
    assert text.startswith("## What to build") and "**No h_p has a design to build**" in text
    assert "| 1 | robust: **none** |" in text and "No robust design: h_p = 1 mm: no stock thickness" in text
    assert "| 1 | nominal FEM optimum | " in text
    assert "The calibration (`calibration/calibration.json`): " in text, "the posterior-predictive check stated"


def test_the_first_table_recommends_the_robust_row_and_shows_the_nominal_one_below_it(beam_run):
    run, _ = beam_run
    choices = robust.robust_choices(beam_calibration(800), {1 * MM: NOMINAL}, [0.75 * MM, 1 * MM], 2, SEPARATED,
                                    beam_evaluate([]), 54.0)
    recommendation = robust.RobustRecommendation(choices, ("P1", "P2"), RobustSettings(), 54.0)
    text = robust_section(run, recommendation)
    rows = [line for line in text.splitlines() if line.startswith("| 1 |")]
    best = choices[1 * MM].best
    assert rows[0].startswith(f"| 1 | robust (stock h_i of 2 tried) | {float(best.plate.wavelength) / MM:.3f} | "
                              f"{float(best.plate.resonator_thickness) / MM:.3f} |")
    assert f"| {best.probability:.3f} ± {best.probability_error:.1g} |" in rows[0] and "**build this**" in rows[0]
    assert rows[1].startswith(f"| 1 | nominal FEM optimum | {float(NOMINAL.wavelength) / MM:.3f} | 0.750 |")
    assert "**likely below 25 kHz: P 0." in rows[1] and "| – |" in rows[1], "no Q(v) column without a fit"
    assert "on the measured built plates (P1, P2)" in text and "Build: h_p = 1 mm from the robust rows." in text
    assert "What these bands contain" in text and "constant Q = 54" in text
    assert f"{recommendation.evaluations} FEM evaluations" in text
    assert recommendation.evaluations == 3 * choices[1 * MM].nominal.evaluations


def test_recommendation_settings_are_checked_like_the_others():
    config = default_config()
    assert config["recommendation"]["robust"] and config["recommendation"]["published_plates"]
    for text, message in (({"reliability": 1.5}, "'recommendation.reliability' = 1.5 is outside"),
                          ({"stock_hi_mm": []}, "'recommendation.stock_hi_mm' is empty"),
                          ({"built_plates": [3]}, "'recommendation.built_plates[0]' must be a string")):
        with pytest.raises(InputFileError, match=re.escape(message)):
            merge(config, {"recommendation": text})


def test_a_bad_built_plate_log_fails_the_run_before_any_step(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("frequency_hz,velocity\n1,2\n", encoding="utf-8")
    status, _, err = run_cli(capsys, "run", "--built-plates", bad, "--out", tmp_path / "out")
    assert status != 0 and len(err.strip().splitlines()) == 1 and "bad.csv" in err, err
    assert not (tmp_path / "out" / "report.md").exists()


def test_a_robust_design_that_misses_the_deflection_with_q_of_v_is_not_recommended(beam_run):
    """The verdict weighs the target deflection too: a robust design whose voltage for 1.15 µm with Q(v) exceeds the
    design voltage says so instead of "build this", and the opening sentence leaves it out."""
    run, _ = beam_run
    choices = robust.robust_choices(beam_calibration(300), {1 * MM: NOMINAL}, [0.75 * MM, 1 * MM], 2, SEPARATED,
                                    beam_evaluate([]), 54.0)
    weak = types.SimpleNamespace(reaches_target=False, target=1.15e-6, problem=types.SimpleNamespace(voltage=15.0),
                                 required_voltage=(19.0, 21.04, 24.0))
    strong = types.SimpleNamespace(reaches_target=True, required_voltage=(5.0, 6.0, 7.0))
    choice = choices[1 * MM]
    for damped, verdict, opening in ((weak, "**misses 1.15 µm at 15 V: needs 21.0 V with Q(v)**", "**No h_p has"),
                                     (strong, "**build this**", "Build: h_p = 1 mm")):
        recommendation = robust.RobustRecommendation({1 * MM: replace(choice, best_damped=damped, nominal_damped=weak)},
                                                     ("P1",), RobustSettings(), 54.0)
        text = robust_section(run, recommendation)
        rows = [line for line in text.splitlines() if line.startswith("| 1 |")]
        assert rows[0].endswith(f"| {verdict} |") and opening in text
        assert f"| {damped.required_voltage[1]:.1f} [{damped.required_voltage[0]:.1f}, " in rows[0]
        assert "misses 1.15 µm at 15 V" in rows[1] and "likely below 25 kHz" in rows[1]


def test_the_q_of_v_columns_come_from_the_fem_at_each_rows_posterior_median_plate(beam_run, coarse_model):
    """With the coarse FEM as the model: each row's Q(v) numbers are those of the recommended-design code at the FEM
    result of its posterior-median plate (the robust row's solved λ, the nominal row's own), and the voltage for the
    target inverts the self-consistent deflection there."""
    from workflow.damping.posterior import DampingPosterior
    from workflow.optimise.damped import damped_deflection
    from workflow.pipeline.recommendation import fem_recommendation

    run, _ = beam_run
    rng = np.random.default_rng(0)
    posterior = DampingPosterior("quadratic", {"q0": rng.normal(150, 3, 40), "alpha": rng.normal(0.25, 0.005, 40)})
    run.results.damping_fit = types.SimpleNamespace(answer=posterior)
    run.config["damping"]["posterior_draws"] = 8
    with_damping = robust.damped_evaluation(run)
    choices = robust.robust_choices(beam_calibration(300), {1 * MM: NOMINAL}, [0.75 * MM], 1,
                                    RobustSettings(separation=0.0), coarse_model.design_fem(), 54.0, with_damping)
    choice = choices[1 * MM]
    draws = posterior.draws(8, run.config["damping"]["seed"])
    for candidate, damped in ((choice.best, choice.best_damped), (choice.nominal, choice.nominal_damped)):
        assert candidate.working.frequency > 0 and damped.plate == candidate.plate
        expected = fem_recommendation(candidate.working, candidate.plate, DesignProblem(1 * MM), draws, 1.15e-6)
        assert damped.required_voltage == pytest.approx(expected.required_voltage, rel=1e-12)
        w = damped_deflection(ScaledResponse(candidate.working, damped.required_voltage[1] / candidate.working.voltage),
                              posterior.median_law())
        assert float(w) == pytest.approx(1.15e-6, rel=0.02), "the median voltage gives about the target"


def test_a_cached_step_is_keyed_by_the_built_plates_contents(beam_run):
    """The calibration on the built plates is cached: its key changes with the bytes of a --built-plates log, not only
    with its path (an edited log is calibrated again)."""
    from workflow.pipeline.runner import _step_key
    from workflow.pipeline.steps import STEPS

    run, _ = beam_run
    (step,) = [s for s in STEPS if s.key == "built_calibration"]
    assert step.cacheable
    before = _step_key(run, step)
    own = Path(run.config["recommendation"]["built_plates"][0])
    own.write_text(own.read_text(encoding="utf-8") + "\n", encoding="utf-8")
    assert _step_key(run, step) != before


def test_the_nominal_verdict_weighs_the_mode_separation_like_the_robust_rows(beam_run):
    """A nominal plate whose frequency clears the limit but with a transverse mode nearer than the separation is not
    "robust as it is" (the stand-in's transverse mode is 2 % away; the default separation 3 %)."""
    run, _ = beam_run
    clear = NOMINAL.with_(wavelength=0.9 * float(NOMINAL.wavelength))  # f_r well above 25 kHz: P = 1
    choices = robust.robust_choices(beam_calibration(300), {1 * MM: clear}, [0.75 * MM], 1, RobustSettings(),
                                    beam_evaluate([]), 54.0, sources={1 * MM: "beam model"})
    recommendation = robust.RobustRecommendation(choices, ("P1",), RobustSettings(), 54.0)
    (nominal_row,) = [line for line in robust_section(run, recommendation).splitlines()
                      if line.startswith("| 1 | nominal beam model optimum |")]
    assert choices[1 * MM].nominal.probability == 1.0
    assert nominal_row.endswith("| **a transverse mode 2.0 % away (< 3 %)** |")


def test_the_robust_design_keeps_to_the_runs_design_space(beam_run):
    """λ outside the configured range is no robust design; a stock the beam model cannot bring to the limit at any
    wavelength is reported, not fatal."""
    calibration = beam_calibration(300)
    narrow = robust.robust_choices(calibration, {1 * MM: NOMINAL}, [0.75 * MM], 1, SEPARATED, beam_evaluate([]), 54.0,
                                   wavelength_range=(15 * MM, 16 * MM))
    assert narrow[1 * MM].best is None and "lambda inside its range" in narrow[1 * MM].reason
    unreachable = RobustSettings(separation=0.01, min_frequency=1e6)  # no wavelength puts the beam at 1 MHz
    choices = robust.robust_choices(calibration, {1 * MM: NOMINAL}, [0.75 * MM], 1, unreachable, beam_evaluate([]), 54.0)
    assert choices[1 * MM].best is None and choices[1 * MM].candidates == ()
    assert choices[1 * MM].reason.startswith("h_i 0.75 mm: no wavelength gives")


def test_built_plates_are_not_read_when_the_robust_recommendation_is_off(beam_run, tmp_path, capsys):
    run, _ = beam_run
    config = dict(run.config, recommendation={**run.config["recommendation"], "robust": False,
                                               "built_plates": [str(tmp_path / "missing.csv")]})
    assert robust.own_plates(config) == []
    toml = tmp_path / "off.toml"
    toml.write_text("[recommendation]\nrobust = false\n", encoding="utf-8")
    status, _, err = run_cli(capsys, "run", "--config", toml, "--built-plates", tmp_path / "missing.csv",
                             "--print-config")
    assert status == 0 and "warning: --built-plates is not used" in err
