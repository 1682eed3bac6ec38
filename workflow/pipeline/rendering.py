"""``tactile render`` at the edges: the plate's envelope model, the drive as the 33500 plays it, the output files.

- :func:`plate_envelope` is the envelope model of a plate: the fit's measured plate (gain,
  resonance, softening from ``fit.json`` beside a ``--damping`` posterior) or the beam model of
  a geometry, with the posterior-median Q(v) or a constant Q;
- :func:`modulated_drive` turns a drive envelope into the 33500's modulation
  (:mod:`instruments.drivers.arbitrary`); :func:`write_rendering` writes ``tactile render``'s files.

Texture files: :mod:`.texture_files`; the bench's playback and render logs: :mod:`.render_logs`;
the design note's section: :mod:`.design_rendering`.
"""

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from instruments.drivers.amplifier import PowerAmplifier
from instruments.drivers.arbitrary import ModulatedDrive, arb_file_text, dac_codes
from instruments.drivers.generator import modulation_script
from workflow.damping.envelope import EnvelopeModel
from workflow.damping.laws import ConstantQ, law_parameters
from workflow.damping.posterior import load_posterior
from workflow.errors import InputFileError
from workflow.models import analytical
from workflow.pipeline.outputs import save_figure
from workflow.rendering.textures import TextureError
from workflow.serialise import jsonable
from workflow.units import MM, UM

FIT_FILE = "fit.json"
"""The fit's summary beside its posterior: the measured plate's gain, resonance and softening."""
RENDER_OUTPUTS = ("drive.csv", "*.arb", "*.scpi", "render.png", "render.json")
"""Files ``tactile render`` writes into its folder (:mod:`workflow.pipeline.outputs`)."""


def fitted_plate(posterior) -> dict:
    """The measured plate of the fit a posterior belongs to: ``gain`` [m/V], ``resonance_frequency`` [Hz]
    (the first sweep's), ``softening`` [s^2/m^2], each the posterior median where ``fit.json`` holds it."""
    folder = Path(posterior) if Path(posterior).is_dir() else Path(posterior).parent
    path = folder / FIT_FILE
    if not path.is_file():
        return {}
    try:
        parameters = json.loads(path.read_text(encoding="utf-8"))["parameters"]
        found = {key: float(parameters[name]["median"]) for key, name in
                 (("gain", "gain"), ("resonance_frequency", "f_r_0"), ("softening", "kappa")) if name in parameters}
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise InputFileError(f"{path}: not the fit.json 'tactile fit-damping' writes ({error})") from None
    if not all(math.isfinite(value) and value >= 0 for value in found.values()):
        raise InputFileError(f"{path}: gain, resonance and softening must be finite and >= 0")
    return found


@dataclass(frozen=True)
class PlateEnvelope:
    """An envelope model and where its numbers come from (for people, JSON and log headers)."""

    model: EnvelopeModel
    source: str

    def record(self) -> dict:
        """JSON-able description: law, its parameters, resonance, gain, softening, source."""
        law = self.model.law
        return {"law": law.name, "law_parameters": law_parameters(law),
                "resonance_frequency_hz": float(self.model.resonance_frequency), "gain_m_v": float(self.model.gain),
                "softening_s2_m2": float(self.model.softening), "source": self.source}


def plate_envelope(plate, q: float, posterior=None) -> PlateEnvelope:
    """The envelope model of ``plate`` (a :class:`~workflow.models.plate.Plate`, beam model) with constant ``q``,
    or with the posterior-median law of ``posterior``; the fit's gain, resonance and softening replace the beam
    model's where its ``fit.json`` has them (a fit describes the plate it measured)."""
    beam = {"gain": float(analytical.deflection_per_volt_per_q(plate)),
            "resonance_frequency": float(analytical.resonance_frequency(plate)), "softening": 0.0}
    if posterior is None:
        return PlateEnvelope(EnvelopeModel(beam["resonance_frequency"], beam["gain"], ConstantQ(q)),
                             f"beam model of the plate (lambda {plate.wavelength / MM:g} mm, h_i "
                             f"{plate.resonator_thickness / MM:g} mm, h_p {plate.ceramic_thickness / MM:g} mm), constant Q")
    law = load_posterior(posterior).median_law()
    fitted = fitted_plate(posterior)
    numbers = {**beam, **fitted}
    origin = "the fit's measured plate" if fitted else "the beam model of the plate"
    return PlateEnvelope(EnvelopeModel(numbers["resonance_frequency"], numbers["gain"], law, numbers["softening"]),
                         f"posterior-median Q(v) of {posterior}; gain, resonance and softening from {origin}"
                         + (f" ({', '.join(sorted(fitted))} fitted)" if fitted else ""))


