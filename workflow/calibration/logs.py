"""Built-plate logs: a format-1 log whose metadata name the plate, and the resonance it measured.

Metadata (docs/log-format.md): ``# lambda_mm``, ``# h_i_mm``, ``# h_p_mm``, ``# b_mm`` (required
here), ``# ceramic``, ``# resonator`` (material record names), ``# glue_um`` (optional).  The
rows are a resonance sweep (or several): the measured f_r is the velocity peak of each sweep,
refined by a parabola through ln v at the three highest points, and the median over sweeps.
The deflection per volt comes from the lowest-drive sweep that resolves its resonance
(:func:`~workflow.resonance.lorentzian_top`), mapped onto the antinode when the
log names a measurement point off it; a log whose ``# amplitude: synthesised`` says its velocities
are not measured amplitudes (the published plates' logs) has none.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workflow.damping.logs import read_log
from workflow.errors import InputFileError, TactileError
from workflow.logformat import read_metadata
from workflow.models.builtplate import BuiltPlate
from workflow.models.plate import Plate
from workflow.resonance import log_parabolic_peak_frequency, lorentzian_top

SYNTHESISED_AMPLITUDE = ("amplitude", "synthesised")
"""Metadata item of a log whose velocity amplitudes are made up around a published frequency (no deflection per volt)."""


@dataclass(frozen=True)
class BuiltPlateLog:
    """What one built-plate log says.

    Attributes
    ----------
    source : str
        The file.
    plate : Plate
        Nominal plate named by the metadata [m].
    frequency : float
        Measured resonance frequency: median peak of the finest-spaced sweeps [Hz].
    sweep_frequencies : tuple of float
        Peak frequency of each sweep with a peak inside its range [Hz].
    deflection_per_volt : float or None
        Quasi-static antinode deflection per volt from the lowest-drive sweep [m/V] (None: no sweep
        resolves its resonance's width).
    """

    source: str
    plate: Plate
    frequency: float
    sweep_frequencies: tuple
    deflection_per_volt: float | None = None


def read_built_plate(path) -> BuiltPlateLog:
    """Read a built-plate log: nominal plate from the metadata, measured f_r from the sweeps.

    f_r is the median of the peaks of the finest-spaced sweeps (a resonance search's fine sweep, not its
    coarse one; every sweep of a campaign with equal spacing).

    Raises
    ------
    InputFileError
        A missing or non-numeric geometry key, an unknown material record, a geometry the
        plate model refuses, a peak at the edge of every sweep, or any error of the log itself.
    """
    path = Path(path)
    try:
        metadata = read_metadata(path)
        plate = BuiltPlate.from_metadata(metadata, str(path)).plate()
    except TactileError as error:
        raise InputFileError(str(error) if str(path) in str(error) else f"{path}: {error}") from None
    log = read_log(path)
    sweeps = [(log.frequency[log.sweep == k], log.velocity[log.sweep == k]) for k in range(log.n_sweeps)]
    located = [(frequency_step(f), log_parabolic_peak_frequency(f, v)) for f, v in sweeps]
    located = [(step, peak) for step, peak in located if peak is not None]
    if not located:
        raise InputFileError(f"{path}: no sweep has its velocity peak inside the swept range; cannot locate f_r")
    finest = min(step for step, _ in located)
    peaks = [peak for step, peak in located if step <= 1.01 * finest]
    key, value = SYNTHESISED_AMPLITUDE
    synthesised = metadata.get(key, ("",))[0].strip() == value
    return BuiltPlateLog(str(path), plate, float(np.median(peaks)), tuple(peak for _, peak in located),
                         None if synthesised else lowest_drive_deflection(log))


def lowest_drive_deflection(log) -> float | None:
    """Deflection per volt [m/V] of the lowest-drive sweep whose top the Lorentzian (:func:`lorentzian_top`) resolves
    (finest spacing first among equal drives), or None.

    The velocity is divided by the mode factor |phi| of the log's measurement point (1 without one).
    """
    candidates = []
    for k in range(log.n_sweeps):
        rows = log.sweep == k
        factor = 1.0 if log.mode_factor is None else float(np.median(log.mode_factor[rows]))
        fit = lorentzian_top(log.frequency[rows], log.velocity[rows] / factor)
        voltage = float(np.median(log.drive_voltage[rows]))
        if fit is not None and voltage > 0:
            candidates.append((voltage, frequency_step(log.frequency[rows]), fit))
    if not candidates:
        return None
    voltage, _, fit = min(candidates, key=lambda c: c[:2])
    return fit.deflection_per_volt(voltage)


def frequency_step(frequency: np.ndarray) -> float:
    """Median spacing of a sweep's frequencies [Hz] (a resonance search's coarse sweep is much wider-spaced)."""
    spacing = np.diff(np.sort(frequency))
    return float(np.median(spacing)) if spacing.size else np.inf
