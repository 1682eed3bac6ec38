"""What the (lambda, h_i) maps share: the 25 kHz line, the h_i limit, the optimum, labelled
contours that stay readable on any colour map, and a legend outside the data area."""

import matplotlib.patheffects as patheffects
import numpy as np
from matplotlib.lines import Line2D

from workflow.units import KHZ, MM

OUTLINE = [patheffects.withStroke(linewidth=3, foreground="black")]
"""Black edge around white lines: readable on light and dark colours alike."""
LABEL_MARGIN = 0.12
"""Nearest a contour label comes to the axes' edge, as a fraction of the axes [-]."""


def label_box(colour: str) -> dict:
    """Background of a label on a colour map: translucent black under white text, white under coloured text."""
    white_text = colour == "white"
    return dict(boxstyle="round,pad=0.15", fc="black" if white_text else "white", alpha=0.6 if white_text else 0.85, lw=0)


def label_contour(ax, contour, text: str, avoid=(), colour: str = "white") -> None:
    """Label the first level of ``contour`` with ``text`` inside the axes, away from the ``avoid`` points.

    The label sits on the contour's vertex farthest from both the axes' edges and the points
    ``avoid`` ((x, y) in data coordinates), at least :data:`LABEL_MARGIN` inside the axes, and is
    set on a :func:`label_box`.
    """
    paths = [path for path in contour.get_paths() if len(path.vertices)]
    if not paths:
        return
    vertices = np.concatenate([path.vertices for path in paths])
    inside = ax.transLimits.transform(vertices)
    margin = np.min(np.column_stack([inside, 1 - inside]), axis=1)
    candidates = np.flatnonzero(margin >= LABEL_MARGIN)
    if candidates.size == 0:
        candidates = np.array([np.argmax(margin)])
    score = margin[candidates]
    if len(avoid):
        away = ax.transLimits.transform(np.asarray(avoid, dtype=float))
        distance = np.min(np.linalg.norm(inside[candidates, None, :] - away[None, :, :], axis=2), axis=1)
        score = np.minimum(score, distance)
    chosen = candidates[np.argmax(score)]
    labels = ax.clabel(contour, [contour.levels[0]], fmt={contour.levels[0]: text}, manual=[vertices[chosen]], fontsize=8)
    for label in labels:
        label.set_color(colour)
        label.set_bbox(label_box(colour))


def optimum_point(optimum) -> list:
    """[(lambda, h_i)] of an optimum in mm, or [] without one: the point a map's labels keep away from."""
    return [] if optimum is None else [(optimum.plate.wavelength / MM, optimum.plate.resonator_thickness / MM)]


def mark_design_limits(ax, wavelength, thickness, frequency, min_frequency: float, min_thickness: float, optimum=None):
    """The f_min line, the h_i limit and the optimum on a map over (lambda, h_i) in mm.

    Parameters
    ----------
    wavelength, thickness : ndarray
        Axes of the map [m].
    frequency : ndarray (n_lambda, n_h)
        Resonance [Hz].
    min_frequency, min_thickness : float
        f_min [Hz] and the practical h_i minimum [m].
    optimum : Optimum or None
        Marked with a star.

    Returns
    -------
    list of Line2D
        Legend handles of what was drawn.
    """
    lam, h_i = wavelength / MM, thickness / MM
    line = ax.contour(lam, h_i, frequency.T, levels=[min_frequency], colors="white", linewidths=2)
    line.set_path_effects(OUTLINE)
    ax.axhline(min_thickness / MM, color="white", ls="--", lw=1.5, path_effects=OUTLINE)
    ax.annotate(f"h_i = {min_thickness / MM:g} mm", (0.98, min_thickness / MM), xycoords=("axes fraction", "data"),
                xytext=(0, 3), textcoords="offset points", ha="right", va="bottom", fontsize=8, color="white",
                bbox=label_box("white"))
    handles = [
        Line2D([], [], color="white", lw=2, path_effects=OUTLINE, label=f"f_r = {min_frequency / KHZ:g} kHz (lowest allowed)"),
        Line2D([], [], color="white", ls="--", lw=1.5, path_effects=OUTLINE,
               label=f"h_i = {min_thickness / MM:g} mm (practical minimum)"),
    ]
    avoid = optimum_point(optimum)
    if avoid:
        handles += ax.plot(*avoid[0], "w*", ms=15, mec="k", mew=1.2, ls="none", label="optimum")
    label_contour(ax, line, f"{min_frequency / KHZ:g} kHz", avoid)
    ax.set_xlabel("wavelength λ [mm]")
    ax.set_ylabel("resonator thickness h_i [mm]")
    return handles


def legend_below(figure, handles, columns: int = 3) -> None:
    """One legend for the whole figure, under the axes, never over the data (needs ``layout="constrained"``)."""
    figure.legend(handles=handles, loc="outside lower center", ncol=columns, fontsize=8, frameon=False)
