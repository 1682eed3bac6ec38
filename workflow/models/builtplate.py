"""Built plates: the nominal geometry a log names, and how a built plate deviates from it.

A plate built from a design differs from the model by its bond (an epoxy layer), the scatter of
the material constants, thickness tolerances and the placement of the ceramics (docs/instruments.md, "Built plates").
:class:`PlateDeviations` holds such deviations and :func:`deviated_plate` applies them to a
nominal :class:`~workflow.models.plate.Plate`: the plate the FEM solves when the bench simulator
plays a built plate.  :class:`BuiltPlate` is the nominal geometry a built-plate log names in its
metadata (docs/log-format.md), parsed and checked here, written back by :meth:`BuiltPlate.metadata`.
"""

from dataclasses import dataclass, fields, replace

import numpy as np

from workflow import logformat
from workflow.errors import InputFileError
from workflow.models import materials
from workflow.models.limits import problem
from workflow.models.materials import Material, PiezoMaterial
from workflow.models.plate import Plate
from workflow.units import MM, UM


def scaled_ceramic(ceramic: PiezoMaterial, factor: float) -> PiezoMaterial:
    """The ceramic with its stiffness c^E scaled by ``factor`` [-] and its charge constants d kept.

    The piezoelectric stress constants e = c^E d scale with it, so the free strain per volt
    is unchanged while the ceramic is stiffer or softer; E (= 1/s11^E) scales by ``factor``.
    """
    return replace(
        ceramic,
        name=f"{ceramic.name} x{factor:g}",
        youngs_modulus=ceramic.youngs_modulus * factor,
        elastic_stiffness=tuple(tuple(c * factor for c in row) for row in ceramic.elastic_stiffness),
        piezo_stress=tuple(tuple(e * factor for e in row) for row in ceramic.piezo_stress),
    )


def scaled_material(material: Material, factor: float) -> Material:
    """The isotropic material with its Young's modulus scaled by ``factor`` [-]."""
    return replace(material, name=f"{material.name} x{factor:g}", youngs_modulus=material.youngs_modulus * factor)


