"""Calibration of the plate FEM to built plates: priors, surrogate, posterior (docs/calibration.md)."""
