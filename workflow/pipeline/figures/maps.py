"""Contour maps of w_dyn and f_r over (lambda, h_i), and the width sweep.  Each returns a Figure."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from workflow.optimise.maps import TRANSVERSE_THRESHOLD, DesignMap, WidthSweep  # noqa: E402
from workflow.pipeline.design_models import DESIGN_MODELS  # noqa: E402
from workflow.pipeline.figures.marks import legend_below, mark_design_limits  # noqa: E402
from workflow.units import KHZ, MM, UM  # noqa: E402

WIDTH_SWEEP_FILE = "width_sweep_fem.png"
"""File name of the width sweep's figure (``tactile maps --width-sweep`` and ``tactile run``)."""


def map_file(design_map: DesignMap) -> str:
    """File name of a map's figure: ``map_<model>_hp<h_p>mm.png`` (``tactile maps`` and ``tactile run``)."""
    return f"map_{design_map.model}_hp{design_map.problem.ceramic_thickness / MM:g}mm.png"


def map_figure(design_map: DesignMap):
    """Two panels: w_dyn [um] and f_r [kHz] over (lambda, h_i), with the limits and the optimum.

    FEM maps also show the evaluated grid points, so the reader sees how coarse the contours are.
    """
    figure, axes = plt.subplots(1, 2, figsize=(11, 5.2), layout="constrained")
    lam, h_i = design_map.wavelength / MM, design_map.resonator_thickness / MM
    panels = (
        (design_map.deflection / UM, "deflection w_dyn [µm]", "viridis"),
        (design_map.frequency / KHZ, "resonance f_r [kHz]", "magma"),
    )
    problem = design_map.problem
    for ax, (values, label, colours) in zip(axes, panels):
        filled = ax.contourf(lam, h_i, values.T, levels=20, cmap=colours)
        figure.colorbar(filled, ax=ax, label=label)
        handles = mark_design_limits(
            ax,
            design_map.wavelength,
            design_map.resonator_thickness,
            design_map.frequency,
            problem.min_frequency,
            problem.min_resonator_thickness,
            design_map.optimum,
        )
        if DESIGN_MODELS[design_map.model].sampled_grid:
            grid_lam, grid_h = np.meshgrid(lam, h_i)
            handles += ax.plot(grid_lam.ravel(), grid_h.ravel(), "o", ms=4, mfc="white", mec="black", ls="none",
                               clip_on=False, label="FEM evaluations (contours interpolate between them)")
        ax.set_title(label.rsplit(" ", 1)[0])
    legend_below(figure, handles, columns=len(handles))
    points = f"{len(lam)} x {len(h_i)} grid"
    figure.suptitle(
        f"{DESIGN_MODELS[design_map.model].model_label}, {points}: h_p = {problem.ceramic_thickness / MM:g} mm, "
        f"b = {problem.width / MM:g} mm, {problem.voltage:g} V"
    )
    return figure


def width_sweep_figure(sweep: WidthSweep, design_width: float = None):
    """w(b) and f(b) of the FEM's working mode; transverse-mixed widths and the design width marked.

    Parameters
    ----------
    sweep : WidthSweep
    design_width : float, optional
        b of the design [m], drawn as a vertical line; default the swept plate's own width.
    """
    design_width = sweep.plate.width if design_width is None else design_width
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(7, 6.5), sharex=True, layout="constrained")
    width = sweep.width / MM
    mixed = sweep.transverse
    for b, modes in zip(width, sweep.modes):
        bottom.plot(np.full(len(modes), b), [m.frequency / KHZ for m in modes], "_", color="0.55", ms=4, mew=1.2)
    for ax, values, label in ((top, sweep.deflection / UM, "w_dyn [µm]"), (bottom, sweep.frequency / KHZ, "f_r [kHz]")):
        ax.plot(width, values, "o-", color="C0", ms=4, lw=1.2)
        ax.plot(width[mixed], values[mixed], "o", ms=6, color="tab:red", zorder=3)
        ax.axvline(design_width / MM, color="k", ls="--", lw=1)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    top.annotate(f"design b = {design_width / MM:g} mm", (design_width / MM, 1), xycoords=("data", "axes fraction"),
                 xytext=(3, -3), textcoords="offset points", ha="left", va="top", fontsize=8)
    handles = [
        Line2D([], [], marker="o", ms=4, color="C0", label="working mode (best deflection)"),
        Line2D([], [], marker="o", ms=6, color="tab:red", ls="none",
               label=f"working mode mixed (transverse indicator > {TRANSVERSE_THRESHOLD:g})"),
        Line2D([], [], marker="_", ms=4, mew=1.2, color="0.55", ls="none", label="other modes (FEM eigenfrequencies)"),
        Line2D([], [], color="k", ls="--", lw=1, label="design width"),
    ]
    legend_below(figure, handles, columns=2)
    bottom.set_xlabel("width b [mm]")
    plate = sweep.plate
    figure.suptitle(
        f"FEM width sweep, {len(width)} widths: λ {plate.wavelength / MM:g} mm, h_i {plate.resonator_thickness / MM:g} mm, "
        f"h_p {plate.ceramic_thickness / MM:g} mm"
    )
    return figure
