"""A calibration: surrogates of the built plates, the posterior, and predictions for other plates.

Pure given a :class:`~workflow.calibration.plate_surrogate.DesignFem` (how a surrogate's design is evaluated; the
caller binds Q, voltage, FEM accuracy and the cache).  :class:`Calibration` converts to and from plain data (the
``calibration.json`` that ``--calibration`` reads: no code, no pickle).
"""

from dataclasses import asdict, dataclass, replace
from typing import Sequence

import numpy as np

from workflow.calibration.logs import BuiltPlateLog
from workflow.calibration.measurements import ScanShape
from workflow.calibration.parameters import DISCREPANCIES, CalibrationSettings, Parameter, checked_settings
from workflow.calibration.plate_surrogate import (
    DesignFem,
    PlateSurrogate,
    build_plate_surrogate,
    fit_plate_surrogate,
    surrogate_design,
)
from workflow.calibration.posterior import (
    calibration_data,
    identifiability,
    parameter_summary,
    predictive_check,
    predictive_quantiles,
    prior_bounds,
    sample_posterior,
)
from workflow.errors import InputFileError, TactileError
from workflow.models import materials
from workflow.models.fem.settings import PIEZO_MODELS
from workflow.models.limits import LIMITS, plate_problem, problem
from workflow.sampling import ChainDiagnostics
from workflow.models.plate import Plate

FORMAT = "tactile-calibration"
VERSION = 2
"""Version written; version 1 (before the model-discrepancy terms) is still read, its discrepancy zero."""
READ_VERSIONS = (1, 2)
PREDICTION_DEGREE = 1
"""Degree of the surrogate built at a new geometry over the posterior's range (narrow: linear suffices, its
leave-one-out error says how well)."""
POSTERIOR_RANGE = (0.5, 99.5)
"""Percentiles of the posterior that bound a prediction surrogate's box [%]."""


def prediction_points(n_parameters: int) -> int:
    """FEM evaluations of a prediction surrogate: twice the linear basis plus two [-]."""
    return 2 * (n_parameters + 1) + 2


@dataclass(frozen=True)
class MeasuredPlate:
    """A nominal plate and what its logs measured.

    Attributes
    ----------
    name : str
        Where the measurement comes from (a log file, a label).
    plate : Plate
        Nominal plate [m].
    frequency : float
        Measured resonance frequency [Hz].
    deflection_per_volt : float or None
        Measured quasi-static antinode deflection per volt (peak over V Q) [m/V]; None: not used.
    scan : ScanShape or None
        Measured mode pattern of a deflection scan; None: no scan.
    """

    name: str
    plate: Plate
    frequency: float
    deflection_per_volt: float | None = None
    scan: ScanShape | None = None

    @property
    def data_used(self) -> list:
        """The measured quantities the likelihood uses for this plate."""
        return (["resonance frequency"] + (["deflection per volt"] if self.deflection_per_volt is not None else [])
                + (["scan mode shape"] if self.scan is not None else []))

    def to_dict(self) -> dict:
        return {"name": self.name, "plate": plate_record(self.plate), "frequency_hz": self.frequency,
                "deflection_per_volt_m_v": self.deflection_per_volt,
                "scan": None if self.scan is None else self.scan.to_dict(), "data_used": self.data_used}

    def checked(self, where: str) -> "MeasuredPlate":
        """This plate, or :class:`InputFileError` naming ``where``: an implausible geometry (:func:`plate_problem`),
        resonance frequency or deflection per volt."""
        reason = plate_problem(self.plate) or problem("frequency_hz", self.frequency, name="frequency_hz")
        if reason is None and self.deflection_per_volt is not None and not 0 < self.deflection_per_volt < 1e-3:
            reason = f"deflection_per_volt_m_v = {self.deflection_per_volt:g} is not a deflection per volt [m/V]"
        if reason:
            raise InputFileError(f"{where}: {reason}")
        return self

    @classmethod
    def from_dict(cls, data: dict) -> "MeasuredPlate":
        deflection, scan = data.get("deflection_per_volt_m_v"), data.get("scan")
        return cls(data["name"], plate_from_record(data["plate"]), float(data["frequency_hz"]),
                   None if deflection is None else float(deflection), None if scan is None else ScanShape.from_dict(scan))


