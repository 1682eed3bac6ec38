"""Materials, design bounds and fixed design choices (Table 1 of the paper).

The material records live as data in ``materials.toml`` beside this module; this module
loads and checks them and is the single source of truth in code for every number here.  SI units.
"""

import sys
from dataclasses import dataclass, field
from functools import cache
from importlib import resources

import numpy as np

from workflow.errors import InputFileError, TactileError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

VACUUM_PERMITTIVITY = 8.8541878128e-12
"""eps_0 [F/m]."""

RECORDS_FILE = "materials.toml"
"""The named material records, package data beside this module (docs/model.md)."""

_VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))
"""Voigt index I -> tensor index pair (i, j): xx, yy, zz, yz, xz, xy."""


def isotropic_stiffness(youngs_modulus: float, poisson_ratio: float) -> np.ndarray:
    """Voigt stiffness C (6 x 6) of an isotropic solid [Pa]."""
    lam = youngs_modulus * poisson_ratio / ((1 + poisson_ratio) * (1 - 2 * poisson_ratio))
    mu = youngs_modulus / (2 * (1 + poisson_ratio))
    stiffness = np.zeros((6, 6))
    stiffness[:3, :3] = lam
    stiffness[range(3), range(3)] = lam + 2 * mu
    stiffness[range(3, 6), range(3, 6)] = mu
    return stiffness


def transversely_isotropic_stiffness(c11, c12, c13, c33, c44, c66) -> np.ndarray:
    """Voigt stiffness C (6 x 6) of a solid isotropic in the xy plane, axis z [Pa]."""
    return np.array(
        [
            [c11, c12, c13, 0, 0, 0],
            [c12, c11, c13, 0, 0, 0],
            [c13, c13, c33, 0, 0, 0],
            [0, 0, 0, c44, 0, 0],
            [0, 0, 0, 0, c44, 0],
            [0, 0, 0, 0, 0, c66],
        ],
        dtype=float,
    )


def voigt_index() -> np.ndarray:
    """(3, 3) int array: the Voigt index of each tensor index pair (i, j)."""
    index = np.empty((3, 3), dtype=int)
    for voigt, (i, j) in enumerate(_VOIGT):
        index[i, j] = index[j, i] = voigt
    return index


def _frozen(array) -> tuple:
    return tuple(tuple(float(x) for x in row) for row in np.asarray(array))


@dataclass(frozen=True)
class Material:
    """An isotropic elastic layer.

    Attributes
    ----------
    name : str
    youngs_modulus : float
        Young's modulus [Pa] (for the ceramic: c11p^E, short circuit).
    density : float
        Mass density [kg/m^3].
    poisson_ratio : float
        Poisson's ratio [-].
    source : str
        Where the constants come from.
    """

    name: str
    youngs_modulus: float
    density: float
    poisson_ratio: float
    source: str = field(default="", kw_only=True)

    def stiffness_matrix(self) -> np.ndarray:
        """Voigt stiffness C (6 x 6) [Pa]."""
        return isotropic_stiffness(self.youngs_modulus, self.poisson_ratio)


@dataclass(frozen=True, kw_only=True)
class Glue(Material):
    """An isotropic bonding layer.

    Attributes
    ----------
    typical_thickness : float
        Bond line thickness typical of the product [m] (a documented default, not a design value).
    """

    typical_thickness: float


@dataclass(frozen=True, kw_only=True)
class VaryingGlue(Glue):
    """A bond whose thickness differs from ceramic to ceramic (docs/instruments.md, "Built plates").

    The FEM keeps one glue layer of the plate's ``glue_thickness`` (the mean) and gives the bond under ceramic k the
    modulus E / f_k: a layer f_k times as thick has that compliance, through the thickness and in shear.  The bond's
    mass (under 1 % of a plate's) and the small shift in height of the ceramic above a thicker bond are not modelled.

    Attributes
    ----------
    thickness_factors : tuple of float
        Local bond thickness over the layer's, one per ceramic in the order of ``Plate.ceramic_centres`` [-].
    """

    thickness_factors: tuple

    def under_ceramic(self, index: int) -> Material:
        """The isotropic bond under ceramic ``index`` (of ``Plate.ceramic_centres``): E / f_index [Pa]."""
        factor = self.thickness_factors[index]
        return Material(f"{self.name} under ceramic {index}", self.youngs_modulus / factor, self.density,
                        self.poisson_ratio, source=self.source)


