"""Shared pytest configuration: figures render off-screen; Hypothesis profiles.

Hypothesis profiles (tests/test_fuzz.py): ``default`` runs a few dozen examples per property
(a few seconds in all); ``long`` runs thousands, for the tests marked ``slow`` or for every
property with ``HYPOTHESIS_PROFILE=long``.
"""

import os

import matplotlib
from hypothesis import HealthCheck, settings

matplotlib.use("Agg")

settings.register_profile("default", max_examples=40, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=3000, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