def measured_plate(log: BuiltPlateLog, scan: ScanShape | None = None, use_deflection: bool = True) -> MeasuredPlate:
    """The measurements of a built-plate log (its deflection per volt when it has one and ``use_deflection``)."""
    return MeasuredPlate(log.source, log.plate, log.frequency, log.deflection_per_volt if use_deflection else None, scan)


@dataclass(frozen=True, eq=False)
class Calibration:
    """The posterior of a calibration and everything needed to use it.

    Attributes
    ----------
    settings : CalibrationSettings
    samples : numpy.ndarray
        (n, n_parameters) posterior samples [SI].
    plates : tuple of MeasuredPlate
    surrogates : tuple of PlateSurrogate
        One per plate, over the prior's box.
    diagnostics : ChainDiagnostics
    fem : dict
        FEM conditions of the surrogates: ``q`` [-], ``voltage_v`` [V], ``accuracy`` [-], ``piezo``.
    discrepancy : numpy.ndarray or None
        (n, 2) the model-discrepancy terms at the samples, relative sds of ln f_r and ln g [-]
        (:mod:`workflow.calibration.posterior`); None (a calibration file of version 1) stands for zeros.
    """

    settings: CalibrationSettings
    samples: np.ndarray
    plates: tuple
    surrogates: tuple
    diagnostics: ChainDiagnostics
    fem: dict
    discrepancy: np.ndarray | None = None

    def __post_init__(self):
        if self.discrepancy is None:
            object.__setattr__(self, "discrepancy", np.zeros((len(self.samples), len(DISCREPANCIES))))

    @property
    def evaluations(self) -> int:
        """FEM evaluations of the surrogates [-]."""
        return sum(s.evaluations for s in self.surrogates)

    def summary(self) -> dict:
        """name -> {median, p05, p95, unit} (factors [-], lengths [um])."""
        return parameter_summary(self.settings, self.samples)

    def identifiability(self) -> dict:
        return identifiability(self.settings, self.samples)

    def at_prior_bounds(self) -> dict:
        """Parameters whose posterior sits at a prior bound: name -> "at lower/upper prior bound"."""
        return prior_bounds(self.settings, self.samples)

    def check(self) -> dict:
        """The posterior-predictive check of the calibration plates and the discrepancy terms
        (:func:`~workflow.calibration.posterior.predictive_check`)."""
        data = calibration_data(self.settings, self.surrogates, [p.frequency for p in self.plates],
                                [p.deflection_per_volt for p in self.plates], [p.scan for p in self.plates])
        return predictive_check(data, self.samples, self.discrepancy, [p.name for p in self.plates])

    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "settings": {**asdict(self.settings), "parameters": [asdict(p) for p in self.settings.parameters]},
            "names": list(self.settings.names),
            "samples": self.samples.tolist(),
            "plates": [p.to_dict() for p in self.plates],
            "surrogates": [s.to_dict() for s in self.surrogates],
            "diagnostics": self.diagnostics.to_dict(),
            "fem": dict(self.fem),
            "discrepancy": {"names": list(DISCREPANCIES), "samples": self.discrepancy.tolist()},
            "intervals": interval_contents(self.settings),
        }

    @classmethod
    def from_dict(cls, data: dict, origin: str = "calibration") -> "Calibration":
        """Inverse of :meth:`to_dict`, every value checked; raises :class:`InputFileError` naming ``origin`` and the
        field when it is not one (docs/calibration.md, "Using a calibration")."""
        if not isinstance(data, dict) or data.get("format") != FORMAT or data.get("version") not in READ_VERSIONS:
            raise InputFileError(f"{origin}: not a calibration file of 'tactile calibrate' ({FORMAT} version "
                                 f"{' or '.join(map(str, READ_VERSIONS))})")
        field = "settings"
        try:
            settings = dict(data["settings"])
            settings["parameters"] = tuple(Parameter(**p) for p in settings["parameters"])
            settings = checked_settings(CalibrationSettings(**settings), f"{origin}: settings")
            field = "samples"
            samples = _checked_samples(data["samples"], settings, origin)
            field = "plates"
            plates = tuple(MeasuredPlate.from_dict(p).checked(f"{origin}: plate {k}") for k, p in enumerate(data["plates"]))
            field = "surrogates"
            surrogates = tuple(PlateSurrogate.from_dict(s) for s in data["surrogates"])
            if len(surrogates) != len(plates) or any(s.names != settings.names for s in surrogates):
                raise ValueError(f"one surrogate of the parameters {', '.join(settings.names)} per plate")
            for k, surrogate in enumerate(surrogates):
                _check_predictions(surrogate, samples, f"{origin}: field 'surrogates': plate {k}")
            field = "diagnostics"
            diagnostics = ChainDiagnostics.from_dict(data["diagnostics"])
            field = "fem"
            fem = _checked_fem(data["fem"], origin)
            field = "discrepancy"
            discrepancy = None if data["version"] == 1 else _checked_discrepancy(data["discrepancy"], len(samples), origin)
        except InputFileError:
            raise
        except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError, TactileError) as error:
            raise InputFileError(f"{origin}: damaged calibration file, field '{field}' "
                                 f"({type(error).__name__}: {error})") from None
        if discrepancy is None:
            settings = replace(settings, frequency_discrepancy=0.0, deflection_discrepancy=0.0)
        return cls(settings, samples, plates, surrogates, diagnostics, fem, discrepancy)