@dataclass(frozen=True)
class PlateDeviations:
    """How a built plate differs from its nominal design.

    The first five are the deviations the calibration's parameters describe (or, for the ceramics' placement, the
    drive); the others are deviations no calibration parameter spans (issue 29: what a calibration must survive).

    Attributes
    ----------
    glue_thickness : float
        Epoxy bond under each ceramic [m] (replaces the nominal plate's bond); with ``glue_thickness_factors``
        its mean.
    ceramic_modulus_factor : float
        Ceramic stiffness c^E over the record's [-] (d kept, see :func:`scaled_ceramic`).
    resonator_modulus_factor : float
        Resonator Young's modulus over the record's [-].
    resonator_thickness_offset : float
        Built h_i minus nominal h_i [m].
    ceramic_offset : float
        Shift of the row of ceramics along x from the antinodes [m].  The quarter-plate FEM
        keeps the plate symmetric, so the offset acts on the drive only: every ceramic then
        covers a shifted stretch of the sinusoidal mode, and the modal drive falls by
        :meth:`drive_factor` (the modes it would excite, antisymmetric in x, are not modelled).
    glue_modulus_factor : float
        The bond's Young's modulus over its record's [-]: below 1 for a bond only partly cured.
    glue_thickness_factors : tuple of float
        Bond thickness under each ceramic over the mean, from the centre ceramic outwards (mirrored on the
        other half: the quarter-plate FEM is symmetric) [-]; empty: uniform (:class:`~workflow.models.materials.VaryingGlue`).
    width_offset : float
        Built width minus nominal width [m].
    ceramic_length_offset : float
        Built ceramic length minus nominal l_p = lambda/2 - delta [m] (the gaps shrink by as much: the ceramics stay
        centred on the antinodes).
    ceramic_record : str or None
        The material record the ceramics were actually made of (e.g. an anisotropic ``PZT-5A``), before
        ``ceramic_modulus_factor``; None: the nominal plate's.
    """

    glue_thickness: float = 0.0
    ceramic_modulus_factor: float = 1.0
    resonator_modulus_factor: float = 1.0
    resonator_thickness_offset: float = 0.0
    ceramic_offset: float = 0.0
    glue_modulus_factor: float = 1.0
    glue_thickness_factors: tuple = ()
    width_offset: float = 0.0
    ceramic_length_offset: float = 0.0
    ceramic_record: str | None = None

    def __post_init__(self):
        for name, key in DEVIATION_LIMITS.items():
            for value in np.ravel(getattr(self, name)):
                reason = problem(key, value, si=True, name=name)
                if reason:
                    raise ValueError(reason)
        if self.ceramic_record is not None and self.ceramic_record not in materials.ceramic_names():
            raise ValueError(f"ceramic_record {self.ceramic_record!r} is not a ceramic record; known: "
                             f"{', '.join(materials.ceramic_names())}")

    def drive_factor(self, wavelength: float) -> float:
        """cos(2 pi delta / lambda) [-]: the modal drive of ceramics shifted by delta along a mode of wavelength lambda [m].

        A ceramic spanning [x_k + delta - l/2, x_k + delta + l/2] on w ~ cos(2 pi x / lambda) drives the
        mode through w'(end) - w'(start), proportional to cos(2 pi delta / lambda).
        """
        return float(np.cos(2 * np.pi * self.ceramic_offset / wavelength))

    def metadata(self) -> dict:
        """Flat ``deviation_*`` items in the units of the logs (um, mm) for a simulated log's header (the deviations
        beyond the calibration's parameters only when present)."""
        items = {
            "deviation_glue_um": self.glue_thickness / UM,
            "deviation_ceramic_modulus_factor": self.ceramic_modulus_factor,
            "deviation_resonator_modulus_factor": self.resonator_modulus_factor,
            "deviation_hi_offset_um": self.resonator_thickness_offset / UM,
            "deviation_ceramic_offset_mm": self.ceramic_offset / MM,
        }
        beyond = {
            "deviation_glue_modulus_factor": (self.glue_modulus_factor, 1.0),
            "deviation_glue_thickness_factors": (",".join(f"{f:g}" for f in self.glue_thickness_factors), ""),
            "deviation_width_offset_mm": (self.width_offset / MM, 0.0),
            "deviation_ceramic_length_offset_mm": (self.ceramic_length_offset / MM, 0.0),
            "deviation_ceramic_record": (self.ceramic_record, None),
        }
        return {**items, **{key: value for key, (value, nominal) in beyond.items() if value != nominal}}


DEVIATION_LIMITS = {
    "glue_thickness": "glue_um",
    "ceramic_modulus_factor": "modulus_factor",
    "resonator_modulus_factor": "modulus_factor",
    "resonator_thickness_offset": "hi_offset_um",
    "ceramic_offset": "ceramic_offset_mm",
    "glue_modulus_factor": "glue_modulus_factor",
    "glue_thickness_factors": "glue_thickness_factor",
    "width_offset": "width_offset_mm",
    "ceramic_length_offset": "ceramic_length_offset_mm",
}
""":class:`PlateDeviations` field -> its key in :data:`~workflow.models.limits.LIMITS` (each value of a tuple checked)."""


DEMONSTRATION_DEVIATIONS = PlateDeviations(
    glue_thickness=40 * UM,
    ceramic_modulus_factor=0.95,
    resonator_modulus_factor=0.95,
    resonator_thickness_offset=-30 * UM,
    ceramic_offset=0.3 * MM,
)
"""The demonstration built plate's hidden deviations (docs/instruments.md, "Built plates"): a 40 um
epoxy bond, both moduli 5 % low, h_i 30 um thin, ceramics 0.3 mm off the antinodes.  They put a
plate designed for 25 kHz about 8 % low, as the paper's built plates were (computed with the FEM,
not fitted to the paper)."""


