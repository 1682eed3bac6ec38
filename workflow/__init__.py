"""tactile: design ultrasonic tactile plates from experiments.

Layers, one direction: models (pure) <- fitting / optimisation (pure, take callables)
<- steps (files) <- CLI.  SI units everywhere inside; millimetres and microns only at
the edges, through :mod:`workflow.units`.
"""

__version__ = "0.1.0"
