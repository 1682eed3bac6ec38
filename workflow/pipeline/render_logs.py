"""``tactile measure render`` around the procedure: the playbacks of a rendering, and what a render log achieved.

:func:`measure_rendering` renders the texture for the plate on the bench and plays it
(:mod:`instruments.procedures.render`); :func:`compare_log` reads a render log back and compares
each playback's captured envelope with the wanted and predicted ones (:mod:`workflow.rendering.metrics`);
:func:`comparison_figure_file` draws them side by side.
"""

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from instruments.drivers.amplifier import PowerAmplifier
from instruments.drivers.arbitrary import MAX_POINTS, drive_of_codes
from instruments.drivers.lockin import capture_interval
from instruments.procedures.capture import CaptureWindow
from instruments.procedures.logwriter import read_log
from instruments.procedures.render import Playback, RenderPlan, render_playback
from workflow import logformat
from workflow.damping.envelope import envelope_at
from workflow.damping.laws import law_parameters
from workflow.damping.mode_shape import BeamMode, measurement_factor
from workflow.pipeline.rendering import PlateEnvelope, modulated_drive, save_figure
from workflow.rendering.metrics import contrast_per_period, envelope_error, median_time, transition_times
from workflow.rendering.synthesis import render
from workflow.rendering.textures import wanted_deflection
from workflow.units import MM

PLAYBACKS = ("plain", "precompensated")
"""The drives ``tactile measure render`` plays, in this order (playback ids 0 and 1)."""
RECORD_SAMPLES = 256
"""Envelope samples captured per playback (the most a ring-down keeps too) [-]."""


def record_times(loop: float, loops: float, samples: int = RECORD_SAMPLES) -> tuple:
    """(interval [s], the lock-in's shortest capture interval covering ``loops`` loops of ``loop`` [s]) and the capture
    times (:class:`~instruments.procedures.capture.CaptureWindow`)."""
    interval = capture_interval(loops * loop / samples, at_least=True)
    return interval, CaptureWindow.after(interval, 0.0, samples).times()


def render_plan(rendering, texture, motion, amplifier: PowerAmplifier, loops: float, settle: float) -> RenderPlan:
    """``tactile measure render``'s playbacks: plain switching, then the pre-compensated drive, each with the wanted
    and predicted antinode velocity at the capture times (``loops`` loops from a loop's start)."""
    interval, times = record_times(rendering.duration, loops)
    within = np.mod(times, rendering.duration)
    wanted = rendering.velocity(wanted_deflection(texture, motion, within))
    playbacks = []
    for name, drive, envelope in (("plain", rendering.plain_drive, rendering.plain_envelope),
                                  ("precompensated", rendering.drive, rendering.envelope)):
        boundaries = rendering.velocity(np.append(envelope, envelope[0]))
        predicted = np.abs(envelope_at(rendering.model, drive, rendering.interval, boundaries, within))
        modulated = modulated_drive(drive, rendering.interval, float(rendering.model.carrier), amplifier)
        playbacks.append(Playback(name, modulated, tuple(wanted), tuple(predicted)))
    return RenderPlan(tuple(playbacks), len(times), interval, settle)


@dataclass(frozen=True)
class PlaybackRecord:
    """One playback of a render log, antinode velocities at the capture times.

    Attributes
    ----------
    name : str
    time : numpy.ndarray
        Since the start of a loop [s].
    drive, measured, wanted, predicted : numpy.ndarray
        Drive envelope [V]; antinode velocity amplitude measured, wanted, predicted [m/s].
    carrier : float
        [Hz]
    waveform : numpy.ndarray
        The drive envelope of each sample of the loop as played [V] (from the plan's codes).
    sample_rate : float
        Of ``waveform`` [Sa/s].
    """

    name: str
    time: np.ndarray
    drive: np.ndarray
    measured: np.ndarray
    wanted: np.ndarray
    predicted: np.ndarray
    carrier: float
    waveform: np.ndarray
    sample_rate: float

    def deflection(self, velocity):
        """Deflection amplitude of a velocity amplitude at the carrier [m]."""
        return np.asarray(velocity) / (2 * np.pi * self.carrier)

    def played(self) -> tuple:
        """(start times [s], drive [V]) of every sample of the waveform over the capture's span."""
        loops = int(np.ceil(self.time[-1] * self.sample_rate / len(self.waveform))) + 1
        return np.arange(loops * len(self.waveform)) / self.sample_rate, np.tile(self.waveform, loops)