@dataclass(frozen=True)
class DeviationSetting:
    """One hidden deviation of a simulated built plate as the settings name it: ``built_<name>`` in the run's
    [simulator] section, ``--dev-<name>`` of ``tactile measure --simulate``.

    Attributes
    ----------
    field : str
        The :class:`PlateDeviations` field.
    name : str
        The settings' name, ending in its unit.
    quantity : str
        Its range in :data:`~workflow.models.limits.LIMITS`.
    scale : float
        SI per unit of the setting (um: 1e-6, mm: 1e-3, factors: 1).
    text : str
        What it is, for help texts.
    """

    field: str
    name: str
    quantity: str
    scale: float
    text: str

    @property
    def config_key(self) -> str:
        return f"built_{self.name}"

    @property
    def option(self) -> str:
        return f"--dev-{self.name.replace('_', '-')}"

    @property
    def dest(self) -> str:
        return f"dev_{self.name}"

    def value(self, deviations: PlateDeviations) -> float:
        """The setting's value of ``deviations`` [its unit]."""
        return getattr(deviations, self.field) / self.scale


SIMULATED_DEVIATIONS = (
    DeviationSetting("glue_thickness", "glue_um", "glue_um", UM, "bond thickness [um]"),
    DeviationSetting("ceramic_modulus_factor", "ceramic_factor", "modulus_factor", 1.0, "ceramic stiffness factor [-]"),
    DeviationSetting("resonator_modulus_factor", "resonator_factor", "modulus_factor", 1.0,
                     "resonator Young's modulus factor [-]"),
    DeviationSetting("resonator_thickness_offset", "hi_offset_um", "hi_offset_um", UM, "resonator thickness offset [um]"),
    DeviationSetting("ceramic_offset", "ceramic_offset_mm", "ceramic_offset_mm", MM, "offset of the ceramics along x [mm]"),
)
"""The deviations a simulated built plate's settings set (the rest keep :class:`PlateDeviations`' defaults): one
declaration for the run's configuration, its ranges and the measure command's options."""


def deviations_from_settings(values: dict, base: PlateDeviations = PlateDeviations()) -> PlateDeviations:
    """``base`` with the deviations of ``values`` (setting name -> value in its unit; None or absent: kept)."""
    return replace(base, **{s.field: values[s.name] * s.scale for s in SIMULATED_DEVIATIONS if values.get(s.name) is not None})


def deviated_plate(plate: Plate, deviations: PlateDeviations) -> Plate:
    """The plate as built: ``plate`` with the bond, materials, thickness, width and ceramic length of ``deviations``.

    Raises
    ------
    GeometryError
        If the resonator thickness offset leaves no resonator, or the ceramics would overlap.
    """
    ceramic = plate.ceramic if deviations.ceramic_record is None else materials.ceramic(deviations.ceramic_record)
    glue = plate.glue if deviations.glue_modulus_factor == 1.0 else scaled_material(plate.glue, deviations.glue_modulus_factor)
    if deviations.glue_thickness_factors:
        profile = tuple(float(f) for f in deviations.glue_thickness_factors)
        outwards = np.abs(plate.ceramic_indices) // 2
        glue = materials.VaryingGlue(**{f.name: getattr(glue, f.name) for f in fields(materials.Glue)},
                                     thickness_factors=tuple(profile[min(k, len(profile) - 1)] for k in outwards))
    return plate.with_(
        glue_thickness=deviations.glue_thickness,
        glue=glue,
        ceramic=scaled_ceramic(ceramic, deviations.ceramic_modulus_factor),
        resonator=scaled_material(plate.resonator, deviations.resonator_modulus_factor),
        resonator_thickness=plate.resonator_thickness + deviations.resonator_thickness_offset,
        width=plate.width + deviations.width_offset,
        gap=plate.gap - deviations.ceramic_length_offset,
    )