@dataclass(frozen=True, kw_only=True)
class PiezoMaterial(Material):
    """A poled piezo-ceramic, poling axis z, driven through the transverse (31) effect.

    ``youngs_modulus``, ``poisson_ratio`` and ``d31`` are what the beam model uses; the FEM
    uses the tensors.  They agree: E = 1/s11^E, nu = -s12^E/s11^E and d31 = (e s^E)_31 with
    s^E = (c^E)^-1 (checked on construction).

    Attributes
    ----------
    d31 : float
        Piezoelectric charge constant [m/V].
    e31 : float
        Published piezoelectric stress constant [C/m^2] (for the paper's record, Table 1's value;
        the tensor below is built from d31 instead, docs/model.md).
    mechanical_q : float
        Mechanical quality factor of the material [-].
    elastic_stiffness : tuple
        c^E, 6 x 6 Voigt (xx, yy, zz, yz, xz, xy) [Pa].
    piezo_stress : tuple
        e, 3 x 6 [C/m^2]: stress -e^T E from a field E.
    clamped_permittivity : tuple
        eps^S, 3 x 3 [F/m].
    """

    d31: float
    e31: float
    mechanical_q: float
    elastic_stiffness: tuple
    piezo_stress: tuple
    clamped_permittivity: tuple

    def __post_init__(self):
        compliance = np.linalg.inv(self.stiffness_matrix())
        derived = {
            "youngs_modulus": 1 / compliance[0, 0],
            "poisson_ratio": -compliance[0, 1] / compliance[0, 0],
            "d31": (self.piezo_matrix() @ compliance)[2, 0],
        }
        for name, value in derived.items():
            if not np.isclose(getattr(self, name), value, rtol=1e-9, atol=0):
                raise ValueError(f"ceramic {self.name!r}: {name} {getattr(self, name):g} disagrees with its tensors ({value:g})")

    def stiffness_matrix(self) -> np.ndarray:
        """c^E, Voigt 6 x 6 [Pa]."""
        return np.array(self.elastic_stiffness)

    def piezo_matrix(self) -> np.ndarray:
        """e, 3 x 6 [C/m^2]."""
        return np.array(self.piezo_stress)

    def permittivity_matrix(self) -> np.ndarray:
        """eps^S, 3 x 3 [F/m]."""
        return np.array(self.clamped_permittivity)

    @classmethod
    def from_tensors(cls, name, stiffness, piezo_stress, permittivity, density, mechanical_q, source):
        """A ceramic from its full constants; E, nu and d31 derived from s^E = (c^E)^-1 and d = e s^E."""
        compliance = np.linalg.inv(stiffness)
        return cls(
            name=name,
            youngs_modulus=1 / compliance[0, 0],
            density=density,
            poisson_ratio=-compliance[0, 1] / compliance[0, 0],
            d31=(np.asarray(piezo_stress) @ compliance)[2, 0],
            e31=float(piezo_stress[2][0]),
            mechanical_q=mechanical_q,
            elastic_stiffness=_frozen(stiffness),
            piezo_stress=_frozen(piezo_stress),
            clamped_permittivity=_frozen(permittivity),
            source=source,
        )

    @classmethod
    def isotropic(cls, name, youngs_modulus, poisson_ratio, density, d31, e31, mechanical_q, permittivity, source):
        """A ceramic known only by E, nu and d31: c^E isotropic and e = c^E d with d = (d31, d31, 0, 0, 0, 0).

        Its converse effect under a field E_z is then exactly the in-plane isotropic eigenstrain d31 E_z.
        """
        stiffness = isotropic_stiffness(youngs_modulus, poisson_ratio)
        charge = np.zeros((3, 6))
        charge[2, :2] = d31
        return cls(
            name=name,
            youngs_modulus=youngs_modulus,
            density=density,
            poisson_ratio=poisson_ratio,
            d31=d31,
            e31=e31,
            mechanical_q=mechanical_q,
            elastic_stiffness=_frozen(stiffness),
            piezo_stress=_frozen(charge @ stiffness),
            clamped_permittivity=_frozen(permittivity),
            source=source,
        )


