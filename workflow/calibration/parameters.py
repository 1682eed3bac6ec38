"""The uncertain model parameters of a built plate, their priors, and the plate they describe.

Known parameters (docs/calibration.md):

* ``ceramic_modulus_factor`` [-]: factor on the ceramic's c^E and e (d31 = e s^E is kept);
* ``resonator_modulus_factor`` [-]: factor on the resonator's Young's modulus;
* ``glue_modulus_factor`` [-]: factor on the bond's Young's modulus (off by default);
* ``glue_um`` [m inside, um in files]: the epoxy bond under each ceramic;
* ``resonator_offset_um`` [m inside, um in files]: resonator thickness minus its nominal value.

Values are SI inside (a vector ``theta`` in the order of :attr:`CalibrationSettings.names`);
micrometres appear only in the settings file and in reports (:attr:`Parameter.display_scale`).
"""

import math
import sys
from dataclasses import dataclass
from importlib import resources

import numpy as np
from scipy import stats

from workflow.errors import InputFileError
from workflow.inputfiles import load_toml
from workflow.models.builtplate import scaled_ceramic, scaled_material
from workflow.models.plate import Plate
from workflow.units import UM

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

DEFAULTS_FILE = "calibration.toml"
"""Default settings, package data beside this module."""

LENGTHS = ("glue_um", "resonator_offset_um")
"""Parameters that are lengths: micrometres in files, metres inside."""
FACTORS = ("ceramic_modulus_factor", "resonator_modulus_factor", "glue_modulus_factor")
"""Parameters that are dimensionless factors on a modulus."""
PRIORS = ("normal", "uniform")


