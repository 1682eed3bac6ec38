"""Two-level surrogate designs (issue 27, item 3): every design point on one coarse mesh level, two anchors to the
accuracy, the coarse values moved by the anchors' mean difference.

The machinery is checked on stand-ins whose coarse level has a known error; the physics (the two-level surrogate
against fresh accurate FEM evaluations, beside the surrogate whose every point is accurate) in a slow test and in
``bench/bench_two_level.py`` (docs/calibration.md, "Two-level designs")."""

import json
import time
from types import SimpleNamespace

import numpy as np
import pytest
from calibration_setup import P1, P2, BeamResult

from workflow.calibration.calibration import prediction_points
from workflow.calibration.parameters import default_settings, deviated_plate
from workflow.calibration.plate_surrogate import (
    ANCHORS,
    DesignFem,
    PlateSurrogate,
    anchor_indices,
    build_plate_surrogate,
    point_deflection_per_volt,
    surrogate_design,
)
from workflow.calibration.surrogate import latin_hypercube
from workflow.errors import TactileError
from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.accuracy import FemAccuracy, FemLevel, mesh_for_level
from workflow.optimise.fem_model import FemModel

SETTINGS = default_settings()


class CoarseResult(BeamResult):
    """The beam stand-in with a coarse level's errors that differ between the outputs and vary with the bond: f_r
    ``e`` high, w ``3 e + 0.2 %`` high and the centre's deflection g ``0.5 %`` low, e = 0.1 % + 0.1 % bond/60 um."""

    def __init__(self, plate):
        super().__init__(plate)
        excess = 1e-3 + 1e-3 * float(plate.glue_thickness) / 60e-6
        self.frequency *= 1 + excess
        self.deflection *= 1 + 3 * excess + 2e-3
        g = BeamResult(plate).deflection * (1 - 5e-3)
        self.probe_model = SimpleNamespace(response=lambda f, q: np.full(44, g))


class FlippingSurface:
    """Top-face modes whose pattern is a cosine along x, varying across the width with the bond, of the sign ``sign``
    (an eigenvector's is arbitrary), distorted by ``distortion`` (a coarse level's error) along x."""

    def __init__(self, plate, sign, distortion=0.0):
        self.wavelength, self.bond = float(plate.wavelength), float(plate.glue_thickness)
        self.sign, self.distortion = sign, distortion

    def deflection(self, x, y, frequency, q):
        across = 1 + (0.1 + 0.5 * self.bond / 60e-6) * y / 0.02
        shape = np.cos(2 * np.pi * x / self.wavelength) * across * (1 + self.distortion * x / 0.01)
        return self.sign * shape + 0j


def counting(results, calls, label):
    def evaluate(plates):
        calls.append((label, len(plates)))
        return [results(p) for p in plates]
    return evaluate


def test_a_level_is_each_plates_own_mesh_of_that_degree():
    level = FemLevel(2, n_modes=3)
    mesh = mesh_for_level(P2, 2, 3)
    assert level.resolved(P2, None) == (mesh, None) and not level.refines
    assert evaluate_fem(P2, 54.0, 15.0, level).frequency == evaluate_fem(P2, 54.0, 15.0, mesh).frequency
    assert level.as_dict() == {"kind": "level", "level": 2, "n_modes": 3, "piezo": "eigenstrain"}
    with pytest.raises(TactileError, match="level must be one of"):
        FemLevel(7)
    with pytest.raises(TactileError, match="piezo"):
        FemLevel(3, piezo="quantum")


def test_an_fem_model_designs_on_two_levels_only_below_the_coarse_levels_accuracy():
    assert FemModel(settings=FemAccuracy(2e-3)).design_fem().coarse_level == 3
    assert FemModel(settings=FemAccuracy(2e-3, piezo="coupled")).design_fem().coarse is not None
    assert FemModel(settings=FemAccuracy(1e-2)).design_fem().coarse is None, "its own evaluations end on level 3"
    assert FemModel(settings=FemSettings()).design_fem().coarse is None


