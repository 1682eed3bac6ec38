"""Mesh-convergence study: the cost on uniformly refined meshes and Richardson extrapolation."""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from workflow.models.fem.evaluate import evaluate_fem
from workflow.models.fem.settings import FemSettings
from workflow.models.plate import Plate


@dataclass(frozen=True)
class ConvergenceStudy:
    """Frequency and deflection of the best mode on meshes refined by ``factors``.

    Attributes
    ----------
    factors : tuple of int
        Refinement factors of the base settings (element size h proportional to 1/factor).
    n_dofs : tuple of int
    frequencies : tuple of float
        [Hz].
    deflections : tuple of float
        [m].
    """

    factors: tuple
    n_dofs: tuple
    frequencies: tuple
    deflections: tuple

    def frequency_extrapolation(self):
        """(observed rate p, extrapolated frequency [Hz]) from the last three meshes."""
        return richardson(self.factors[-3:], self.frequencies[-3:])

    def deflection_extrapolation(self):
        """(observed rate p, extrapolated deflection [m]) from the last three meshes."""
        return richardson(self.factors[-3:], self.deflections[-3:])


def richardson(factors, values):
    """Observed convergence rate and extrapolated limit of values on three meshes, h ~ 1/factor.

    Solves (v1 - v2) / (v2 - v3) = (r1^-p - r2^-p) / (r2^-p - r3^-p) for p, then
    v_inf = v3 - (v2 - v3) r3^-p / (r2^-p - r3^-p).
    """
    (r1, r2, r3), (v1, v2, v3) = np.asarray(factors, dtype=float), np.asarray(values, dtype=float)
    ratio = (v1 - v2) / (v2 - v3)

    def mismatch(p):
        return (r1**-p - r2**-p) / (r2**-p - r3**-p) - ratio

    rate = brentq(mismatch, 0.05, 12.0)
    return rate, v3 - (v2 - v3) * r3**-rate / (r2**-rate - r3**-rate)


def convergence_study(plate: Plate, q: float, voltage: float, base: FemSettings, factors=(1, 2, 3)) -> ConvergenceStudy:
    """Evaluate the FEM with ``base.refined(factor)`` for each factor."""
    results = [evaluate_fem(plate, q, voltage, base.refined(factor)) for factor in factors]
    return ConvergenceStudy(
        factors=tuple(factors),
        n_dofs=tuple(r.n_dofs for r in results),
        frequencies=tuple(r.frequency for r in results),
        deflections=tuple(r.deflection for r in results),
    )
