"""Cross-prediction between two measured plates: calibrate on one, predict the other, and the reverse."""

from workflow.calibration.calibration import MeasuredPlate, posterior_from, prior_surrogates
from workflow.calibration.parameters import CalibrationSettings
from workflow.calibration.plate_surrogate import DesignFem
from workflow.calibration.posterior import predictive_quantiles


def cross_predictions(first: MeasuredPlate, second: MeasuredPlate, settings: CalibrationSettings,
                      design_fem: DesignFem | None, fem: dict, surrogates: tuple | None = None) -> list[dict]:
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
    list of dict
        One per direction: ``calibrated_on``, ``predicted``, ``measured_hz``, ``predicted_hz``
        (p05, p50, p95) [Hz], ``inside`` (the measurement within the 90 % interval),
        ``error`` (median over measured - 1) [-], ``source_fit_hz`` (the calibrated plate's own
        posterior median) [Hz], ``parameters`` (posterior summary), ``evaluations`` (FEM, both surrogates).
    """
    surrogates = surrogates or prior_surrogates([first.plate, second.plate], settings, design_fem)
    directions = []
    for (source, source_surrogate), (target, target_surrogate) in (
        ((first, surrogates[0]), (second, surrogates[1])),
        ((second, surrogates[1]), (first, surrogates[0])),
    ):
        calibration = posterior_from([source], [source_surrogate], settings, fem)
        predicted = predictive_quantiles(target_surrogate, calibration.samples, calibration.discrepancy)["frequency"]
        directions.append({
            "calibrated_on": source.name,
            "predicted": target.name,
            "measured_hz": target.frequency,
            "predicted_hz": tuple(float(x) for x in predicted),
            "inside": bool(predicted[0] <= target.frequency <= predicted[2]),
            "error": float(predicted[1] / target.frequency - 1),
            "source_fit_hz": float(predictive_quantiles(source_surrogate, calibration.samples,
                                                        calibration.discrepancy)["frequency"][1]),
            "parameters": calibration.summary(),
            "evaluations": sum(s.evaluations for s in surrogates),
        })
    return directions