def test_the_anchors_are_the_centre_and_the_point_farthest_from_it():
    points = latin_hypercube(12, SETTINGS.bounds, 3)
    unit = (points - SETTINGS.bounds[:, 0]) / np.ptp(SETTINGS.bounds, axis=1)
    anchors = anchor_indices(points, SETTINGS.bounds, 2)
    assert anchors[0] == 0 and anchors[1] == int(np.argmax(np.sum((unit - 0.5) ** 2, axis=1)))
    assert anchor_indices(points[:1], SETTINGS.bounds, 2) == [0]


def test_two_level_values_are_the_coarse_ones_moved_by_the_anchors_and_their_spread_is_an_error():
    """The stand-in's coarse level errs differently on f_r, w and g, varying with the bond: each output is moved by its
    own anchors' mean difference, so that the corrected values sit within the variation of the coarse error over the
    box; the spread of the two anchors' frequency corrections enters the error; the designs of two plates go to each
    level in one batch."""
    calls = []
    fem = DesignFem(counting(BeamResult, calls, "accurate"), None, counting(CoarseResult, calls, "coarse"), None, 3)
    n = 14
    designs = [surrogate_design(plate, SETTINGS.names, SETTINGS.bounds, n, 5) for plate in (P1, P2)]
    values = fem.values(designs)
    assert calls == [("coarse", 2 * n), ("accurate", 2 * ANCHORS)]
    outputs = {"log_frequency": lambda r: r.frequency, "log_deflection": lambda r: r.deflection,
               "log_point_deflection": point_deflection_per_volt}
    for design, found in zip(designs, values):
        anchors = anchor_indices(design.points, design.bounds, ANCHORS)
        for name, output in outputs.items():
            exact = np.log([output(BeamResult(p)) for p in design.plates])
            coarse = np.log([output(CoarseResult(p)) for p in design.plates])
            correction = np.mean((exact - coarse)[anchors])
            assert np.allclose(getattr(found, name), coarse + correction, atol=1e-12), name
            assert np.max(np.abs(getattr(found, name) - exact)) <= np.ptp(exact - coarse) + 1e-12, name
        corrections = np.log([BeamResult(design.plates[k]).frequency / CoarseResult(design.plates[k]).frequency
                              for k in anchors])
        assert found.fem_error == pytest.approx(np.std(corrections, ddof=1) * np.sqrt(1.5), rel=1e-9)
        assert found.fem_error > 1e-4 and found.evaluations == n + ANCHORS and found.coarse_level == 3


def test_two_level_patterns_follow_the_accurate_ones_whatever_the_signs_of_the_modes():
    """A scanned design whose coarse modes come with random signs and whose accurate ones all with one sign (each way
    round), the coarse level distorting the pattern by 3 % along x: the corrected patterns are the accurate ones up to
    one sign, to the distortion's variation over the box, far closer than the coarse patterns are."""
    rng = np.random.default_rng(4)
    results = lambda plates: [BeamResult(p) for p in plates]  # noqa: E731
    scan = (np.array([0.0, 0.003, 0.006, 0.009, 0.004]), np.array([0.0, 0.0, 0.01, 0.0, 0.02]))
    design = surrogate_design(P1, SETTINGS.names, SETTINGS.bounds, 16, 5, scan)
    every = DesignFem(results, lambda plates: (results(plates), [FlippingSurface(p, 1.0) for p in plates]))
    (reference,) = every.values([design])
    for accurate_sign in (1.0, -1.0):
        two = DesignFem(results, lambda plates: (results(plates), [FlippingSurface(p, accurate_sign) for p in plates]),
                        results, lambda plates: (results(plates), [FlippingSurface(p, rng.choice([-1.0, 1.0]), 0.03)
                                                                   for p in plates]), 3)
        (found,) = two.values([design])
        assert found.patterns.shape == reference.patterns.shape == (16, 5)
        sign = np.sign(np.sum(found.patterns[0] * reference.patterns[0]))
        coarse_miss = 0.03 * 0.009 / 0.01  # the distortion at the last scan point, before normalisation
        assert np.max(np.abs(sign * found.patterns - reference.patterns)) < 0.1 * coarse_miss, accurate_sign


