"""The FEM of one plate geometry as a fast function of the calibration parameters.

A design of FEM evaluations (Latin hypercube over the parameters' box) gives a response
surface of log f_r and of log w (the best mode's frequency and mean probe deflection).  Its
error, used as an extra variance in the likelihood, combines the leave-one-out residual of
the fit and the FEM's own discretisation-error estimate.
"""

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from workflow.calibration.parameters import deviated_plate
from workflow.calibration.surrogate import ResponseSurface, fit_response_surface, latin_hypercube
from workflow.models.plate import Plate

Evaluate = Callable[[Sequence[Plate]], list]
"""Plates -> FemResults (the caller binds Q, voltage, accuracy, cache)."""


@dataclass(frozen=True)
class PlateSurrogate:
    """log f_r and log w of one nominal plate over the calibration parameters.

    Attributes
    ----------
    names : tuple of str
        Parameters, in the order of the inputs.
    log_frequency, log_deflection : ResponseSurface
        ln(f_r / Hz) and ln(w / m) of the best mode [-].
    fem_error : float
        Root mean square of the FEM's relative frequency-error estimates over the design [-]
        (0 when the evaluations carry none).
    evaluations : int
        FEM evaluations of the design [-].
    """

    names: tuple
    log_frequency: ResponseSurface
    log_deflection: ResponseSurface
    fem_error: float
    evaluations: int

    @property
    def frequency_sigma(self) -> float:
        """Relative standard deviation of a surrogate frequency: fit and FEM errors in quadrature [-]."""
        return float(np.hypot(self.log_frequency.loo_rms, self.fem_error))

    def frequency(self, theta) -> np.ndarray:
        """f_r at parameter values ``theta`` (..., n) [Hz]."""
        return np.exp(self.log_frequency(theta))

    def deflection(self, theta) -> np.ndarray:
        """Best mode's mean probe deflection at ``theta`` (..., n) [m]."""
        return np.exp(self.log_deflection(theta))

    def to_dict(self) -> dict:
        return {
            "names": list(self.names),
            "log_frequency": self.log_frequency.to_dict(),
            "log_deflection": self.log_deflection.to_dict(),
            "fem_error": self.fem_error,
            "evaluations": self.evaluations,
        }

    @classmethod
    def from_dict(cls, data: dict) -> "PlateSurrogate":
        return cls(
            names=tuple(data["names"]),
            log_frequency=ResponseSurface.from_dict(data["log_frequency"]),
            log_deflection=ResponseSurface.from_dict(data["log_deflection"]),
            fem_error=float(data["fem_error"]),
            evaluations=int(data["evaluations"]),
        )


def design_results(plate: Plate, names: Sequence[str], points: np.ndarray, evaluate: Evaluate) -> tuple:
    """FEM of the nominal ``plate`` deviated by each row of ``points`` [SI]: (log f, log w, relative f errors)."""
    results = evaluate([deviated_plate(plate, names, theta) for theta in points])
    log_f = np.log([r.frequency for r in results])
    log_w = np.log([r.deflection for r in results])
    errors = np.array([0.0 if r.error is None else r.error.frequency for r in results])
    return log_f, log_w, errors


def build_plate_surrogate(
    plate: Plate, names: Sequence[str], bounds: np.ndarray, evaluate: Evaluate, n_points: int, degree: int, seed: int
) -> PlateSurrogate:
    """Response surfaces of the nominal ``plate`` over ``bounds`` from ``n_points`` FEM evaluations.

    Parameters
    ----------
    plate : Plate
        Nominal geometry and materials [m].
    names : sequence of str
        Calibration parameters (:func:`~workflow.calibration.parameters.deviated_plate`).
    bounds : array (n, 2)
        Box of the design [SI].
    evaluate : callable
        Plates -> FemResults.
    n_points, degree, seed : int
        Design size, polynomial degree (1 or 2), Latin hypercube seed.
    """
    points = latin_hypercube(n_points, bounds, seed)
    log_f, log_w, errors = design_results(plate, names, points, evaluate)
    return PlateSurrogate(
        names=tuple(names),
        log_frequency=fit_response_surface(points, log_f, bounds, degree),
        log_deflection=fit_response_surface(points, log_w, bounds, degree),
        fem_error=float(np.sqrt(np.mean(errors**2))),
        evaluations=len(points),
    )