_POSITIVE = "a positive number"
_NUMBER = "a number"
_FIELDS = {
    "resonator": {"youngs_modulus": _POSITIVE, "density": _POSITIVE, "poisson_ratio": _NUMBER},
    "glue": {"youngs_modulus": _POSITIVE, "density": _POSITIVE, "poisson_ratio": _NUMBER, "typical_thickness": _POSITIVE},
    "paper ceramic": {
        "youngs_modulus": _POSITIVE,
        "poisson_ratio": _NUMBER,
        "density": _POSITIVE,
        "d31": _NUMBER,
        "e31": _NUMBER,
        "mechanical_q": _POSITIVE,
        "permittivity_from": "the name of another ceramic record",
    },
    "ceramic": {
        **{name: _POSITIVE for name in ("c11", "c12", "c13", "c33", "c44", "c66")},
        "e31": _NUMBER,
        "e33": _NUMBER,
        "e15": _NUMBER,
        "relative_eps_s11": _POSITIVE,
        "relative_eps_s33": _POSITIVE,
        "density": _POSITIVE,
        "mechanical_q": _POSITIVE,
    },
}
"""Required fields of each kind of record and what each must be (besides ``source``)."""


def _checked(kind: str, name: str, record, origin: str) -> dict:
    """The record's fields after checking them; raises naming the record and the field."""
    where = f"{origin}: {kind.split()[-1]} {name!r}"
    if not isinstance(record, dict):
        raise InputFileError(f"{where} must be a table of fields")
    expected = _FIELDS[kind]
    unknown = sorted(set(record) - set(expected) - {"source"})
    if unknown:
        raise InputFileError(f"{where}: unknown field {unknown[0]!r}; expected {', '.join(['source', *expected])}")
    for key, what in {"source": "a non-empty string naming where the constants come from", **expected}.items():
        value = record.get(key)
        if what in (_POSITIVE, _NUMBER):
            valid = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
            valid = valid and (what == _NUMBER or value > 0)
        else:
            valid = isinstance(value, str) and value.strip() != ""
        if not valid:
            raise InputFileError(f"{where}: field {key!r} must be {what}, got {value!r}")
    if "poisson_ratio" in record and not -1 < record["poisson_ratio"] < 0.5:
        raise InputFileError(f"{where}: field 'poisson_ratio' must lie in (-1, 0.5), got {record['poisson_ratio']!r}")
    return record


def parse_records(text: str, origin: str = RECORDS_FILE) -> dict:
    """Material records from the TOML text of a records file, checked.

    Parameters
    ----------
    text : str
        TOML with tables ``[ceramic.NAME]``, ``[resonator.NAME]``, ``[glue.NAME]``.
    origin : str
        File name used in error messages.

    Returns
    -------
    dict
        ``{"ceramic": {name: PiezoMaterial}, "resonator": {name: Material}, "glue": {name: Glue}}``.

    Raises
    ------
    InputFileError
        Naming the record and the field that is missing or wrong.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputFileError(f"{origin}: not valid TOML ({error})") from None
    unknown = sorted(set(data) - {"ceramic", "resonator", "glue"})
    if unknown:
        raise InputFileError(f"{origin}: unknown section {unknown[0]!r}; expected ceramic, resonator, glue")
    sections = {kind: data.get(kind, {}) for kind in ("ceramic", "resonator", "glue")}
    for kind, records in sections.items():
        if not isinstance(records, dict) or not records:
            raise InputFileError(f"{origin}: section {kind!r} must hold at least one record [{kind}.NAME]")
    resonators = {
        name: Material(name, r["youngs_modulus"], r["density"], r["poisson_ratio"], source=r["source"])
        for name, r in ((n, _checked("resonator", n, r, origin)) for n, r in sections["resonator"].items())
    }
    glues = {
        name: Glue(
            name, r["youngs_modulus"], r["density"], r["poisson_ratio"], typical_thickness=r["typical_thickness"],
            source=r["source"],
        )
        for name, r in ((n, _checked("glue", n, r, origin)) for n, r in sections["glue"].items())
    }
    ceramics, isotropic = {}, {}
    for name, record in sections["ceramic"].items():
        if isinstance(record, dict) and "permittivity_from" in record:
            isotropic[name] = _checked("paper ceramic", name, record, origin)
            continue
        r = _checked("ceramic", name, record, origin)
        stiffness = transversely_isotropic_stiffness(*(r[key] for key in ("c11", "c12", "c13", "c33", "c44", "c66")))
        piezo = np.zeros((3, 6))
        piezo[2, :3] = r["e31"], r["e31"], r["e33"]
        piezo[0, 4] = piezo[1, 3] = r["e15"]
        permittivity = VACUUM_PERMITTIVITY * np.diag([r["relative_eps_s11"], r["relative_eps_s11"], r["relative_eps_s33"]])
        try:
            ceramics[name] = PiezoMaterial.from_tensors(
                name, stiffness, piezo, permittivity, r["density"], r["mechanical_q"], r["source"]
            )
        except np.linalg.LinAlgError:
            raise InputFileError(f"{origin}: ceramic {name!r}: its elastic constants c11...c66 are singular") from None
    for name, r in isotropic.items():
        borrowed = ceramics.get(r["permittivity_from"])
        if borrowed is None:
            raise InputFileError(
                f"{origin}: ceramic {name!r}: field 'permittivity_from' must name a ceramic record with full "
                f"constants ({', '.join(ceramics) or 'none'}), got {r['permittivity_from']!r}"
            )
        ceramics[name] = PiezoMaterial.isotropic(
            name, r["youngs_modulus"], r["poisson_ratio"], r["density"], r["d31"], r["e31"], r["mechanical_q"],
            borrowed.permittivity_matrix(), r["source"],
        )
    ordered = {name: ceramics[name] for name in sections["ceramic"]}
    return {"ceramic": ordered, "resonator": resonators, "glue": glues}


@cache
def records() -> dict:
    """The package's material records (``materials.toml`` beside this module), parsed once."""
    text = resources.files(__package__).joinpath(RECORDS_FILE).read_text(encoding="utf-8")
    return parse_records(text)


