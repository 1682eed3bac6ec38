"""What the calibration tests share: a coarse mesh, the published plates' geometry, the hidden deviations of the
simulated built plates and fast sampler settings (the fixtures built on them are in conftest.py)."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from workflow.calibration.calibration import Calibration, MeasuredPlate
from workflow.calibration.parameters import default_settings
from workflow.calibration.plate_surrogate import DesignFem, build_plate_surrogate
from workflow.models import analytical
from workflow.models.fem import FemSettings
from workflow.models.plate import Plate

COARSE = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=2, n_modes=3)
"""A coarse mesh (0.4 s an evaluation): the tests check the machinery, not the physics' last per cent."""
P1 = Plate(20.56e-3, 0.75e-3, 1.0e-3, 49e-3)
P2 = Plate(15.66e-3, 0.5e-3, 0.5e-3, 49e-3)
TRUTH = np.array([0.93, 1.04, 30e-6, -15e-6])
"""Hidden deviations of the simulated built plates: ceramic and resonator factors, glue [m], h_i offset [m]."""
FAST = replace(default_settings(), surrogate_points=18)
"""Calibration settings with a small surrogate design (the chain stops once converged, as by default: ~4000 steps)."""
SHORT = replace(FAST, steps=600)
"""FAST with a chain too short to count as converged (a 600-step cap, ~16 tau), for the tests that do not ask for one:
their assertions (intervals holding the measurements, the constrained directions, the case study's errors, the model
discrepancy's check) hold on sampler seeds 2-6 with the same margins as at 2000 steps (measured)."""
SHORT_CONFIG = "[sampler]\nsteps = 600\n[surrogate]\npoints = 18\n"
"""SHORT as a ``tactile calibrate --config`` file."""
FEM_RECORD = {"q": 54.0, "voltage_v": 15.0, "accuracy": 0.01, "piezo": "eigenstrain"}
"""The FEM conditions a calibration records (what ``tactile calibrate`` binds)."""


class BeamResult:
    """A stand-in for an FEM result from the beam model: one longitudinal mode, uniform probes."""

    def __init__(self, plate):
        self.frequency = float(analytical.resonance_frequency(plate))
        self.deflection = float(analytical.dynamic_deflection(plate, 15.0, 54.0))
        self.error, self.best_index, self.q, self.voltage = None, 0, 54.0, 15.0
        self.modes = (SimpleNamespace(frequency=self.frequency, transverse_indicator=0.0),
                      SimpleNamespace(frequency=1.02 * self.frequency, transverse_indicator=0.9))
        self.probe_model = SimpleNamespace(response=lambda f, q: np.full(44, self.deflection))


BEAM_FEM = DesignFem(lambda plates: [BeamResult(p) for p in plates])
"""Surrogate designs evaluated with the beam stand-in, every point alike."""


def beam_calibration(n_samples: int) -> Calibration:
    """A calibration on P1 with the beam model as 'FEM' and a made-up posterior of ``n_samples`` samples."""
    settings = default_settings()
    rng = np.random.default_rng(0)
    samples = np.column_stack([rng.normal(0.95, 0.02, n_samples), rng.normal(0.97, 0.02, n_samples),
                               rng.uniform(20e-6, 40e-6, n_samples), rng.normal(-10e-6, 5e-6, n_samples)])
    surrogate = build_plate_surrogate(P1, settings.names, settings.bounds, BEAM_FEM, 20, 2, 1)
    return Calibration(settings, samples, (MeasuredPlate("P1", P1, 23.2e3),), (surrogate,), None, {})