@dataclass(frozen=True)
class Parameter:
    """One calibrated parameter and its prior.

    Attributes
    ----------
    name : str
        One of :data:`FACTORS` or :data:`LENGTHS`.
    prior : str
        "normal" (truncated to [low, high]) or "uniform".
    low, high : float
        Support of the prior, and the box the surrogate is built on [SI].
    mean, sigma : float
        Normal prior's centre and standard deviation [SI] (uniform: its mean and standard deviation).
    description : str
    """

    name: str
    prior: str
    low: float
    high: float
    mean: float
    sigma: float
    description: str = ""

    @property
    def display_scale(self) -> float:
        """SI value per display unit (1e-6 for the lengths shown in um, 1 for factors)."""
        return UM if self.name in LENGTHS else 1.0

    @property
    def unit(self) -> str:
        return "um" if self.name in LENGTHS else "-"

    def log_prior(self, value) -> np.ndarray:
        """Log prior density up to a constant; -inf outside [low, high] (vectorised)."""
        value = np.asarray(value, dtype=float)
        inside = (value >= self.low) & (value <= self.high)
        density = -0.5 * ((value - self.mean) / self.sigma) ** 2 if self.prior == "normal" else np.zeros_like(value)
        return np.where(inside, density, -np.inf)

    def draw(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` draws from the prior [SI]."""
        if self.prior == "uniform":
            return rng.uniform(self.low, self.high, n)
        a, b = (self.low - self.mean) / self.sigma, (self.high - self.mean) / self.sigma
        return stats.truncnorm.rvs(a, b, loc=self.mean, scale=self.sigma, size=n, random_state=rng)


@dataclass(frozen=True)
class CalibrationSettings:
    """Priors, likelihood, surrogate and sampler settings of a calibration.

    Attributes
    ----------
    parameters : tuple of Parameter
    measurement_sigma : float
        Relative standard deviation of a measured resonance frequency [-].
    deflection_sigma : float
        Relative standard deviation of a measured deflection per volt per Q [-].
    shape_sigma : float
        Noise floor of a scan's pattern value (patterns have a root mean square of 1) [-].
    surrogate_points, surrogate_degree : int
        FEM evaluations of each surrogate's design and the polynomial degree (1 or 2) [-].
    surrogate_seed, sampler_seed : int
    walkers, steps, kept_samples : int
    """

    parameters: tuple
    measurement_sigma: float = 0.002
    deflection_sigma: float = 0.05
    shape_sigma: float = 0.03
    surrogate_points: int = 24
    surrogate_degree: int = 2
    surrogate_seed: int = 1
    walkers: int = 32
    steps: int = 4000
    sampler_seed: int = 2
    kept_samples: int = 4000

    @property
    def names(self) -> tuple:
        return tuple(p.name for p in self.parameters)

    @property
    def bounds(self) -> np.ndarray:
        """(n, 2) box [low, high] of the parameters [SI]."""
        return np.array([(p.low, p.high) for p in self.parameters])

    def log_prior(self, theta) -> np.ndarray:
        """Joint log prior of ``theta`` (..., n) [SI] up to a constant."""
        theta = np.asarray(theta, dtype=float)
        return sum(p.log_prior(theta[..., k]) for k, p in enumerate(self.parameters))

    def prior_scale(self) -> tuple[np.ndarray, np.ndarray]:
        """Prior mean and standard deviation of each parameter [SI] (to standardise directions)."""
        return np.array([p.mean for p in self.parameters]), np.array([p.sigma for p in self.parameters])


def deviated_plate(plate: Plate, names, theta) -> Plate:
    """The nominal ``plate`` with the parameter values ``theta`` [SI] applied.

    Parameters
    ----------
    plate : Plate
        Nominal scalar plate [m].
    names : sequence of str
        Parameter names (:data:`FACTORS`, :data:`LENGTHS`), in the order of ``theta``.
    theta : sequence of float
        Values [SI]: factors [-], glue thickness and resonator offset [m].
    """
    changes = {}
    for name, value in zip(names, (float(v) for v in theta)):
        if name == "ceramic_modulus_factor":
            changes["ceramic"] = plate.ceramic if value == 1.0 else scaled_ceramic(plate.ceramic, value)
        elif name == "resonator_modulus_factor":
            changes["resonator"] = scaled_material(plate.resonator, value)
        elif name == "glue_modulus_factor":
            changes["glue"] = scaled_material(plate.glue, value)
        elif name == "glue_um":
            changes["glue_thickness"] = max(value, 0.0)
        elif name == "resonator_offset_um":
            changes["resonator_thickness"] = float(plate.resonator_thickness) + value
        else:
            raise InputFileError(f"unknown calibration parameter {name!r}; known: {', '.join(FACTORS + LENGTHS)}")
    return plate.with_(**changes)


def default_settings() -> CalibrationSettings:
    """The package's defaults (``calibration.toml`` beside this module)."""
    text = resources.files(__package__).joinpath(DEFAULTS_FILE).read_text(encoding="utf-8")
    return parse_settings(tomllib.loads(text), DEFAULTS_FILE)


def load_settings(path=None) -> CalibrationSettings:
    """The defaults, overridden by the TOML file ``path`` if given (see :func:`parse_settings`)."""
    if path is None:
        return default_settings()
    user = load_toml(path, str(path))
    defaults = tomllib.loads(resources.files(__package__).joinpath(DEFAULTS_FILE).read_text(encoding="utf-8"))
    unknown = sorted(set(user) - set(defaults))
    if unknown:
        raise InputFileError(f"{path}: unknown section {unknown[0]!r}; expected {', '.join(defaults)}")
    merged = {key: dict(value) for key, value in defaults.items()}
    for section, table in user.items():
        if not isinstance(table, dict):
            raise InputFileError(f"{path}: [{section}] must be a table")
        merged[section] = dict(table) if section == "parameter" else {**merged[section], **table}
    return parse_settings(merged, str(path))


def parse_settings(data: dict, origin: str) -> CalibrationSettings:
    """Settings from the parsed TOML tables; raises :class:`InputFileError` naming ``origin`` and the key."""
    parameters = tuple(_parameter(name, record, origin) for name, record in data.get("parameter", {}).items())
    if not parameters:
        raise InputFileError(f"{origin}: no [parameter.NAME] table: nothing to calibrate")
    numbers = {
        ("likelihood", "measurement_sigma"): (float, 1e-6, 0.5),
        ("likelihood", "deflection_sigma"): (float, 1e-4, 2.0),
        ("likelihood", "shape_sigma"): (float, 1e-4, 2.0),
        ("surrogate", "points"): (int, 3, 10_000),
        ("surrogate", "degree"): (int, 1, 2),
        ("surrogate", "seed"): (int, 0, 2**32 - 1),
        ("sampler", "walkers"): (int, 4, 10_000),
        ("sampler", "steps"): (int, 10, 10_000_000),
        ("sampler", "seed"): (int, 0, 2**32 - 1),
        ("sampler", "kept_samples"): (int, 10, 1_000_000),
    }
    values = {}
    for (section, key), (kind, low, high) in numbers.items():
        table = data.get(section, {})
        unknown = sorted(set(table) - {k for s, k in numbers if s == section})
        if unknown:
            raise InputFileError(f"{origin}: [{section}] has an unknown key {unknown[0]!r}")
        value = table.get(key)
        valid = isinstance(value, (int, float)) and not isinstance(value, bool) and (kind is float or isinstance(value, int))
        if not valid or not (math.isfinite(value) and low <= value <= high):
            raise InputFileError(f"{origin}: [{section}] {key} must be {'an integer' if kind is int else 'a number'} "
                                 f"from {low:g} to {high:g}, got {value!r}")
        values[(section, key)] = kind(value)
    settings = CalibrationSettings(
        parameters=parameters,
        measurement_sigma=values[("likelihood", "measurement_sigma")],
        deflection_sigma=values[("likelihood", "deflection_sigma")],
        shape_sigma=values[("likelihood", "shape_sigma")],
        surrogate_points=values[("surrogate", "points")],
        surrogate_degree=values[("surrogate", "degree")],
        surrogate_seed=values[("surrogate", "seed")],
        walkers=values[("sampler", "walkers")],
        steps=values[("sampler", "steps")],
        sampler_seed=values[("sampler", "seed")],
        kept_samples=values[("sampler", "kept_samples")],
    )
    if settings.walkers < 2 * len(parameters):
        raise InputFileError(f"{origin}: [sampler] walkers must be at least twice the {len(parameters)} parameters")
    return settings


def _parameter(name: str, record, origin: str) -> Parameter:
    where = f"{origin}: [parameter.{name}]"
    if name not in FACTORS + LENGTHS:
        raise InputFileError(f"{where}: unknown parameter; known: {', '.join(FACTORS + LENGTHS)}")
    if not isinstance(record, dict) or record.get("prior") not in PRIORS:
        raise InputFileError(f"{where}: prior must be one of {', '.join(PRIORS)}")
    needed = ("low", "high") + (("mean", "sigma") if record["prior"] == "normal" else ())
    unknown = sorted(set(record) - set(needed) - {"prior", "description"})
    if unknown:
        raise InputFileError(f"{where}: unknown key {unknown[0]!r}; expected prior, {', '.join(needed)}, description")
    for key in needed:
        value = record.get(key)
        if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)):
            raise InputFileError(f"{where}: {key} must be a number, got {value!r}")
    scale = UM if name in LENGTHS else 1.0
    low, high = record["low"] * scale, record["high"] * scale
    if not low < high:
        raise InputFileError(f"{where}: low must be below high")
    if name in FACTORS and low <= 0:
        raise InputFileError(f"{where}: a modulus factor must stay positive (low > 0)")
    if record["prior"] == "normal":
        mean, sigma = record["mean"] * scale, record["sigma"] * scale
        if not sigma > 0:
            raise InputFileError(f"{where}: sigma must be positive")
    else:
        mean, sigma = (low + high) / 2, (high - low) / math.sqrt(12)
    return Parameter(name, record["prior"], low, high, mean, sigma, str(record.get("description", "")))
