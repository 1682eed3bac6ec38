"""The working mode's shape: where the vibrometer points, and how local damping adds up over the plate.

Velocity convention (docs/damping.md): every Q(v) law of the fit and the design is a
function of the *peak velocity amplitude at the antinodes*, v_a.  The vibrometer reads one
point (x, y); in the mode phi (normalised to |phi| = 1 at the antinodes) it reads
v_a |phi(x, y)|, so the fit divides by :func:`measurement_factor`.

Local and modal damping: the material at x loses energy per cycle at a rate set by its
own velocity v_a |phi(x)|.  Weighting the local loss factor by the mode's energy
density (phi^2), the plate's (modal) loss factor is

    1/Q(v_a) = < phi^2 / Q_loc(v_a |phi|) > / < phi^2 >.

For a power-law loss 1/Q_loc = 1/Q0 + alpha_loc |v|^n this is exactly the same law in v_a
with alpha = alpha_loc <|phi|^(n+2)> / <phi^2>: the local law evaluated at the effective
velocity v_eff = v_a (<|phi|^(n+2)> / <phi^2>)^(1/n) (n = 2: sqrt(<phi^4>/<phi^2>), 0.866
v_a for a sine).  :func:`modal_law` does this conversion, :func:`effective_velocity` gives
v_eff.

Beam mode (the default): the resonator of length L = (2n+1) lambda / 4 carries
phi(x) = cos(2 pi x / lambda), x from the plate's centre along its length (antinodes at the
ceramics' centres, x = k lambda / 2), uniform across the width.  A mode sampled elsewhere
(e.g. from the FEM's nodal deflections) is a :class:`SampledMode`.
"""

from dataclasses import dataclass

import numpy as np

from workflow.damping.laws import LinearLoss, QuadraticLoss
from workflow.models.materials import N_CERAMICS

BEAM_SAMPLES = 2001
"""Points along the beam for the averages over the plate [-]."""
MIN_MEASUREMENT_FACTOR = 0.05
"""A measurement point where |phi| is below this (near a node) is refused: the velocity there says
little about the antinode's [-]."""
LOSS_EXPONENTS = {QuadraticLoss: 2, LinearLoss: 1}
"""Laws with a power-law loss term alpha |v|^n, by class -> n."""


@dataclass(frozen=True)
class SampledMode:
    """A mode shape sampled over the plate, normalised to 1 at its largest |value|.

    Attributes
    ----------
    x, y : numpy.ndarray
        Sample positions from the plate's centre [m] (x along the length).
    shape : numpy.ndarray
        Mode shape phi at the samples [-].
    weight : numpy.ndarray
        Area (or length) each sample stands for, for the averages [m^2 or m].
    """

    x: np.ndarray
    y: np.ndarray
    shape: np.ndarray
    weight: np.ndarray

    def at(self, x, y):
        """phi at (x, y) [m]: the nearest sample's value [-]."""
        distance = (self.x - np.asarray(x, dtype=float)[..., None]) ** 2 + (self.y - np.asarray(y, dtype=float)[..., None]) ** 2
        return self.shape[np.argmin(distance, axis=-1)]

    def moment(self, power: float) -> float:
        """<|phi|^power> / <phi^2> over the plate, energy-weighted averages [-]."""
        magnitude = np.abs(self.shape)
        return float(np.sum(self.weight * magnitude**power) / np.sum(self.weight * magnitude**2))


@dataclass(frozen=True)
class BeamMode:
    """The analytical beam mode phi(x) = cos(2 pi x / lambda) over the resonator's length.

    Attributes
    ----------
    wavelength : float
        lambda [m].
    n_ceramics : int
        Ceramics along x; the resonator is (2n+1) lambda / 4 long.
    """

    wavelength: float
    n_ceramics: int = N_CERAMICS

    @property
    def length(self) -> float:
        """Resonator length (2n+1) lambda / 4 [m]."""
        return (2 * self.n_ceramics + 1) * self.wavelength / 4

    def at(self, x, y):
        """phi at (x, y) [m] from the plate's centre [-] (independent of y)."""
        return np.cos(2 * np.pi * np.asarray(x, dtype=float) / self.wavelength) + 0 * np.asarray(y, dtype=float)

    def sampled(self) -> SampledMode:
        """The mode on :data:`BEAM_SAMPLES` points along the length (trapezoid weights)."""
        x = np.linspace(-self.length / 2, self.length / 2, BEAM_SAMPLES)
        weight = np.full(BEAM_SAMPLES, x[1] - x[0])
        weight[[0, -1]] *= 0.5
        return SampledMode(x, np.zeros_like(x), self.at(x, 0.0), weight)

    def moment(self, power: float) -> float:
        """<|phi|^power> / <phi^2> over the resonator [-]."""
        return self.sampled().moment(power)


def measurement_factor(mode, x, y) -> np.ndarray:
    """|phi(x, y)|: the measured velocity over the antinode's [-].

    Raises
    ------
    ValueError
        Where |phi| < :data:`MIN_MEASUREMENT_FACTOR` (a point near a node).
    """
    factor = np.abs(mode.at(x, y))
    if np.any(factor < MIN_MEASUREMENT_FACTOR):
        raise ValueError(
            f"measurement point too close to a node (|phi| = {float(np.min(factor)):.3f} < {MIN_MEASUREMENT_FACTOR}); "
            "its velocity does not determine the antinode's"
        )
    return factor


def effective_velocity(mode, antinode_velocity, exponent: float = 2.0):
    """v_eff = v_a (<|phi|^(n+2)> / <phi^2>)^(1/n): the velocity at which the local law gives the modal Q [m/s]."""
    return np.asarray(antinode_velocity) * mode.moment(exponent + 2) ** (1 / exponent)


def modal_law(local_law, mode):
    """The plate's law in the antinode velocity from a local (material) power law: alpha = alpha_loc <|phi|^(n+2)>/<phi^2>.

    Raises
    ------
    TypeError
        For a law without a power-law loss term (see :data:`LOSS_EXPONENTS`).
    """
    exponent = LOSS_EXPONENTS.get(type(local_law))
    if exponent is None:
        raise TypeError(f"no exact modal form for the {getattr(local_law, 'name', type(local_law).__name__)} law")
    return type(local_law)(q0=local_law.q0, alpha=np.asarray(local_law.alpha) * mode.moment(exponent + 2))
