"""3D finite-element model of the quarter plate (docs/fem.md).

Structured triquadratic bricks, exact element integrals scattered in one vectorised
assembly, shift-invert eigenmodes near the beam resonance and harmonic responses by
modal superposition.  ``evaluate_fem`` is the cost function (eigenstrain drive);
``evaluate_fem_coupled`` the coupled piezoelectric model.
"""

from workflow.models.fem.evaluate import evaluate_fem
from workflow.models.fem.result import FemResult, ModeResult
from workflow.models.fem.piezoelectric import evaluate_fem_coupled
from workflow.models.fem.settings import FemSettings

__all__ = ["FemResult", "FemSettings", "ModeResult", "evaluate_fem", "evaluate_fem_coupled"]
