"""Figure of the space-mapping searches: every FEM point in the order it was evaluated.

Takes :class:`workflow.fem_optimum.FemOptimum` records (space mapping with its trajectory,
the direct run optional); saving is the caller's business.
"""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from workflow.optimise.space_mapping import FREQUENCY_TOLERANCE, NEAR_CURVE
from workflow.units import MM, UM

LABEL_OFFSETS = ((4, 4), (4, -10), (-12, 4), (-12, -10))
"""Offsets of the point numbers [points], cycled so that numbers of nearby points do not stack."""


def trajectory_figure(searches: dict, min_frequency: float):
    """Deflection and frequency offset of each FEM point against h_i, one column per h_p.

    Parameters
    ----------
    searches : dict
        h_p [m] -> (space-mapping FemOptimum, direct FemOptimum or None).
    min_frequency : float
        f_min [Hz].
    """
    figure, axes = plt.subplots(2, len(searches), figsize=(4.2 * len(searches), 6.4), squeeze=False, sharex="col")
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
            for selection, colour, mode in ((~mixed, "tab:blue", "clean mode"), (mixed, "tab:red", "mixed mode")):
                for filled, where in ((True, "on the limit"), (False, "off it")):
                    chosen = selection & (on_curve == filled)
                    ax.scatter(
                        thickness[chosen],
                        values[chosen],
                        facecolors=colour if filled else "none",
                        edgecolors=colour,
                        zorder=3,
                        label=f"{mode}, {where}",
                    )
            for number, (x, y) in enumerate(zip(thickness, values), start=1):
                shift = LABEL_OFFSETS[(number - 1) % len(LABEL_OFFSETS)]
                ax.annotate(str(number), (x, y), textcoords="offset points", xytext=shift, fontsize=7)
        answer = mapped.optimum
        top.plot(
            answer.plate.resonator_thickness / MM, answer.deflection / UM, "k*", ms=13, label="space-mapping optimum"
        )
        if direct is not None:
            top.plot(
                direct.optimum.plate.resonator_thickness / MM,
                direct.optimum.deflection / UM,
                "kx",
                ms=10,
                label="direct NLopt",
            )
        bottom.axhline(0, color="k", lw=0.8)
        top.set_title(f"h_p = {ceramic_thickness / MM:g} mm: {mapped.fine_evaluations} FEM points")
        top.set_ylabel("w_dyn [um]")
        bottom.set_ylabel("f_r / f_min - 1 [%]")
        bottom.set_xlabel("h_i [mm]")
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="best")
    figure.suptitle(
        f"Space mapping: FEM points in evaluation order (on the limit: f_min (1 - {FREQUENCY_TOLERANCE:g}) "
        f"to f_min (1 + {NEAR_CURVE:g}))",
        fontsize=10,
    )
    figure.tight_layout()
    return figure
