"""What the calibration tests share: a coarse mesh, the published plates' geometry, the hidden deviations of the
simulated built plates and fast sampler settings (the fixtures built on them are in conftest.py)."""

from dataclasses import replace

import numpy as np

from workflow.calibration.parameters import default_settings
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
