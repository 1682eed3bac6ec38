"""Contour maps of w_dyn and f_r over (lambda, h_i), and the width sweep.  Each returns a Figure."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from workflow.optimise.maps import TRANSVERSE_THRESHOLD, DesignMap, WidthSweep  # noqa: E402
from workflow.units import KHZ, MM, UM  # noqa: E402


def _mark_design_limits(ax, design_map: DesignMap) -> None:
    """The f_min line, the h_i limit and the optimum on a map's axes (mm)."""
    lam, h_i = design_map.wavelength / MM, design_map.resonator_thickness / MM
    problem = design_map.problem
    limit = ax.contour(
        lam, h_i, design_map.frequency.T, levels=[problem.min_frequency], colors="red", linewidths=2
    )
    ax.clabel(limit, fmt={problem.min_frequency: f"{problem.min_frequency / KHZ:g} kHz"}, fontsize=8)
    ax.axhline(problem.min_resonator_thickness / MM, color="white", ls="--", lw=1.5)
    ax.text(lam[-1], problem.min_resonator_thickness / MM, f"h_i = {problem.min_resonator_thickness / MM:g} mm ",
            color="white", ha="right", va="bottom", fontsize=8)
    if design_map.optimum is not None:
        plate = design_map.optimum.plate
        ax.plot(plate.wavelength / MM, plate.resonator_thickness / MM, "w*", ms=14, mec="k", label="optimum")
        ax.legend(loc="upper left", fontsize=8)
    ax.set_xlabel("wavelength lambda [mm]")
    ax.set_ylabel("resonator thickness h_i [mm]")


def map_figure(design_map: DesignMap):
    """Two panels: w_dyn [um] and f_r [kHz] over (lambda, h_i), with the limits and the optimum."""
    figure, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    lam, h_i = design_map.wavelength / MM, design_map.resonator_thickness / MM
    panels = (
        (design_map.deflection / UM, "w_dyn [um]", "viridis"),
        (design_map.frequency / KHZ, "f_r [kHz]", "magma"),
    )
    for ax, (values, label, colours) in zip(axes, panels):
        filled = ax.contourf(lam, h_i, values.T, levels=20, cmap=colours)
        figure.colorbar(filled, ax=ax, label=label)
        _mark_design_limits(ax, design_map)
        ax.set_title(label.split(" ")[0])
    problem = design_map.problem
    figure.suptitle(
        f"{design_map.model} model, h_p = {problem.ceramic_thickness / MM:g} mm, b = {problem.width / MM:g} mm, "
        f"{problem.voltage:g} V"
    )
    figure.tight_layout()
    return figure


def width_sweep_figure(sweep: WidthSweep):
    """w(b) and f(b) of the FEM's working mode; transverse-mixed widths marked."""
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(6.5, 6), sharex=True)
    width = sweep.width / MM
    mixed = sweep.transverse
    for ax, values, label in ((top, sweep.deflection / UM, "w_dyn [um]"), (bottom, sweep.frequency / KHZ, "f_r [kHz]")):
        ax.plot(width, values, "o-", color="C0", label="working mode")
        ax.plot(width[mixed], values[mixed], "rs", ms=9, mfc="none",
                label=f"transverse indicator > {TRANSVERSE_THRESHOLD:g}")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    for b, modes in zip(width, sweep.modes):
        bottom.plot(np.full(len(modes), b), [m.frequency / KHZ for m in modes], "k.", ms=3, alpha=0.4)
    top.legend(fontsize=8)
    bottom.set_xlabel("width b [mm]")
    plate = sweep.plate
    top.set_title(
        f"width sweep (FEM): lambda {plate.wavelength / MM:g} mm, h_i {plate.resonator_thickness / MM:g} mm, "
        f"h_p {plate.ceramic_thickness / MM:g} mm"
    )
    figure.tight_layout()
    return figure
