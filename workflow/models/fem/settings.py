"""Mesh and solver settings of the plate FEM: a small, hashable record."""

from dataclasses import asdict, dataclass

from workflow.errors import TactileError
from workflow.models.fem.elements import BRICKS


@dataclass(frozen=True)
class FemSettings:
    """Resolution of the structured triquadratic brick mesh of the quarter plate.

    Attributes
    ----------
    elements_per_ceramic : int
        Elements along x per full ceramic (even; the half ceramic at x = 0 gets half) [-].
        The free end beyond the last ceramic gets elements of about the same length.
    elements_per_gap : int
        Elements along x across each gap between ceramics [-].
    elements_per_layer : int
        Elements through the thickness of each layer (ceramic, resonator) [-].
    elements_across_half_width : int
        Elements along y across the half width b/2 [-].
    n_modes : int
        Eigenmodes computed nearest the analytical resonance [-].
    element : str
        Element type: "serendipity20" or "lagrange27" (see :data:`elements.BRICKS`).
    """

    elements_per_ceramic: int = 6
    elements_per_gap: int = 1
    elements_per_layer: int = 2
    elements_across_half_width: int = 5
    n_modes: int = 6
    element: str = "lagrange27"

    def __post_init__(self):
        if self.element not in BRICKS:
            raise TactileError(f"unknown FEM element {self.element!r}; choose one of {', '.join(BRICKS)}")
        counts = {name: value for name, value in asdict(self).items() if name != "element"}
        bad = {name: value for name, value in counts.items() if not isinstance(value, int) or value < 1}
        if bad:
            raise TactileError(f"FEM settings must be positive integers, got {bad}")
        if self.elements_per_ceramic % 2:
            raise TactileError(f"elements_per_ceramic must be even, got {self.elements_per_ceramic}")

    def as_dict(self) -> dict:
        """The settings as a plain dict (for content hashing and JSON)."""
        return asdict(self)

    def refined(self, factor: int) -> "FemSettings":
        """Every element count multiplied by ``factor`` (for convergence studies)."""
        return FemSettings(
            elements_per_ceramic=self.elements_per_ceramic * factor,
            elements_per_gap=self.elements_per_gap * factor,
            elements_per_layer=self.elements_per_layer * factor,
            elements_across_half_width=self.elements_across_half_width * factor,
            n_modes=self.n_modes,
            element=self.element,
        )


DEFAULT_SETTINGS = FemSettings()
"""The default mesh (frequency within 0.5 % of the converged value, see docs/fem.md)."""
