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
from workflow.models.limits import problem
from workflow.models.builtplate import scaled_ceramic, scaled_material
from workflow.models.plate import Plate
from workflow.units import UM

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

DEFAULTS_FILE = "calibration.toml"
"""Default settings, package data beside this module."""

DISCREPANCIES = ("frequency", "deflection")
"""The model-discrepancy terms sampled beside the parameters, in this order (:attr:`CalibrationSettings.discrepancy_scales`)."""
LENGTHS = ("glue_um", "resonator_offset_um")
"""Parameters that are lengths: micrometres in files, metres inside."""
FACTORS = ("ceramic_modulus_factor", "resonator_modulus_factor", "glue_modulus_factor")
"""Parameters that are dimensionless factors on a modulus."""
PRIORS = ("normal", "uniform")
PLAUSIBLE = {"ceramic_modulus_factor": "modulus_factor", "resonator_modulus_factor": "modulus_factor",
             "glue_modulus_factor": "modulus_factor", "glue_um": "glue_um", "resonator_offset_um": "hi_offset_um"}
"""Parameter -> its quantity in :data:`~workflow.models.limits.LIMITS`: a prior's support must lie inside."""
SETTINGS_NUMBERS = {
    ("likelihood", "measurement_sigma"): ("measurement_sigma", float, 1e-6, 0.5),
    ("likelihood", "deflection_sigma"): ("deflection_sigma", float, 1e-4, 2.0),
    ("likelihood", "shape_sigma"): ("shape_sigma", float, 1e-4, 2.0),
    ("surrogate", "points"): ("surrogate_points", int, 3, 10_000),
    ("surrogate", "degree"): ("surrogate_degree", int, 1, 2),
    ("surrogate", "seed"): ("surrogate_seed", int, 0, 2**32 - 1),
    ("sampler", "walkers"): ("walkers", int, 4, 10_000),
    ("sampler", "steps"): ("steps", int, 10, 10_000_000),
    ("sampler", "seed"): ("sampler_seed", int, 0, 2**32 - 1),
    ("sampler", "kept_samples"): ("kept_samples", int, 10, 100_000),
    ("discrepancy", "frequency"): ("frequency_discrepancy", float, 0.0, 0.5),
    ("discrepancy", "deflection"): ("deflection_discrepancy", float, 0.0, 2.0),
}
"""(TOML table, key) -> (:class:`CalibrationSettings` field, type, lowest, highest accepted value); at most 100 000
kept samples keep ``calibration.json`` within :data:`~workflow.inputfiles.MAX_CALIBRATION_BYTES`."""


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

    def check(self, where: str) -> "Parameter":
        """This parameter, or :class:`InputFileError` naming ``where``: an unknown name or prior, a bound or moment
        that is not a finite number, low not below high, sigma not positive, or a support outside the quantity's
        plausible range (:data:`PLAUSIBLE`)."""
        if self.name not in PLAUSIBLE:
            raise InputFileError(f"{where}: unknown parameter {self.name!r}; known: {', '.join(FACTORS + LENGTHS)}")
        if self.prior not in PRIORS:
            raise InputFileError(f"{where}: prior must be one of {', '.join(PRIORS)}, got {self.prior!r}")
        for key in ("low", "high", "mean", "sigma"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)):
                raise InputFileError(f"{where}: {key} must be a number, got {value!r}")
        if not self.low < self.high:
            raise InputFileError(f"{where}: low must be below high")
        if not self.sigma > 0:
            raise InputFileError(f"{where}: sigma must be positive")
        for bound in (self.low, self.high):
            reason = problem(PLAUSIBLE[self.name], bound, si=True, name=f"a bound of {self.name}")
            if reason:
                raise InputFileError(f"{where}: {reason}")
        return self

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
        Walkers, the chain's step cap (it stops earlier once converged) and the draws kept [-].
    frequency_discrepancy, deflection_discrepancy : float
        Scales of the half-normal priors of the model-discrepancy terms: the relative standard deviation by which a
        built plate's ln f_r and ln g may differ from the FEM at every value of the parameters (what the parameters
        do not span), added in quadrature to the measurement's (:mod:`workflow.calibration.posterior`) [-]; 0: none.
    """

    parameters: tuple
    measurement_sigma: float = 0.002
    deflection_sigma: float = 0.05
    shape_sigma: float = 0.03
    surrogate_points: int = 24
    surrogate_degree: int = 2
    surrogate_seed: int = 1
    walkers: int = 32
    steps: int = 10000
    sampler_seed: int = 2
    kept_samples: int = 4000
    frequency_discrepancy: float = 0.01
    deflection_discrepancy: float = 0.1

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

    @property
    def discrepancy_scales(self) -> np.ndarray:
        """Prior scales of the :data:`DISCREPANCIES` terms, relative [-]."""
        return np.array([self.frequency_discrepancy, self.deflection_discrepancy])

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
    values = {}
    for (section, key), (field, kind, low, high) in SETTINGS_NUMBERS.items():
        table = data.get(section, {})
        unknown = sorted(set(table) - {k for s, k in SETTINGS_NUMBERS if s == section})
        if unknown:
            raise InputFileError(f"{origin}: [{section}] has an unknown key {unknown[0]!r}")
        values[field] = _setting(table.get(key), kind, low, high, f"{origin}: [{section}] {key}")
    return checked_settings(CalibrationSettings(parameters=parameters, **values), origin)


def _setting(value, kind, low, high, where: str):
    """``value`` as ``kind`` if it is a number of that kind in [low, high], else :class:`InputFileError` naming ``where``."""
    valid = isinstance(value, (int, float)) and not isinstance(value, bool) and (kind is float or isinstance(value, int))
    if not valid or not (math.isfinite(value) and low <= value <= high):
        raise InputFileError(f"{where} must be {'an integer' if kind is int else 'a number'} from {low:g} to {high:g}, "
                             f"got {value!r}")
    return kind(value)


def checked_settings(settings: CalibrationSettings, origin: str) -> CalibrationSettings:
    """``settings`` with every parameter checked (:meth:`Parameter.check`), at least one of them, each number in its
    range (:data:`SETTINGS_NUMBERS`) and enough walkers; else :class:`InputFileError` naming ``origin``."""
    if not settings.parameters:
        raise InputFileError(f"{origin}: no parameter to calibrate")
    for parameter in settings.parameters:
        parameter.check(f"{origin}: parameter {parameter.name}")
    for field, kind, low, high in SETTINGS_NUMBERS.values():
        _setting(getattr(settings, field), kind, low, high, f"{origin}: {field}")
    dimension = len(settings.parameters) + len(DISCREPANCIES)
    if settings.walkers < 2 * dimension:
        raise InputFileError(f"{origin}: [sampler] walkers must be at least twice the {len(settings.parameters)} parameters "
                             f"and {len(DISCREPANCIES)} discrepancy terms sampled ({2 * dimension})")
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
    if record["prior"] == "normal":
        mean, sigma = record["mean"] * scale, record["sigma"] * scale
    else:
        mean, sigma = (low + high) / 2, (high - low) / math.sqrt(12)
    return Parameter(name, record["prior"], low, high, mean, sigma, str(record.get("description", ""))).check(where)
