"""Amplitude-dependent damping: Q(v) laws, the self-consistent harmonic solve, the fit."""
