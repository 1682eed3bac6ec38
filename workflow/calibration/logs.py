"""Built-plate logs: a format-1 log whose metadata name the plate, and the resonance it measured.

Metadata (docs/log-format.md): ``# lambda_mm``, ``# h_i_mm``, ``# h_p_mm``, ``# b_mm`` (required
here), ``# ceramic``, ``# resonator`` (material record names), ``# glue_um`` (optional).  The
rows are a resonance sweep (or several): the measured f_r is the velocity peak of each sweep,
refined by a parabola through ln v at the three highest points, and the median over sweeps.
"""

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workflow.damping.logs import read_log
from workflow.errors import InputFileError, TactileError
from workflow.logformat import METADATA_PREFIX
from workflow.models import materials
from workflow.models.plate import Plate
from workflow.units import MM, UM

GEOMETRY_KEYS = {"lambda_mm": "wavelength", "h_i_mm": "resonator_thickness", "h_p_mm": "ceramic_thickness", "b_mm": "width"}
"""Required metadata and the Plate field each names (values in mm)."""


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
        Measured resonance frequency [Hz].
    sweep_frequencies : tuple of float
        Peak frequency of each sweep [Hz].
    """

    source: str
    plate: Plate
    frequency: float
    sweep_frequencies: tuple


def read_metadata(path) -> dict:
    """The ``# key: value`` lines before the header of a log, as strings (the title line is skipped).

    Raises
    ------
    InputFileError
        When the file cannot be read as UTF-8 text.
    """
    metadata = {}
    try:
        with open(path, encoding="utf-8") as stream:
            for line in stream:
                if not line.startswith("#"):
                    break
                key, colon, value = line[len(METADATA_PREFIX):].partition(":")
                if colon and key.strip() and " " not in key.strip():
                    metadata[key.strip()] = value.strip()
    except OSError as error:
        raise InputFileError(f"{path}: cannot read ({error.strerror or error})") from None
    except UnicodeDecodeError:
        raise InputFileError(f"{path}: not UTF-8 text") from None
    return metadata


def peak_frequency(frequency: np.ndarray, velocity: np.ndarray) -> float | None:
    """Frequency of the velocity maximum, refined by a parabola through ln v at it and its neighbours [Hz].

    None when the maximum lies at either end of the swept range (the peak was not bracketed).
    """
    order = np.argsort(frequency)
    f, v = frequency[order], velocity[order]
    k = int(np.argmax(v))
    if k == 0 or k == len(f) - 1:
        return None
    if np.any(v[k - 1:k + 2] <= 0):
        return float(f[k])
    a, b, _ = np.polyfit(f[k - 1:k + 2] - f[k], np.log(v[k - 1:k + 2]), 2)
    return float(f[k] - b / (2 * a)) if a < 0 else float(f[k])


def read_built_plate(path) -> BuiltPlateLog:
    """Read a built-plate log: nominal plate from the metadata, measured f_r from the sweeps.

    Raises
    ------
    InputFileError
        A missing or non-numeric geometry key, an unknown material record, a geometry the
        plate model refuses, a peak at the edge of every sweep, or any error of the log itself.
    """
    path = Path(path)
    metadata = read_metadata(path)
    fields = {}
    for key, name in GEOMETRY_KEYS.items():
        text = metadata.get(key)
        if text is None:
            raise InputFileError(f"{path}: metadata '# {key}: …' missing; a built-plate log names its geometry "
                                 f"({', '.join(GEOMETRY_KEYS)})")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise InputFileError(f"{path}: metadata {key} must be a positive number of mm, got {text!r}")
        fields[name] = value * MM
    try:
        if "ceramic" in metadata:
            fields["ceramic"] = materials.ceramic(metadata["ceramic"])
        if "resonator" in metadata:
            fields["resonator"] = materials.resonator(metadata["resonator"])
        if "glue_um" in metadata:
            glue = float(metadata["glue_um"])
            if not (math.isfinite(glue) and glue >= 0):
                raise ValueError
            fields["glue_thickness"] = glue * UM
        plate = Plate(**fields)
    except TactileError as error:
        raise InputFileError(f"{path}: {error}") from None
    except ValueError:
        raise InputFileError(f"{path}: metadata glue_um must be a number of um >= 0, got {metadata['glue_um']!r}") from None
    log = read_log(path)
    located = (peak_frequency(log.frequency[log.sweep == k], log.velocity[log.sweep == k]) for k in range(log.n_sweeps))
    peaks = [peak for peak in located if peak is not None]
    if not peaks:
        raise InputFileError(f"{path}: no sweep has its velocity peak inside the swept range; cannot locate f_r")
    return BuiltPlateLog(str(path), plate, float(np.median(peaks)), tuple(peaks))
