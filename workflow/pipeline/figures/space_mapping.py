"""Figure of the space-mapping searches: every FEM point in the order it was evaluated.

Takes :class:`workflow.optimise.fem_optimum.FemOptimum` records (space mapping with its
trajectory, the direct run optional); saving is the caller's business.
"""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from workflow.optimise.maps import TRANSVERSE_THRESHOLD  # noqa: E402
from workflow.optimise.space_mapping import FREQUENCY_TOLERANCE, NEAR_CURVE  # noqa: E402
from workflow.pipeline.figures.marks import legend_below  # noqa: E402
from workflow.units import KHZ, MM, UM  # noqa: E402

NUMBER_DISTANCE = 9.0
"""Distance of a point's number from the point's centre [points]."""
NUMBER_DIRECTIONS = 12
"""Directions tried for each number; the one farthest from other markers and numbers is taken [-]."""


def _number_points(ax, x, y) -> None:
    """Write 1, 2, ... beside the points (x, y), each on the side farthest from the other points and
    from the numbers already written, inside the axes (the layout must be final)."""
    to_pixels = ax.figure.dpi / 72
    points = ax.transData.transform(np.column_stack([x, y]))
    box = ax.get_window_extent()
    angles = np.linspace(0, 2 * np.pi, NUMBER_DIRECTIONS, endpoint=False)
    offsets = NUMBER_DISTANCE * to_pixels * np.column_stack([np.cos(angles), np.sin(angles)])
    placed = []
    for number, point in enumerate(points, start=1):
        candidates = point + offsets
        others = np.vstack([np.delete(points, number - 1, axis=0), *placed]) if len(points) > 1 or placed else None
        score = np.full(len(candidates), np.inf) if others is None else np.min(
            np.linalg.norm(candidates[:, None, :] - others[None, :, :], axis=2), axis=1
        )
        inside = (candidates[:, 0] > box.x0 + 6) & (candidates[:, 0] < box.x1 - 6)
        inside &= (candidates[:, 1] > box.y0 + 6) & (candidates[:, 1] < box.y1 - 6)
        score = np.where(inside, score, -np.inf)
        best = int(np.argmax(score))
        placed.append(candidates[best][None, :])
        ax.annotate(str(number), ax.transData.inverted().transform(candidates[best]), ha="center", va="center",
                    fontsize=7)


def trajectory_figure(searches: dict, min_frequency: float):
    """Deflection and frequency offset of each FEM point against h_i, one column per h_p.

    Parameters
    ----------
    searches : dict
        h_p [m] -> (space-mapping FemOptimum, direct FemOptimum or None).
    min_frequency : float
        f_min [Hz].
    """
    figure, axes = plt.subplots(
        2, len(searches), figsize=(4.2 * len(searches), 7), squeeze=False, sharex="col", layout="constrained"
    )
    f_min = f"{min_frequency / KHZ:g} kHz"
    numbered = []
    for column, (ceramic_thickness, (mapped, direct)) in enumerate(searches.items()):
        top, bottom = axes[:, column]
        steps = mapped.trajectory
        thickness = np.array([s.thickness_mm for s in steps])
        deflection = np.array([s.deflection for s in steps]) / UM
        offset = 100 * (np.array([s.frequency for s in steps]) / min_frequency - 1)
        mixed = np.array([s.mixed for s in steps])
        on_curve = (offset >= -100 * FREQUENCY_TOLERANCE) & (offset <= 100 * NEAR_CURVE)  # feasible, near f_min
        for ax, values in ((top, deflection), (bottom, offset)):
            ax.plot(thickness, values, color="0.8", lw=0.8, zorder=1)
            for selection, colour in ((~mixed, "tab:blue"), (mixed, "tab:red")):
                for filled in (True, False):
                    chosen = selection & (on_curve == filled)
                    ax.scatter(thickness[chosen], values[chosen], facecolors=colour if filled else "none",
                               edgecolors=colour, zorder=3)
            numbered.append((ax, thickness, values))
        answer = mapped.optimum
        top.plot(answer.plate.resonator_thickness / MM, answer.deflection / UM, "k*", ms=15, mfc="none", mew=1.2, zorder=4)
        if direct is not None:
            top.plot(direct.optimum.plate.resonator_thickness / MM, direct.optimum.deflection / UM, "kx", ms=10)
        bottom.axhline(0, color="k", lw=0.8)
        top.set_title(f"h_p = {ceramic_thickness / MM:g} mm: {mapped.fine_evaluations} FEM evaluations")
        top.set_ylabel("w_dyn [µm]")
        bottom.set_ylabel(f"f_r / {f_min} - 1 [%]")
        bottom.set_xlabel("resonator thickness h_i [mm]")
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
            ax.margins(0.08)
    band = f"{-100 * FREQUENCY_TOLERANCE:g} % to +{100 * NEAR_CURVE:g} %"
    handles = [
        Line2D([], [], marker="o", ls="none", color="tab:blue", label=f"on the {f_min} limit (f_r within {band})"),
        Line2D([], [], marker="o", ls="none", mfc="none", mec="tab:blue", label="off the limit"),
        Line2D([], [], marker="o", ls="none", mfc="none", mec="tab:red",
               label=f"red: working mode mixed with a transverse mode (indicator > {TRANSVERSE_THRESHOLD:g})"),
        Line2D([], [], marker="*", ms=12, ls="none", mfc="none", mec="k", label="answer of the search (a FEM point)"),
        Line2D([], [], color="0.8", lw=0.8, label="evaluation order"),
    ]
    if any(direct is not None for _, direct in searches.values()):
        handles.append(Line2D([], [], marker="x", ms=9, ls="none", color="k", label="direct NLopt optimum"))
    legend_below(figure, handles, columns=2)
    width = next(iter(searches.values()))[0].optimum.plate.width
    figure.suptitle(
        f"Space mapping: the FEM evaluations that found the largest deflection with f_r >= {f_min} "
        f"(b = {width / MM:g} mm), numbered in the order evaluated",
        fontsize=10,
    )
    figure.draw_without_rendering()  # the numbers are placed in the final layout
    for ax, thickness, values in numbered:
        _number_points(ax, thickness, values)
    return figure
