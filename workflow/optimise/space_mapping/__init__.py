"""Space-mapping optimisation: the FEM optimum from a handful of FEM evaluations (docs/fem.md).

The coarse model (the beam) is cheap, the fine model (the FEM) is not.  Both are plate
models; the design variables are x = (lambda, h_i).

Where the optimum is.  The deflection grows with lambda at fixed h_i (a longer, softer
plate), so the constrained optimum lies on the fine model's resonance curve
f_f(lambda, h_i) = f_min (or on the lambda bound), and the search is one-dimensional along
that curve, parametrised by h_i.  Two ratios, functions of h_i, map the coarse model onto
the fine one along it: the wavelength ratio m and the deflection ratio rho.

Why not the textbook iteration.  Aggressive space mapping solves P(x) = z* for the coarse
optimum z*.  With the frequency constraint active, P(x) = z* only puts x on the right
curve; where along it the fine deflection peaks is fine-model information (the deflection
ratio) that P(x) = z* ignores.

One search (:mod:`.search`, over the fine steps of :mod:`.steps`), two ways to fit the mapping:

- :mod:`.from_sensitivities`: each fine point gives the ratios' values and slopes (the FEM's
  design sensitivities); ``optimise_fem`` uses it for the plain FEM;
- :mod:`.from_responses`: the ratios fitted to fine values only (parameter extraction), for
  fine models without sensitivities (the FEM with Q(v)).
"""

from workflow.optimise.space_mapping.from_responses import NEAR_CURVE, ResponseMapping
from workflow.optimise.space_mapping.from_sensitivities import SensitivityMapping, finite_difference_gradients
from workflow.optimise.space_mapping.search import SpaceMappingResult, coarse_wavelength, space_mapping_optimum
from workflow.optimise.space_mapping.steps import FREQUENCY_TOLERANCE

__all__ = [
    "FREQUENCY_TOLERANCE",
    "NEAR_CURVE",
    "ResponseMapping",
    "SensitivityMapping",
    "SpaceMappingResult",
    "coarse_wavelength",
    "finite_difference_gradients",
    "space_mapping_optimum",
]
