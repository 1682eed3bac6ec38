"""What a plate model gives at a geometry, whichever the model: the protocol the Q(v) design is written against.

The beam model (:class:`workflow.models.analytical.BeamResponse`), the FEM with an eigenstrain drive and the coupled
piezoelectric FEM (:class:`workflow.models.fem.result.FemResult`) each give, at a geometry and a drive voltage, the
working mode's resonance frequency, the antinode deflection as a function of the quality factor Q (the mode's
response at its own frequency) and, where the model has one, an estimate of its discretisation error.  The
self-consistent deflection with Q(v) and the voltage for a target deflection are written once on this
(:mod:`workflow.optimise.damped`).
"""

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class PlateResponse(Protocol):
    """The working mode of one plate (or a batch, as arrays) at a drive voltage.

    Attributes
    ----------
    frequency : float or numpy.ndarray
        Resonance frequency f_r [Hz].
    voltage : float
        Drive amplitude the deflection is at [V peak].
    error : object or None
        The model's estimate of its discretisation error (the FEM's ``ErrorEstimate``); None without one.
    """

    frequency: object
    voltage: float
    error: object

    def deflection_at_q(self, q):
        """Antinode deflection amplitude at f_r for quality factor ``q`` [m] (vectorised over ``q``)."""


@dataclass(frozen=True)
class ScaledResponse:
    """A response seen at another drive voltage: every model here is linear in V.

    Attributes
    ----------
    response : PlateResponse
    scale : float
        New voltage over the response's [-].
    """

    response: PlateResponse
    scale: float

    @property
    def frequency(self):
        return self.response.frequency

    @property
    def voltage(self) -> float:
        return self.response.voltage * self.scale

    @property
    def error(self):
        return self.response.error

    def deflection_at_q(self, q):
        return self.scale * self.response.deflection_at_q(q)


@dataclass(frozen=True)
class StackedResponse:
    """Single-geometry responses of a batch of plates (e.g. the FEM's results, one per geometry) as one batched
    response, so that what is written for the beam model's arrays applies to them unchanged.

    Attributes
    ----------
    responses : tuple of PlateResponse
        One per geometry, in C order of ``shape``, all at the same voltage.
    shape : tuple
        The batch's shape (the plates' ``batch_shape``).
    """

    responses: tuple
    shape: tuple

    @property
    def frequency(self):
        return np.reshape([r.frequency for r in self.responses], self.shape)

    @property
    def voltage(self) -> float:
        return self.responses[0].voltage

    @property
    def error(self):
        return None

    def deflection_at_q(self, q):
        """Each geometry's deflection at its own Q [m]: ``q`` broadcasts against the batch's shape, which takes its
        trailing axes (leading axes, e.g. posterior draws, are passed to every response as a vector)."""
        q = np.asarray(q, dtype=float)
        full = np.broadcast_shapes(q.shape, self.shape)
        per_geometry = np.broadcast_to(q, full).reshape(full[: len(full) - len(self.shape)] + (-1,))
        return np.stack([np.asarray(r.deflection_at_q(per_geometry[..., i]), dtype=float)
                         for i, r in enumerate(self.responses)], axis=-1).reshape(full)
