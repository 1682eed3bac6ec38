"""The figure of one or more holds: velocity against the target, frequency, drive and temperature over time."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

MINUTE = 60.0
"""[s]"""


def hold_figure(records, title: str | None = None):
    """Four panels sharing the time axis: the velocity relative to the target (with +-2 %), the drive frequency,
    the drive amplitude and the plate temperature, one line per :class:`~workflow.pipeline.hold_logs.HoldRecord`."""
    figure, axes = plt.subplots(4, 1, figsize=(9, 9.5), sharex=True, layout="constrained",
                                gridspec_kw={"height_ratios": [2, 1.2, 1, 1]})
    velocity, frequency, drive, temperature = axes
    for index, record in enumerate(records):
        minutes, colour = record.time / MINUTE, f"C{index}"
        velocity.plot(minutes, 100 * (record.velocity / record.target - 1), color=colour, label=record.label)
        frequency.plot(minutes, record.frequency, color=colour)
        drive.plot(minutes, record.drive, color=colour)
        if np.any(np.isfinite(record.temperature)):
            temperature.plot(minutes, record.temperature, color=colour)
    for bound in (-2, 2):
        velocity.axhline(bound, color="k", lw=0.7, ls=":")
    velocity.set_ylabel("velocity - target [%]")
    velocity.legend(fontsize=8)
    frequency.set_ylabel("drive frequency [Hz]")
    frequency.ticklabel_format(axis="y", useOffset=False)
    drive.set_ylabel("drive [V peak]")
    temperature.set_ylabel("plate [°C]")
    temperature.set_xlabel("hold time [min]")
    if title:
        velocity.set_title(title, fontsize=9)
    return figure