@dataclass(frozen=True)
class BuiltPlate:
    """The nominal design of a built plate, as its logs name it.

    Attributes
    ----------
    wavelength, resonator_thickness, ceramic_thickness, width : float
        lambda, h_i, h_p, b [m].
    ceramic, resonator : str or None
        Material record names, when known (:mod:`workflow.models.materials`).
    glue_thickness : float or None
        Nominal bond thickness [m], when known.
    """

    wavelength: float
    resonator_thickness: float
    ceramic_thickness: float
    width: float
    ceramic: str | None = None
    resonator: str | None = None
    glue_thickness: float | None = None

    @classmethod
    def from_plate(cls, plate: Plate) -> "BuiltPlate":
        """The record of a nominal :class:`Plate` (its material names and bond included)."""
        return cls(float(plate.wavelength), float(plate.resonator_thickness), float(plate.ceramic_thickness),
                   float(plate.width), plate.ceramic.name, plate.resonator.name, float(plate.glue_thickness))

    def plate(self) -> Plate:
        """The nominal :class:`Plate`: the paper's materials and no bond unless named."""
        return Plate(
            wavelength=self.wavelength,
            resonator_thickness=self.resonator_thickness,
            ceramic_thickness=self.ceramic_thickness,
            width=self.width,
            ceramic=materials.ceramic(self.ceramic or materials.PAPER),
            resonator=materials.resonator(self.resonator or materials.PAPER),
            glue_thickness=self.glue_thickness or 0.0,
        )

    def metadata(self) -> dict:
        """The log metadata items naming this plate (docs/log-format.md), lengths in mm, the bond in um."""
        items = {
            logformat.LAMBDA_MM: self.wavelength / MM,
            logformat.HI_MM: self.resonator_thickness / MM,
            logformat.HP_MM: self.ceramic_thickness / MM,
            logformat.B_MM: self.width / MM,
            logformat.CERAMIC: self.ceramic,
            logformat.RESONATOR: self.resonator,
            logformat.GLUE_UM: None if self.glue_thickness is None else self.glue_thickness / UM,
        }
        return {key: f"{value:.12g}" if isinstance(value, float) else value for key, value in items.items() if value is not None}

    @classmethod
    def from_metadata(cls, metadata: dict, source: str) -> "BuiltPlate":
        """Parse and check the built-plate keys of a log's metadata.

        Parameters
        ----------
        metadata : dict
            key -> (value text, line number) of the log's ``# key: value`` lines.
        source : str
            The log's path, for messages.

        Raises
        ------
        InputFileError
            A geometry key missing (naming the keys that are), a value that is not a finite number
            within its plausible range (naming its line), or an unknown material name.
        """
        missing = [key for key in logformat.BUILT_PLATE_KEYS if key not in metadata]
        if missing:
            raise InputFileError(f"{source}: not a built-plate log: no '# {missing[0]}: ...' metadata line "
                                 f"(a built-plate log names {', '.join(logformat.BUILT_PLATE_KEYS)})")
        lengths = {key: _plausible(metadata, key, source) for key in logformat.BUILT_PLATE_KEYS}
        names = {}
        for key, known in ((logformat.CERAMIC, materials.ceramic_names()), (logformat.RESONATOR, materials.resonator_names())):
            if key in metadata:
                value, line = metadata[key]
                if value not in known:
                    raise InputFileError(f"{source}, line {line}: {key} {value!r} is not a material record; "
                                         f"known: {', '.join(known)}")
                names[key] = value
        glue = _plausible(metadata, logformat.GLUE_UM, source) * UM if logformat.GLUE_UM in metadata else None
        return cls(
            wavelength=lengths[logformat.LAMBDA_MM] * MM,
            resonator_thickness=lengths[logformat.HI_MM] * MM,
            ceramic_thickness=lengths[logformat.HP_MM] * MM,
            width=lengths[logformat.B_MM] * MM,
            ceramic=names.get(logformat.CERAMIC),
            resonator=names.get(logformat.RESONATOR),
            glue_thickness=glue,
        )


def _plausible(metadata: dict, key: str, source: str) -> float:
    """The number of metadata item ``key``, within its plausible range (:data:`~workflow.models.limits.LIMITS`)."""
    value = logformat.metadata_number(metadata, key, source)
    reason = problem(key, value)
    if reason:
        raise InputFileError(f"{source}, line {metadata[key][1]}: {reason}")
    return value
