"""Fine steps, the fine evaluations of a space-mapping search, and what is judged from them."""

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from workflow.optimise.problem import DesignProblem
from workflow.units import MM

FREQUENCY_TOLERANCE = 2e-4
"""Relative shortfall of f below f_min accepted at a fine point [-] (5 Hz at 25 kHz)."""


@dataclass(frozen=True)
class FineStep:
    """One fine evaluation: at ``design`` (lambda, h_i) [m], the fine ``deflection`` [m] and
    ``frequency`` [Hz], and the ``transverse_indicator`` of its working mode [-] (0 when the fine
    model does not report it)."""

    mixing_limit: ClassVar[float]
    """Transverse indicator above which the step is mixed [-] (set by each mapping)."""

    design: np.ndarray
    deflection: float
    frequency: float
    transverse_indicator: float

    @property
    def thickness_mm(self) -> float:
        return float(self.design[1] / MM)

    @property
    def mixed(self) -> bool:
        """Whether a transverse mode mixes into the working mode (the step does not shape the mapping)."""
        return self.transverse_indicator > self.mixing_limit


def reaches_min_frequency(step: FineStep, problem: DesignProblem) -> bool:
    """Whether a fine step reached f_min within :data:`FREQUENCY_TOLERANCE` [-]."""
    return step.frequency >= problem.min_frequency * (1 - FREQUENCY_TOLERANCE)


def best_step(steps, problem: DesignProblem, accept_mixed: bool) -> FineStep | None:
    """The feasible clean step of largest deflection (``accept_mixed``: a mixed one when none is clean)."""
    feasible = [s for s in steps if reaches_min_frequency(s, problem)]
    pool = [s for s in feasible if not s.mixed] or (feasible if accept_mixed else [])
    return max(pool, key=lambda s: s.deflection) if pool else None


def nearest_to_curve(steps, problem: DesignProblem) -> FineStep:
    """The step whose frequency is nearest f_min (in ln f)."""
    return min(steps, key=lambda s: abs(np.log(s.frequency / problem.min_frequency)))
