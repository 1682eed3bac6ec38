"""Shared pytest configuration: figures render off-screen."""

import matplotlib

matplotlib.use("Agg")
