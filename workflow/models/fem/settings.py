"""Mesh and solver settings of the plate FEM: a small, hashable record."""

from dataclasses import asdict, dataclass

from workflow.errors import TactileError
from workflow.models.fem.elements import BRICKS, brick


PIEZO_MODELS = ("eigenstrain", "coupled")
"""The piezo models of the FEM (docs/fem.md)."""


def check_piezo(piezo: str) -> None:
    """Raise a TactileError naming the choices unless ``piezo`` is one of :data:`PIEZO_MODELS`."""
    if piezo not in PIEZO_MODELS:
        raise TactileError(f"unknown piezo model {piezo!r}; choose one of {', '.join(PIEZO_MODELS)}")


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
        Element type: "lagrange27", "serendipity20" or "lagrange-PX-PY-PZ", tensor-product Lagrange of
        degrees PX, PY, PZ along x, y, z (:func:`elements.brick`).
    piezo : str
        Piezo model: "eigenstrain" (the converse effect as an eigenstress of a uniform field, fast,
        the paper's model) or "coupled" (the electric potential as an unknown; resonance,
        antiresonance, coupling and admittance).
    grading : float
        Grading c in [0, 1) of the elements towards the ceramic ends (along x) and the bond
        (through the thickness): the end element is (1 - c)/(1 + c) of the mean size; 0 is uniform.
    """

    elements_per_ceramic: int = 6
    elements_per_gap: int = 1
    elements_per_layer: int = 2
    elements_across_half_width: int = 5
    n_modes: int = 6
    element: str = "lagrange27"
    grading: float = 0.0
    piezo: str = "eigenstrain"

    def __post_init__(self):
        try:
            brick(self.element)
        except KeyError:
            raise TactileError(f"unknown FEM element {self.element!r}; choose one of {', '.join(BRICKS)} or "
                               "lagrange-PX-PY-PZ (degrees 1 to 6 along x, y, z)") from None
        check_piezo(self.piezo)
        counts = {name: value for name, value in asdict(self).items() if name not in ("element", "grading", "piezo")}
        bad = {name: value for name, value in counts.items() if not isinstance(value, int) or value < 1}
        if bad:
            raise TactileError(f"FEM settings must be positive integers, got {bad}")
        if not 0 <= self.grading < 1:
            raise TactileError(f"grading must be in [0, 1), got {self.grading}")
        if self.elements_per_ceramic % 2:
            raise TactileError(f"elements_per_ceramic must be even, got {self.elements_per_ceramic}")

    def as_dict(self) -> dict:
        """The settings as a plain dict (for content hashing and JSON)."""
        return asdict(self)

    refines = False
    """One fixed mesh (the counterpart of :attr:`~workflow.models.fem.accuracy.FemAccuracy.refines`)."""

    def resolved(self, plate, evaluate) -> tuple:
        """(this mesh, no error estimate): the counterpart of
        :meth:`~workflow.models.fem.accuracy.FemAccuracy.resolved` (``evaluate`` is not called)."""
        return self, None

    def evaluated(self, plate, evaluate_mesh, start=None, keep_solution: bool = False):
        """The FEM result of ``plate`` on this mesh: ``evaluate_mesh(self, start)`` (the counterpart of
        :meth:`~workflow.models.fem.accuracy.FemAccuracy.evaluated`; ``plate`` and ``keep_solution`` unused: one
        evaluation, its solution kept)."""
        return evaluate_mesh(self, start)

    def refined(self, factor: int) -> "FemSettings":
        """Every element count multiplied by ``factor`` (for convergence studies)."""
        return FemSettings(
            elements_per_ceramic=self.elements_per_ceramic * factor,
            elements_per_gap=self.elements_per_gap * factor,
            elements_per_layer=self.elements_per_layer * factor,
            elements_across_half_width=self.elements_across_half_width * factor,
            n_modes=self.n_modes,
            element=self.element,
            grading=self.grading,
            piezo=self.piezo,
        )


DEFAULT_SETTINGS = FemSettings()
"""The fixed mesh used before accuracy control (+0.4 % in frequency on the original plate, +0.8-1.2 % on
thin designs; docs/fem.md); FEM evaluations default to an accuracy target instead (``accuracy.FemAccuracy``)."""