def test_a_two_level_surrogate_keeps_its_coarse_level_through_json():
    fem = DesignFem(lambda plates: [BeamResult(p) for p in plates], None,
                    lambda plates: [CoarseResult(p) for p in plates], None, 3)
    surrogate = build_plate_surrogate(P1, SETTINGS.names, SETTINGS.bounds, fem, 18, 2, 1)
    assert surrogate.coarse_level == 3 and surrogate.evaluations == 18 + ANCHORS
    assert PlateSurrogate.from_dict(json.loads(json.dumps(surrogate.to_dict()))) == surrogate
    older = {key: value for key, value in surrogate.to_dict().items() if key != "coarse_level"}
    assert PlateSurrogate.from_dict(older).coarse_level is None


def test_without_a_coarse_level_every_point_is_accurate():
    calls = []
    fem = DesignFem(counting(BeamResult, calls, "accurate"))
    design = surrogate_design(P1, SETTINGS.names, SETTINGS.bounds, 12, 5)
    (found,) = fem.values([design])
    assert calls == [("accurate", 12)] and found.coarse_level is None and found.evaluations == 12
    assert np.allclose(found.log_frequency, np.log([BeamResult(p).frequency for p in design.plates]))


def test_a_scan_design_needs_the_top_face_modes():
    from workflow.calibration.plate_surrogate import SurrogateDesign

    design = surrogate_design(P1, SETTINGS.names, SETTINGS.bounds, 12, 5)
    scanned = SurrogateDesign(design.points, design.bounds, design.plates, (np.zeros(2), np.zeros(2)))
    with pytest.raises(ValueError, match="top-face modes"):
        DesignFem(lambda plates: [BeamResult(p) for p in plates]).values([scanned])


POSTERIOR_BOX = np.array([[0.93, 0.99], [0.94, 1.0], [20e-6, 40e-6], [-40e-6, -10e-6]])
"""A prediction surrogate's box: the posterior's central range of the four parameters (moduli factors, bond [m],
h_i offset [m]), about what the published plates give."""


@pytest.mark.slow
def test_two_level_prediction_surrogate_matches_the_all_accurate_one_on_fresh_fem_points():
    """P2's linear prediction surrogate over a posterior's box at 0.2 %: the two-level design's error at 4 fresh
    accurate points is within 0.05 % of the all-accurate design's and under 0.3 %, and it takes under 70 % of the time
    (evaluated first, so that the other design finds level 3's set-up done; measured: docs/calibration.md)."""
    accurate = FemModel(settings=FemAccuracy(2e-3, n_modes=4), scheduler="synchronous")
    names, n = SETTINGS.names, prediction_points(len(SETTINGS.names))
    times, surrogates = {}, {}
    for label, fem in (("two", accurate.design_fem()), ("all", DesignFem(accurate.evaluate_plates))):
        started = time.perf_counter()
        surrogates[label] = build_plate_surrogate(P2, names, POSTERIOR_BOX, fem, n, 1, 0)
        times[label] = time.perf_counter() - started
    fresh = latin_hypercube(5, POSTERIOR_BOX, 23)[1:]
    truth = np.log([r.frequency for r in accurate.evaluate_plates([deviated_plate(P2, names, t) for t in fresh])])
    errors = {label: float(np.sqrt(np.mean((s.log_frequency(fresh) - truth) ** 2))) for label, s in surrogates.items()}
    assert errors["two"] <= errors["all"] + 5e-4 and errors["two"] < 3e-3, errors
    assert times["two"] < 0.7 * times["all"], times
