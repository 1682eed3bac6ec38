"""Logs of the two plates built and measured in the source paper (P1, P2; docs/calibration.md), read as package data."""
