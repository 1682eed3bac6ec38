"""Seeded small versions of issue 29's coverage studies (bench/bench_damping_coverage.py and
bench/bench_calibration_coverage.py): a few hidden truths each, short chains and a coarse mesh.

The chains are far shorter than the studies' (400 steps a law, 600 a calibration): the assertions hold with wide margins
at those lengths on the fit's own seed and on four other sampler seeds (measured; see each test)."""

import importlib.util
from dataclasses import replace

import numpy as np
from calibration_setup import COARSE, FAST
from paths import BENCH



def bench_module(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_damping_study_the_threshold_truth_of_issue_29_is_inside_its_band_and_its_softening_found():
    """Truth 1 of the study's seed: a threshold whose onset width (0.19 of v_t) is not the old fixed 0.2 ... with
    softening (kappa 0.081) and drift (-0.13 Hz/s) on the bench simulator, whose plate heats as it is driven, fitted
    with the default options."""
    study = bench_module("bench_damping_coverage")
    truth = study.truths(2, 2029)[1]
    assert truth.law.name == "threshold" and truth.softening > 0 and truth.drift_rate != 0
    # 1500 steps: with the heating fitted too, 400 left the chains short of the softening's and the heating's joint
    # posterior (kappa [0.026, 0.110], a band 27 % wide). At 1500, on fit seeds 0-2: coverage 1.0, width 0.04-0.08,
    # kappa's 90 % interval about [0.078, 0.087] around the truth 0.0808, 36-41 s
    record = study.study_truth(truth, max_steps=1500)
    assert record["coverage"] >= 0.7 and record["width"] < 0.10, record
    softening = record["effects"]["softening"]
    assert softening["fitted"] and softening["detected"]
    assert record["kappa"]["p05"] <= truth.softening <= record["kappa"]["p95"]
    assert record["effects"]["drift"]["fitted"]
    assert record["effects"]["heating"]["fitted"] and record["effects"]["heating"]["detected"]  # the bench's plate heats
    summary = study.summarise([record])
    assert summary["softening"] == {"campaigns_carrying_it": 1, "fitted_when_carried": 1, "fitted_when_absent": 0,
                                    "detected_when_carried": 1, "detected_when_absent": 0}
    assert summary["heating"]["detected_when_carried"] == 1


def test_calibration_study_on_a_coarse_mesh(monkeypatch, calibration_cache_dir):
    """One campaign of three built plates with deviations beyond the parameters, on the coarse mesh: calibrated on
    two, the third's measured resonance lies in the predictive band, which the discrepancy term widens."""
    monkeypatch.setenv("TACTILE_CACHE", str(calibration_cache_dir))
    study = bench_module("bench_calibration_coverage")
    # 600 steps (FAST's 2000 are for its converged chains; nothing here asks for that): on sampler seeds 2-6 the band
    # without the term is [27.19, 27.78] kHz and with it [25.95, 27.71] kHz about C's 26.71 kHz, widths 1.9 % and 6.1 %
    settings = replace(FAST, steps=600, kept_samples=2000)
    runs = {kind: study.study(1, 2029, COARSE, COARSE, settings, discrepancy=kind, scheduler="synchronous")
            for kind in (False, True)}
    (before,), (after,) = (runs[kind]["records"] for kind in (False, True))
    assert after["deviations"] == before["deviations"] and after["measured_f_hz"] == before["measured_f_hz"]
    # seed 2029's campaign: P1 and B calibrate, C is predicted; a bond partly cured (0.57) and varying from ceramic
    # to ceramic, width and ceramic-length errors; without the term the band (1.8 %) misses C by 3 %
    assert not before["inside"] and after["inside"], (before, after)
    assert after["width"] > 2 * before["width"]
    assert before["check"]["discrepancy"] == {} and "frequency" in after["check"]["discrepancy"]
    assert np.all(np.array(after["discrepancy_median"]) > 0)
