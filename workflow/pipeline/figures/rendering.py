"""Figures of texture rendering: a rendered drive with its predicted envelopes, and a render log's playbacks side by side."""

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from workflow.damping.envelope import LIMITED_FALL, LIMITED_RISE  # noqa: E402
from workflow.rendering.synthesis import ERROR_TARGET  # noqa: E402
from workflow.units import MM, UM  # noqa: E402

MS = MM
"""One millisecond [s] (the same factor as a millimetre)."""
EXTRAPOLATION = 8
"""How far beyond the longest period evaluated the period figure continues each error as 1/sqrt(period) [-]."""
FLAG_COLOURS = {LIMITED_RISE: ("tab:red", "rise held back by the voltage limit"),
                LIMITED_FALL: ("tab:orange", "fall held back by the free decay")}


def _shade_flags(axis, time, interval, flags) -> None:
    """Shade each run of samples whose wanted envelope is out of reach, one colour per reason."""
    for flag, (colour, label) in FLAG_COLOURS.items():
        mine = np.concatenate([[False], flags == flag, [False]])
        starts, stops = np.nonzero(mine[1:] & ~mine[:-1])[0], np.nonzero(~mine[1:] & mine[:-1])[0]
        for number, (start, stop) in enumerate(zip(starts, stops)):
            axis.axvspan(time[start] / MS, (time[stop - 1] + interval) / MS, color=colour, alpha=0.15, lw=0,
                         label=label if number == 0 else None)


def rendering_figure(rendering):
    """Top: the wanted envelope, and the envelopes the model predicts for the pre-compensated drive and for plain
    switching (one loop, periodic steady state); bottom: the two drives and the voltage limit."""
    time = rendering.time
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, layout="constrained")
    top.step(time / MS, rendering.wanted / UM, where="post", color="k", lw=1.2, label="wanted")
    top.plot(time / MS, rendering.envelope / UM, color="C0", label=f"pre-compensated (error {rendering.error:.1%})")
    top.plot(time / MS, rendering.plain_envelope / UM, color="C1", ls="--",
             label=f"plain switching (error {rendering.plain_error:.1%})")
    _shade_flags(top, time, rendering.interval, rendering.flags)
    top.set_ylabel("antinode deflection amplitude [µm]")
    top.legend(fontsize=8)
    top.set_title(f"predicted envelope, carrier {float(rendering.model.carrier):.1f} Hz, {len(time)} samples of "
                  f"{rendering.interval * 1e6:.1f} µs", fontsize=9)
    bottom.step(time / MS, rendering.drive, where="post", color="C0", label="pre-compensated drive")
    bottom.step(time / MS, rendering.plain_drive, where="post", color="C1", ls="--", label="plain switching")
    bottom.axhline(rendering.voltage_limit, color="tab:red", lw=0.8, label=f"voltage limit {rendering.voltage_limit:g} V")
    bottom.set_xlabel("time in the loop [ms]")
    bottom.set_ylabel("drive amplitude across the ceramics [V]")
    bottom.legend(fontsize=8)
    return figure


def comparison_figure(playbacks, comparisons: dict, title: str):
    """One column per playback (plain switching, pre-compensated): top, the envelope wanted, predicted and
    measured (antinode deflection); bottom, the drive played."""
    figure, axes = plt.subplots(2, len(playbacks), figsize=(5.5 * len(playbacks), 6.5), sharex=True, sharey="row",
                                layout="constrained", squeeze=False)
    for column, playback in enumerate(playbacks):
        result = comparisons[playback.name]
        top, bottom = axes[0, column], axes[1, column]
        time = playback.time / MS
        top.step(time, playback.deflection(playback.wanted) / UM, where="post", color="k", lw=1.2, label="wanted")
        top.plot(time, playback.deflection(playback.predicted) / UM, color="C0", lw=1,
                 label=f"predicted (error {result['predicted_error']:.1%})")
        top.plot(time, playback.deflection(playback.measured) / UM, ".", ms=2.5, color="C3",
                 label=f"measured (error {result['error']:.1%})")
        top.set_title(f"{playback.name.replace('precompensated', 'pre-compensated')}: measured - predicted "
                      f"{result['model_error']:.1%} of the swing", fontsize=9)
        top.legend(fontsize=7)
        start, drive = playback.played()
        bottom.step(start / MS, drive, where="post", color="C0", lw=1)
        bottom.set_xlim(time[0], time[-1])
        bottom.set_xlabel("time from the start of a loop [ms]")
    axes[0, 0].set_ylabel("antinode deflection amplitude [µm]")
    axes[1, 0].set_ylabel("drive amplitude across the ceramics [V]")
    figure.suptitle(title, fontsize=10)
    return figure


def period_error_figure(renderings: dict, target: float = ERROR_TARGET):
    """Predicted envelope error of a grating against its period in time, pre-compensated and plain, per design
    (``renderings``: h_p [m] -> DesignRendering), with the error target; a spatial period is the finger speed times it."""
    figure, axis = plt.subplots(figsize=(7.5, 4.8), layout="constrained")
    for index, (hp, rendering) in enumerate(renderings.items()):
        colour, search = f"C{index}", rendering.search
        longer = search.time_period[-1] * np.geomspace(1, EXTRAPOLATION, 10)
        for error, style, name in ((search.error, "-", "pre-compensated"), (search.plain_error, "--", "plain")):
            axis.loglog(search.time_period / MS, error * 100, color=colour, ls=style, label=f"h_p {hp / MM:g} mm, {name}")
            axis.loglog(longer / MS, error[-1] * 100 * np.sqrt(longer[0] / longer), color=colour, ls=":", lw=0.8)
    axis.axhline(target * 100, color="k", lw=0.8, label=f"{target * 100:g} %")
    low, high = next(iter(renderings.values())).levels
    axis.set_xlabel("grating period in time [ms] (spatial period = finger speed x this)")
    axis.set_ylabel("envelope error, RMS over the swing [%]")
    for ticks, minor in ((axis.xaxis, matplotlib.ticker.NullFormatter()), (axis.yaxis, matplotlib.ticker.FormatStrFormatter("%g"))):
        ticks.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ticks.set_minor_formatter(minor)
    axis.set_title(f"gratings {low / UM:g} to {high / UM:g} µm, 50 % duty, within the voltage limit\n(dotted: beyond the "
                   "periods evaluated, the error falls as 1/sqrt(period))", fontsize=9)
    axis.legend(fontsize=7)
    return figure