def interval_contents(settings: CalibrationSettings) -> dict:
    """What a prediction's 90 % band (:func:`predict`) contains and what it does not (issue 29), in words; written into
    ``calibration.json`` beside the samples (read back: ignored, it follows from the settings)."""
    discrepancy = settings.frequency_discrepancy > 0 or settings.deflection_discrepancy > 0
    return {
        "contains": [
            "the posterior of the parameters " + ", ".join(settings.names) + " given the calibration plates' measurements "
            "and their noise",
            "the surrogate's error (leave-one-out) and the FEM's discretisation error",
            (f"the model discrepancy: how far a built plate may differ from the FEM at any value of the parameters "
             f"(prior scales {100 * settings.frequency_discrepancy:g} % in f_r, {100 * settings.deflection_discrepancy:g} % "
             "in the deflection; the plates raise it when the parameters cannot represent them)") if discrepancy else
            "no model discrepancy (switched off in the settings): only deviations the parameters span",
        ],
        "does_not_contain": [
            "manufacturing scatter of a new plate about the calibration plates' (the robust design adds it: its tolerances)",
            "the measurement noise of the new plate's own resonance search",
            "a plate built elsewhere, of other materials or by another process than the calibration plates",
            "Q(v): the predictions are at constant Q (the fit of Q(v) has its own band)",
        ],
    }


FEM_KEYS = {"q": "q", "voltage_v": "design.voltage_v", "accuracy": "fem_accuracy"}
"""Numeric keys of a calibration's ``fem`` record -> their range in :data:`~workflow.models.limits.LIMITS` (and ``piezo``)."""


def _checked_fem(record, origin: str) -> dict:
    """The ``fem`` record of a calibration file: Q, voltage, accuracy in range and a known piezo model."""
    if not isinstance(record, dict):
        raise InputFileError(f"{origin}: field 'fem' must be a table of {', '.join(FEM_KEYS)}, piezo")
    for key, quantity in FEM_KEYS.items():
        if key not in record:
            raise InputFileError(f"{origin}: field 'fem' has no '{key}' (the FEM conditions of the calibration)")
        value = record[key]
        reason = "is not a number" if not isinstance(value, (int, float)) or isinstance(value, bool) else problem(
            quantity, value, name=f"fem.{key}")
        if reason:
            raise InputFileError(f"{origin}: field 'fem': {reason if reason.startswith('fem.') else f'{key} {reason}'}")
    if record.get("piezo") not in PIEZO_MODELS:
        raise InputFileError(f"{origin}: field 'fem': piezo must be one of {', '.join(PIEZO_MODELS)}, got "
                             f"{record.get('piezo')!r}")
    return dict(record)


