"""The figure of one or more holds: velocity against the target, frequency, drive and temperature over time."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

MINUTE = 60.0
"""[s]"""
TOLERANCE = 2.0
"""The hold's amplitude tolerance drawn [%]."""


def hold_figure(records, title: str | None = None, resonances=()):
    """Five panels sharing the time axis: the velocity relative to the target, the same within +-3 % (the +-2 %
    tolerance marked), the drive frequency, the drive amplitude and the plate temperature, one line per
    :class:`~workflow.pipeline.hold_logs.HoldRecord`; ``resonances``, (label, time [s], frequency [Hz]) each, are
    drawn dashed over the frequencies (a simulator's truth)."""
    figure, axes = plt.subplots(5, 1, figsize=(9, 11), sharex=True, layout="constrained",
                                gridspec_kw={"height_ratios": [1.4, 1.2, 1.4, 1, 1]})
    velocity, zoom, frequency, drive, temperature = axes
    for index, record in enumerate(records):
        minutes, colour = record.time / MINUTE, f"C{index}"
        relative = 100 * (record.velocity / record.target - 1)
        velocity.plot(minutes, relative, color=colour, label=record.label)
        zoom.plot(minutes, relative, color=colour)
        frequency.plot(minutes, record.frequency, color=colour)
        drive.plot(minutes, record.drive, color=colour)
        if np.any(np.isfinite(record.temperature)):
            temperature.plot(minutes, record.temperature, color=colour)
    for index, (label, time, resonance) in enumerate(resonances):
        frequency.plot(np.asarray(time) / MINUTE, resonance, color="k", lw=0.8, ls=("--", ":")[index % 2], label=label)
    if resonances:
        frequency.legend(fontsize=8)
    for bound in (-TOLERANCE, TOLERANCE):
        zoom.axhline(bound, color="k", lw=0.7, ls=":")
    zoom.set_ylim(-1.5 * TOLERANCE, 1.5 * TOLERANCE)
    velocity.set_ylabel("velocity - target [%]")
    velocity.legend(fontsize=8)
    zoom.set_ylabel(f"the same, +-{TOLERANCE:g} % marked")
    frequency.set_ylabel("drive frequency [Hz]")
    frequency.ticklabel_format(axis="y", useOffset=False)
    drive.set_ylabel("drive [V peak]")
    temperature.set_ylabel("plate [°C]")
    temperature.set_xlabel("hold time [min]")
    if title:
        velocity.set_title(title, fontsize=9)
    return figure
