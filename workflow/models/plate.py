"""The plate geometry: a small immutable record and the geometry derived from it.

Fields may be floats or numpy arrays that broadcast together, so that the analytical
model can be evaluated over many geometries at once.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from workflow.errors import GeometryError
from workflow.models import materials
from workflow.models.materials import Material, PiezoMaterial
from workflow.units import MM


@dataclass(frozen=True)
class Plate:
    """A resonator with ``n_ceramics`` piezo strips glued on one face.

    Attributes
    ----------
    wavelength : float or array
        Flexural wavelength lambda [m].
    resonator_thickness : float or array
        Resonator thickness h_i [m].
    ceramic_thickness : float or array
        Ceramic thickness h_p [m].
    width : float or array
        Width b of the resonator and the ceramics [m].
    n_ceramics : int
        Number of ceramics along x [-].
    gap : float
        Gap between neighbouring ceramics, delta [m].
    resonator, ceramic : Material, PiezoMaterial
        Layer materials.
    glue_thickness : float
        Thickness of the bond between each ceramic and the resonator (only under the ceramics) [m];
        0 (the default, as in the paper) bonds them directly.  The beam model ignores it.
    glue : Material
        The bond's material (default: the epoxy record, docs/model.md).
    """

    wavelength: float
    resonator_thickness: float
    ceramic_thickness: float
    width: float = 49e-3
    n_ceramics: int = materials.N_CERAMICS
    gap: float = materials.CERAMIC_GAP
    resonator: Material = field(default=materials.COPPER_BERYLLIUM, repr=False)
    ceramic: PiezoMaterial = field(default=materials.PZT, repr=False)
    glue_thickness: float = 0.0
    glue: Material = field(default=materials.EPOXY, repr=False)

    def __post_init__(self):
        for name in ("wavelength", "resonator_thickness", "ceramic_thickness", "width"):
            value = np.asarray(getattr(self, name), dtype=float)
            if not np.all(np.isfinite(value)) or np.any(value <= 0):
                raise GeometryError(f"{name} must be a positive finite length in metres, got {_show(value)}")
        glue = np.asarray(self.glue_thickness, dtype=float)
        if not np.all(np.isfinite(glue)) or np.any(glue < 0):
            raise GeometryError(f"glue_thickness must be a finite length >= 0 in metres, got {_show(glue)}")
        if not (isinstance(self.n_ceramics, (int, np.integer)) and self.n_ceramics >= 1 and self.n_ceramics % 2 == 1):
            raise GeometryError(f"n_ceramics must be a positive odd integer, got {self.n_ceramics!r}")
        if not np.all(np.asarray(self.wavelength) / 2 > self.gap):
            raise GeometryError(
                f"wavelength/2 must exceed the ceramic gap {self.gap / MM:g} mm, "
                f"got wavelength {_show(np.asarray(self.wavelength) / MM)} mm"
            )

    def with_(self, **changes) -> "Plate":
        """A copy with some fields changed."""
        return replace(self, **changes)

    @property
    def batch_shape(self) -> tuple:
        """Broadcast shape of the geometric fields (``()`` for a single plate)."""
        return np.broadcast(self.wavelength, self.resonator_thickness, self.ceramic_thickness, self.width).shape

    @property
    def length(self):
        """Resonator length L = (2n+1) lambda / 4 [m]."""
        return (2 * self.n_ceramics + 1) * np.asarray(self.wavelength) / 4

    @property
    def ceramic_length(self):
        """Ceramic length l_p = lambda/2 - delta [m]."""
        return np.asarray(self.wavelength) / 2 - self.gap

    @property
    def total_thickness(self):
        """h_p + h_i [m] (the glue, under the ceramics only, is not counted)."""
        return np.asarray(self.ceramic_thickness) + np.asarray(self.resonator_thickness)

    @property
    def ceramic_indices(self) -> np.ndarray:
        """k = -(n-1), ..., -2, 0, 2, ..., n-1 (even integers), one per ceramic."""
        half = self.n_ceramics - 1
        return np.arange(-half, half + 1, 2)

    @property
    def ceramic_centres(self):
        """Ceramic centres x = k lambda / 4 [m] (on antinodes); shape (n,) + wavelength shape."""
        k = self.ceramic_indices.reshape((-1,) + (1,) * np.ndim(self.wavelength))
        return k * np.asarray(self.wavelength) / 4

    @property
    def polarities(self) -> np.ndarray:
        """+1/-1 per ceramic: neighbours are driven in antiphase; the centre one is +1."""
        return np.where((self.ceramic_indices // 2) % 2 == 0, 1, -1)

    @property
    def antinodes(self):
        """Antinode positions x = k lambda / 4 for the ceramic indices k [m] (same as the centres)."""
        return self.ceramic_centres


def _show(value: np.ndarray) -> str:
    flat = np.ravel(value)
    return f"{flat[0]:g}" if flat.size == 1 else f"an array with values from {np.nanmin(flat):g} to {np.nanmax(flat):g}"


ORIGINAL_PLATE = Plate(wavelength=24e-3, resonator_thickness=2.0e-3, ceramic_thickness=1.0e-3, width=49e-3)
"""The paper's original plate (docs/model.md)."""


def check_design_space(plate: Plate, min_resonator_thickness: float = materials.RESONATOR_THICKNESS_RANGE[0]) -> Plate:
    """Refuse a plate outside the design space of Table 1.

    Parameters
    ----------
    plate : Plate
    min_resonator_thickness : float
        Lower bound on h_i [m]; Table 1's 0.2 mm unless a stricter practical limit is asked.

    Returns
    -------
    Plate
        The same plate, for chaining.

    Raises
    ------
    GeometryError
        Naming the quantity, its value and the allowed range (in mm).
    """
    h_p = np.ravel(np.asarray(plate.ceramic_thickness, dtype=float))
    allowed = np.asarray(materials.CERAMIC_THICKNESSES)
    unknown = ~np.isclose(h_p[:, None], allowed[None, :], rtol=0, atol=1e-9).any(axis=1)
    if unknown.any():
        raise GeometryError(
            f"ceramic thickness h_p = {h_p[unknown][0] / MM:g} mm is not a commercial size; "
            f"choose one of {', '.join(f'{t / MM:g}' for t in allowed)} mm"
        )
    ranges = {
        "wavelength lambda": (plate.wavelength, materials.WAVELENGTH_RANGE),
        "resonator thickness h_i": (
            plate.resonator_thickness,
            (min_resonator_thickness, materials.RESONATOR_THICKNESS_RANGE[1]),
        ),
        "width b": (plate.width, materials.WIDTH_RANGE),
    }
    for name, (value, (low, high)) in ranges.items():
        value = np.asarray(value, dtype=float)
        tolerance = 1e-9 * high
        if np.any(value < low - tolerance) or np.any(value > high + tolerance):
            raise GeometryError(
                f"{name} = {_show(value / MM)} mm is outside the design range {low / MM:g} to {high / MM:g} mm"
            )
    return plate
