"""tactile: design ultrasonic tactile plates from experiments.

Layers, one direction: models (pure) <- fitting / optimisation (pure, take callables)
<- steps (files) <- CLI.  SI units everywhere inside; millimetres and microns only at
the edges, through :mod:`workflow.units`.
"""

__version__ = "0.1.0"

import warnings

# ArviZ 0.23 announces its coming 1.0 refactor with a FutureWarning on every import: it is not the user's business,
# and the version is pinned below 1 (pyproject.toml).
warnings.filterwarnings("ignore", message=r"\s*ArviZ is undergoing a major refactor", category=FutureWarning)