def read_render_log(path) -> tuple:
    """(metadata, playbacks) of a render log, the measured velocities brought to the antinode; a playback played
    again after a capture cut short (a resume) is read from its last, complete capture."""
    path = Path(path)
    logged = read_log(path, logformat.RENDER_COLUMNS)
    metadata, rows = logged.metadata, logged.rows
    samples = int(metadata["plan_samples"])
    names = metadata.get("plan_playbacks", ",".join(PLAYBACKS)).split(",")
    factor = 1.0
    if logformat.X_POSITION in metadata and logformat.LAMBDA_MM in metadata:
        factor = float(measurement_factor(BeamMode(float(metadata[logformat.LAMBDA_MM]) * MM),
                                          float(metadata[logformat.X_POSITION]) * MM,
                                          float(metadata.get(logformat.Y_POSITION, 0.0)) * MM))
    playbacks = []
    for j, name in enumerate(names):
        mine = [row for row in rows if row[logformat.SWEEP] == str(j)][-samples:]
        if not mine:
            continue
        column = {key: np.array([float(row[key]) for row in mine]) for key in logformat.RENDER_COLUMNS[2:]}
        full_scale = PowerAmplifier(float(metadata["amplifier_gain"])).ceramic_voltage(
            float(metadata[f"plan_{name}_amplitude_vpp"]))
        codes = np.array([int(code) for code in metadata[f"plan_{name}_codes"].split(",")])
        playbacks.append(PlaybackRecord(name, column[logformat.RENDER_TIME], column[logformat.DRIVE_VOLTAGE],
                                        column[logformat.VELOCITY] / factor, column[logformat.WANTED_VELOCITY],
                                        column[logformat.PREDICTED_VELOCITY], float(column[logformat.FREQUENCY][0]),
                                        drive_of_codes(codes, full_scale), float(metadata[f"plan_{name}_sample_rate"])))
    return metadata, playbacks


def compare_playback(playback: PlaybackRecord, loop: float | None) -> dict:
    """What a playback achieved against what was wanted: the envelope errors (measured and predicted against
    wanted, measured against predicted, each over the wanted swing), median 10-90 % rise and fall times, and
    the contrast per loop (a grating's period) measured and wanted."""
    transitions = {kind: transition_times(playback.time, values, playback.wanted)
                   for kind, values in (("measured", playback.measured), ("predicted", playback.predicted))}
    span = np.ptp(playback.wanted) or float(np.mean(playback.wanted))
    record = {
        "name": playback.name,
        "error": float(envelope_error(playback.measured, playback.wanted)),
        "predicted_error": float(envelope_error(playback.predicted, playback.wanted)),
        "model_error": float(np.sqrt(np.mean((playback.measured - playback.predicted) ** 2)) / span),
        "rise_time_ms": _milliseconds(median_time(transitions["measured"]["rise"])),
        "fall_time_ms": _milliseconds(median_time(transitions["measured"]["fall"])),
        "predicted_rise_time_ms": _milliseconds(median_time(transitions["predicted"]["rise"])),
        "predicted_fall_time_ms": _milliseconds(median_time(transitions["predicted"]["fall"])),
        "peak_drive_v": float(np.max(playback.drive)),
    }
    if loop is not None:
        record["contrast"] = contrast_per_period(playback.time, playback.measured, loop)
        record["wanted_contrast"] = contrast_per_period(playback.time, playback.wanted, loop)
    return record


def _milliseconds(seconds):
    return None if seconds is None else seconds * 1e3


def compare_log(path) -> tuple:
    """(metadata, playbacks, :func:`compare_playback` of each keyed by name) of the render log ``path``."""
    metadata, playbacks = read_render_log(path)
    loop = float(metadata["texture_loop_s"]) if "texture_loop_s" in metadata else None
    return metadata, playbacks, {playback.name: compare_playback(playback, loop) for playback in playbacks}


def measure_rendering(station, path, texture, motion, envelope: PlateEnvelope, resonance: float, loops: float,
                      settle: float, metadata: dict, restart: bool = False):
    """``tactile measure render``: render the texture with the envelope model's resonance set to the measured
    ``resonance`` [Hz], play plain switching then the pre-compensated drive on ``station`` and log the captures
    (:func:`instruments.procedures.render.render_playback`); the header holds the texture, the model and the
    predicted errors."""
    model = replace(envelope.model, resonance_frequency=resonance)
    rendering = render(model, texture, motion, station.voltage_limit, max_points=MAX_POINTS)
    plan = render_plan(rendering, texture, motion, station.amplifier, loops, settle)
    model_keys = {f"model_{key}": value for key, value in PlateEnvelope(rendering.model, envelope.source).record().items()
                  if key != "law_parameters"}
    law = {f"model_law_{key}": value for key, value in law_parameters(rendering.model.law).items()}
    header = {**metadata, **model_keys, **law, "model_carrier_hz": float(rendering.model.carrier),
              "predicted_error": rendering.error, "predicted_plain_error": rendering.plain_error}
    return render_playback(station, path, plan, header, restart)


def comparison_figure_file(log, figure_path) -> dict:
    """Compare the render log ``log`` (:func:`compare_log`) and write the side-by-side figure; its summary keys."""
    from workflow.pipeline.figures.rendering import comparison_figure

    metadata, playbacks, comparisons = compare_log(log)
    title = (f"{metadata.get('texture_kind', 'texture')} {metadata.get('texture_period_mm', '')} mm at "
             f"{float(metadata.get('texture_speed_mm_s', 'nan')):g} mm/s, carrier {float(metadata['model_carrier_hz']):.1f} Hz"
             if "model_carrier_hz" in metadata else str(log))
    save_figure(comparison_figure(playbacks, comparisons, title), figure_path)
    return {"comparison": comparisons, "figure": str(figure_path)}