def _check_predictions(surrogate: PlateSurrogate, samples: np.ndarray, where: str) -> None:
    """Refuse a surrogate that predicts, at some posterior sample, a resonance outside the plausible frequencies
    or a deflection that is not a finite positive length (damaged coefficients)."""
    with np.errstate(over="ignore"):
        frequency, deflection = surrogate.frequency(samples), surrogate.deflection(samples)
    low, high = LIMITS["frequency_hz"]
    bad = ~((frequency >= low) & (frequency <= high))
    if bad.any():
        raise InputFileError(f"{where}: its surrogate predicts f_r = {frequency[bad][0]:g} Hz at a posterior sample, "
                             f"outside the plausible {low:g} to {high:g} Hz")
    if not np.all(np.isfinite(deflection) & (deflection > 0)):
        raise InputFileError(f"{where}: its surrogate predicts a deflection that is not a finite length")


def _checked_discrepancy(record, n_samples: int, origin: str) -> np.ndarray:
    """The discrepancy terms: a finite (n_samples, 2) table of relative sds within their plausible range."""
    if not isinstance(record, dict) or record.get("names") != list(DISCREPANCIES):
        raise InputFileError(f"{origin}: field 'discrepancy' must name the terms {', '.join(DISCREPANCIES)}")
    values = np.asarray(record["samples"], dtype=float)
    if values.shape != (n_samples, len(DISCREPANCIES)) or not np.all(np.isfinite(values)):
        raise InputFileError(f"{origin}: field 'discrepancy' must hold one finite row of {len(DISCREPANCIES)} terms per "
                             "posterior sample")
    if not np.all((values >= 0) & (values <= MAX_DISCREPANCY)):
        raise InputFileError(f"{origin}: field 'discrepancy': a relative sd outside 0 to {MAX_DISCREPANCY:g}")
    return values


MAX_DISCREPANCY = 10.0
"""Largest model-discrepancy term a calibration file may hold, as a relative sd [-] (the prior scales reach 2: five
of them)."""


def _checked_samples(values, settings: CalibrationSettings, origin: str) -> np.ndarray:
    """The posterior samples: a finite (n >= 1, n_parameters) table, each column within its parameter's prior."""
    samples = np.asarray(values, dtype=float)
    if samples.ndim != 2 or not len(samples) or samples.shape[1] != len(settings.parameters) or not np.all(np.isfinite(samples)):
        raise InputFileError(f"{origin}: field 'samples' must be a finite table with one column per parameter "
                             f"({', '.join(settings.names)})")
    for column, parameter in zip(samples.T, settings.parameters):
        outside = (column < parameter.low) | (column > parameter.high)
        if outside.any():
            value, unit = float(column[outside][0]) / parameter.display_scale, "" if parameter.unit == "-" else f" {parameter.unit}"
            raise InputFileError(
                f"{origin}: field 'samples': {parameter.name} = {value:g}{unit}, outside its prior "
                f"[{parameter.low / parameter.display_scale:g}, {parameter.high / parameter.display_scale:g}]{unit}")
    return samples


def plate_record(plate: Plate) -> dict:
    """A scalar plate as plain data (SI; materials by record name)."""
    return {
        "wavelength": float(plate.wavelength),
        "resonator_thickness": float(plate.resonator_thickness),
        "ceramic_thickness": float(plate.ceramic_thickness),
        "width": float(plate.width),
        "glue_thickness": float(plate.glue_thickness),
        "ceramic": plate.ceramic.name,
        "resonator": plate.resonator.name,
    }


def plate_from_record(record: dict) -> Plate:
    """Inverse of :func:`plate_record`."""
    fields = {key: float(record[key]) for key in ("wavelength", "resonator_thickness", "ceramic_thickness", "width", "glue_thickness")}
    return Plate(**fields, ceramic=materials.ceramic(record["ceramic"]), resonator=materials.resonator(record["resonator"]))


def nominal_theta(names: Sequence[str], plate: Plate) -> np.ndarray:
    """The parameter values of the nominal plate itself: factors 1, its own bond, no offset [SI]."""
    return np.array([float(plate.glue_thickness) if name == "glue_um" else 0.0 if name.endswith("offset_um") else 1.0
                     for name in names])