def _lookup(kind: str, name: str):
    found = records()[kind]
    if name not in found:
        raise TactileError(f"unknown {kind} {name!r}; choose one of {', '.join(found)}")
    return found[name]


def ceramic(name: str) -> PiezoMaterial:
    """The ceramic record ``name`` (see :func:`ceramic_names`)."""
    return _lookup("ceramic", name)


def resonator(name: str) -> Material:
    """The resonator record ``name`` (see :func:`resonator_names`)."""
    return _lookup("resonator", name)


def glue(name: str) -> Glue:
    """The glue record ``name`` (see :func:`glue_names`)."""
    return _lookup("glue", name)


def ceramic_names() -> tuple:
    """Names of the ceramic records, in file order."""
    return tuple(records()["ceramic"])


def resonator_names() -> tuple:
    """Names of the resonator records, in file order."""
    return tuple(records()["resonator"])


def glue_names() -> tuple:
    """Names of the glue records, in file order."""
    return tuple(records()["glue"])


PAPER = "paper"
"""Name of the paper's records (Table 1)."""

COPPER_BERYLLIUM = resonator(PAPER)
"""The resonator (Table 1)."""

PZT = ceramic(PAPER)
"""The piezo-ceramic strips (Table 1)."""

EPOXY = glue("epoxy")
"""The default bond: a structural epoxy (docs/model.md); used where a plate has a glue thickness."""

N_CERAMICS = 7
"""Ceramics along x [-]."""
CERAMIC_GAP = 1.0e-3
"""Gap between neighbouring ceramics, delta [m]."""

WAVELENGTH_RANGE = (15e-3, 40e-3)
"""Bounds on the flexural wavelength lambda [m]."""
RESONATOR_THICKNESS_RANGE = (0.2e-3, 3e-3)
"""Bounds on the resonator thickness h_i [m]."""
PRACTICAL_MIN_RESONATOR_THICKNESS = 0.5e-3
"""Practical lower limit on h_i [m] (the optimiser's default lower bound)."""
WIDTH_RANGE = (30e-3, 100e-3)
"""Bounds on the width b [m] (resonator = ceramics)."""
CERAMIC_THICKNESSES = (0.5e-3, 1.0e-3, 2.0e-3)
"""Commercial ceramic thicknesses h_p [m] (discrete)."""

PLATE_Q = 54.0
"""Quality factor measured on the original plate [-], used for design with constant Q."""
MIN_FREQUENCY = 25e3
"""Lowest acceptable working frequency [Hz] (above hearing, squeeze film works)."""
DESIGN_VOLTAGE = 15.0
"""Safe design drive amplitude across the ceramics [V peak]."""
TARGET_DEFLECTION = 1.15e-6
"""Nominal antinode deflection amplitude [m]."""
MIN_USEFUL_DEFLECTION = 0.3e-6
"""Deflection amplitude below which friction reduction is not useful [m]."""