def modulated_drive(drive, interval: float, carrier: float, amplifier: PowerAmplifier) -> ModulatedDrive:
    """The 33500's modulation playing the drive envelope ``drive`` [V across the ceramics] held ``interval`` [s]
    per sample on a ``carrier`` [Hz]: the carrier amplitude is the envelope's peak."""
    full = float(np.max(drive))
    if not full > 0:
        raise TextureError("the drive is zero everywhere: nothing to play")
    return ModulatedDrive(tuple(int(c) for c in dac_codes(drive, full)), 1 / interval, carrier,
                          amplifier.generator_vpp(full))


def render_summary(rendering, search, speed: float, target: float, envelope: PlateEnvelope) -> dict:
    """``tactile render``'s JSON: the drive, its predicted error and reach, the smallest period at ``speed``."""
    model, to_velocity = rendering.model, rendering.velocity(1.0)
    low, high = float(np.min(rendering.wanted)), float(np.max(rendering.wanted))
    periods = {}
    for name, plain in (("precompensated", False), ("plain", True)):
        period, how = search.smallest_period(speed, target, plain)
        periods[name] = {"period_mm": period / MM, "found": how}
    return {
        "carrier_hz": float(model.carrier),
        "voltage_limit_v": rendering.voltage_limit,
        "points": len(rendering.wanted),
        "sample_rate_sa_s": 1 / rendering.interval,
        "loop_s": rendering.duration,
        "time_constant_ms": {"low": float(model.time_constant(to_velocity * low)) * 1e3,
                             "high": float(model.time_constant(to_velocity * high)) * 1e3},
        "peak_drive_v": float(np.max(rendering.drive)),
        "plain_peak_drive_v": float(np.max(rendering.plain_drive)),
        "error": rendering.error,
        "plain_error": rendering.plain_error,
        "limited_rise_share": rendering.limited_rise_share,
        "limited_fall_share": rendering.limited_fall_share,
        "error_target": target,
        "speed_mm_s": speed / MM,
        "smallest_period": periods,
        "model": envelope.record(),
    }


def write_rendering(folder: Path, rendering, amplifier: PowerAmplifier, summary: dict) -> dict:
    """Write ``drive.csv``, the drives as ``.arb`` files and SCPI scripts, ``render.png`` and ``render.json``."""
    from workflow.pipeline.figures.rendering import rendering_figure

    files = {"table": folder / "drive.csv", "figure": folder / "render.png", "summary": folder / "render.json"}
    to_um = 1 / UM
    columns = {"time_s": rendering.time, "wanted_um": rendering.wanted * to_um, "drive_v": rendering.drive,
               "predicted_um": rendering.envelope * to_um, "flag": rendering.flags,
               "plain_drive_v": rendering.plain_drive, "plain_predicted_um": rendering.plain_envelope * to_um}
    with open(files["table"], "w", encoding="utf-8", newline="") as stream:
        writer = csv.writer(stream, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(zip(*(np.round(v, 9) if v.dtype.kind == "f" else v for v in columns.values())))
    for name, drive in (("precompensated", rendering.drive), ("plain", rendering.plain_drive)):
        modulated = modulated_drive(drive, rendering.interval, float(rendering.model.carrier), amplifier)
        files[f"{name}_arb"] = folder / f"{name}.arb"
        files[f"{name}_arb"].write_text(arb_file_text(modulated.codes, modulated.sample_rate), encoding="ascii", newline="")
        files[f"{name}_scpi"] = folder / f"{name}.scpi"
        files[f"{name}_scpi"].write_text("\n".join(modulation_script(modulated)) + "\n", encoding="ascii")
    save_figure(rendering_figure(rendering), files["figure"])
    paths = {key: str(path) for key, path in files.items()}
    files["summary"].write_text(json.dumps({**summary, "files": paths}, indent=2, default=jsonable) + "\n",
                                encoding="utf-8")
    return paths