def prior_surrogates(plates: Sequence[Plate], settings: CalibrationSettings, fem: DesignFem,
                     scans: Sequence = ()) -> tuple:
    """A surrogate of each plate over the prior's box (the settings' design size, degree and seed), with the
    mode pattern at its scan's points where ``scans`` (one ScanShape or None per plate) has one; the designs of
    all plates are evaluated together (:meth:`DesignFem.values`), so that the workers of a pool stay busy across
    the plates."""
    scans = tuple(scans) or (None,) * len(plates)
    designs = [surrogate_design(plate, settings.names, settings.bounds, settings.surrogate_points,
                                settings.surrogate_seed, None if scan is None else (np.array(scan.x), np.array(scan.y)))
               for plate, scan in zip(plates, scans)]
    return tuple(fit_plate_surrogate(settings.names, design, settings.surrogate_degree, values)
                 for design, values in zip(designs, fem.values(designs)))


def posterior_from(plates: Sequence[MeasuredPlate], surrogates: Sequence[PlateSurrogate], settings: CalibrationSettings,
                   fem: dict) -> Calibration:
    """Sample the posterior given measured plates and their surrogates (no FEM evaluation)."""
    data = calibration_data(settings, surrogates, [p.frequency for p in plates], [p.deflection_per_volt for p in plates],
                            [p.scan for p in plates])
    samples, discrepancy, diagnostics = sample_posterior(data)
    return Calibration(settings, samples, tuple(plates), tuple(surrogates), diagnostics, dict(fem), discrepancy)


def calibrate(plates: Sequence[MeasuredPlate], settings: CalibrationSettings, design_fem: DesignFem,
              fem: dict) -> Calibration:
    """Surrogates of the measured plates, then the posterior of the parameters.

    Parameters
    ----------
    plates : sequence of MeasuredPlate
    settings : CalibrationSettings
    design_fem : DesignFem
        How the surrogates' designs are evaluated (with the top-face modes where a plate has a scan).
    fem : dict
        The FEM conditions ``design_fem`` binds (recorded with the calibration).
    """
    surrogates = prior_surrogates([p.plate for p in plates], settings, design_fem, [p.scan for p in plates])
    return posterior_from(plates, surrogates, settings, fem)


def prediction_surrogate(calibration: Calibration, plate: Plate, fem: DesignFem) -> PlateSurrogate:
    """A linear surrogate of ``plate`` over the posterior's central 99 % range of each parameter."""
    names = calibration.settings.names
    low, high = np.percentile(calibration.samples, POSTERIOR_RANGE, axis=0)
    span = np.maximum(high - low, 1e-3 * (calibration.settings.bounds[:, 1] - calibration.settings.bounds[:, 0]))
    bounds = np.stack([low, low + span], axis=1)
    return build_plate_surrogate(plate, names, bounds, fem, prediction_points(len(names)), PREDICTION_DEGREE,
                                 calibration.settings.surrogate_seed)


@dataclass(frozen=True)
class Prediction:
    """A plate's posterior-predictive resonance and deflection under a calibration.

    Attributes
    ----------
    plate : Plate
    frequency, deflection : numpy.ndarray
        p05, p50, p95 of f_r [Hz] and of the deflection at the calibration's Q and voltage [m].
    surrogate : PlateSurrogate
        The surrogate of the FEM the prediction went through (its leave-one-out error, its FEM evaluations).
    samples : int
        Posterior samples behind the quantiles [-].
    contents : dict
        What the 90 % band contains and what it does not (:func:`interval_contents`).
    """

    plate: Plate
    frequency: np.ndarray
    deflection: np.ndarray
    surrogate: PlateSurrogate
    samples: int
    contents: dict


def predict(calibration: Calibration, plate: Plate, fem: DesignFem | None,
            surrogate: PlateSurrogate | None = None) -> Prediction:
    """Posterior predictive f_r and w of a plate, through ``surrogate`` (default: a new one over the posterior's range,
    built with ``fem``)."""
    surrogate = surrogate or prediction_surrogate(calibration, plate, fem)
    quantiles = predictive_quantiles(surrogate, calibration.samples, calibration.discrepancy)
    return Prediction(plate, quantiles["frequency"], quantiles["deflection"], surrogate, len(calibration.samples),
                      interval_contents(calibration.settings))
