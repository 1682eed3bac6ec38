"""Cross-prediction between two measured plates: calibrate on one, predict the other, and the reverse."""

from dataclasses import dataclass

from workflow.calibration.calibration import MeasuredPlate, posterior_from, prior_surrogates
from workflow.calibration.parameters import CalibrationSettings
from workflow.calibration.plate_surrogate import DesignFem
from workflow.calibration.posterior import predictive_quantiles


@dataclass(frozen=True)
class CrossPrediction:
    """One direction of a cross-prediction: calibrated on one plate, the other predicted.

    Attributes
    ----------
    calibrated_on, predicted : str
        The two plates' names.
    measured : float
        The predicted plate's measured resonance [Hz].
    band : tuple of float
        Its predicted resonance, p05, p50, p95 [Hz].
    source_fit : float
        The calibrated plate's own posterior-median resonance [Hz].
    parameters : dict
        The calibration's posterior summary.
    evaluations : int
        FEM evaluations behind both plates' surrogates [-].
    """

    calibrated_on: str
    predicted: str
    measured: float
    band: tuple
    source_fit: float
    parameters: dict
    evaluations: int

    @property
    def inside(self) -> bool:
        """Whether the measurement lies within the 90 % band."""
        return bool(self.band[0] <= self.measured <= self.band[2])

    @property
    def error(self) -> float:
        """Predicted median over measured, minus 1 [-]."""
        return float(self.band[1] / self.measured - 1)


def cross_predictions(first: MeasuredPlate, second: MeasuredPlate, settings: CalibrationSettings,
                      design_fem: DesignFem | None, fem: dict, surrogates: tuple | None = None) -> list[CrossPrediction]:
    """Calibrate on each plate alone and predict the other's resonance, with 90 % intervals.

    Parameters
    ----------
    first, second : MeasuredPlate
        The plates and their measured frequencies [Hz] (data, e.g. read from logs).
    settings : CalibrationSettings
    design_fem : DesignFem or None
        How the surrogates' designs are evaluated (None with ``surrogates``).
    fem : dict
        The FEM conditions ``design_fem`` binds.
    surrogates : tuple of PlateSurrogate, optional
        The two plates' prior surrogates when already built with these settings and FEM (no evaluation then).

    Returns
    -------
    list of CrossPrediction
        One per direction: calibrated on ``first``, then on ``second``.
    """
    surrogates = surrogates or prior_surrogates([first.plate, second.plate], settings, design_fem)
    directions = []
    for (source, source_surrogate), (target, target_surrogate) in (
        ((first, surrogates[0]), (second, surrogates[1])),
        ((second, surrogates[1]), (first, surrogates[0])),
    ):
        calibration = posterior_from([source], [source_surrogate], settings, fem)
        predicted = predictive_quantiles(target_surrogate, calibration.samples, calibration.discrepancy)["frequency"]
        directions.append(CrossPrediction(
            calibrated_on=source.name,
            predicted=target.name,
            measured=target.frequency,
            band=tuple(float(x) for x in predicted),
            source_fit=float(predictive_quantiles(source_surrogate, calibration.samples,
                                                  calibration.discrepancy)["frequency"][1]),
            parameters=calibration.summary(),
            evaluations=sum(s.evaluations for s in surrogates),
        ))
    return directions
