"""The original plate against the paper's FEM (COMSOL): eigenstrain and coupled models, mesh and width.

For the original plate (Table 1, b = 49 mm, Q = 54, 15 V) the eigenstrain and the coupled piezoelectric
FEM on the accuracy-control mesh levels, their Richardson limits (two finest levels), and both models
against the width around 49 mm, where the working mode mixes with a transverse mode.  Prints one JSON
object and draws the figure ``docs/figures/paper_comparison.png`` (docs/fem.md).  Slow (tens of
minutes on two cores): run it on purpose.

    python bench/paper_comparison.py [--levels 6 8 10 12] [--widths-mm 45 47 49 51 53 56] [--width-level 8]
"""

import argparse
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from workflow.models.fem import evaluate_fem  # noqa: E402
from workflow.models.fem.accuracy import estimate_error, mesh_for_level  # noqa: E402
from workflow.models.plate import ORIGINAL_PLATE  # noqa: E402
from workflow.pipeline.paper import FIGURES  # noqa: E402

MODELS = ("eigenstrain", "coupled")
FIGURE = Path(__file__).resolve().parents[1] / "docs" / "figures" / "paper_comparison.png"


def evaluate(plate, level: int, piezo: str) -> dict:
    """f_r [Hz], w [m], indicator, f_a [Hz] (coupled) and the time of one evaluation."""
    start = time.perf_counter()
    result = evaluate_fem(plate, 54.0, 15.0, mesh_for_level(plate, level, piezo=piezo))
    row = {
        "level": level,
        "dofs": result.n_dofs,
        "seconds": round(time.perf_counter() - start, 2),
        "f_hz": result.frequency,
        "w_m": result.deflection,
        "indicator": result.best.transverse_indicator,
        "modes": [[m.frequency, m.deflection, m.transverse_indicator] for m in result.modes],
        "_result": result,
    }
    if piezo == "coupled":
        row["f_a_hz"] = result.antiresonance
        row["k_eff"] = result.coupling_factor
    return row


def mesh_study(levels, piezo: str) -> dict:
    rows = [evaluate(ORIGINAL_PLATE, level, piezo) for level in levels]
    limit = estimate_error(rows[-1]["_result"], rows[-2]["_result"], levels[-1], levels[-2])
    return {
        "rows": rows,
        "f_converged_hz": rows[-1]["f_hz"] / (1 + limit.frequency),
        "w_converged_m": rows[-1]["w_m"] / (1 + limit.deflection),
    }


def width_study(widths_mm, level: int, piezo: str) -> list:
    return [dict(evaluate(ORIGINAL_PLATE.with_(width=b * 1e-3), level, piezo), width_mm=b) for b in widths_mm]


def responding_modes(ax, x, rows, marker) -> None:
    """Modes within 1.5 kHz deflecting at least 20 % of the working mode: size by deflection, colour by indicator."""
    for position, row in zip(x, rows):
        modes = [m for m in row["modes"] if m[1] >= 0.2 * row["w_m"] and abs(m[0] - row["f_hz"]) < 1.5e3]
        ax.scatter(
            [position] * len(modes),
            [m[0] / 1e3 for m in modes],
            s=[60 * m[1] / row["w_m"] for m in modes],
            c=[m[2] for m in modes],
            cmap="coolwarm",
            vmin=0,
            vmax=1,
            marker=marker,
            alpha=0.6,
        )


def figure(studies: dict, widths: dict, path: Path) -> None:
    paper_f, paper_w = FIGURES["fem_f"].value, FIGURES["fem_w"].value
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.5), constrained_layout=True)
    for piezo, marker in zip(MODELS, "os"):
        rows = studies[piezo]["rows"]
        h2 = [1 / row["level"] ** 2 for row in rows]
        axes[0, 0].plot(h2, [row["f_hz"] / 1e3 for row in rows], marker=marker, label=f"{piezo} FEM")
        responding_modes(axes[0, 0], h2, rows, marker)
        axes[0, 0].plot(0, studies[piezo]["f_converged_hz"] / 1e3, marker=marker, color="k", fillstyle="none")
        axes[1, 0].plot(h2, [row["w_m"] * 1e6 for row in rows], marker=marker, label=f"{piezo} FEM")
        axes[1, 0].plot(0, studies[piezo]["w_converged_m"] * 1e6, marker=marker, color="k", fillstyle="none")
        rows = widths[piezo]
        axes[0, 1].plot([r["width_mm"] for r in rows], [r["f_hz"] / 1e3 for r in rows], marker=marker, label=piezo)
        responding_modes(axes[0, 1], [r["width_mm"] for r in rows], rows, marker)
        axes[1, 1].plot([r["width_mm"] for r in rows], [r["w_m"] * 1e6 for r in rows], marker=marker, label=piezo)
    for ax in axes[0]:
        ax.axhline(paper_f, color="tab:red", ls="--", label=f"paper (COMSOL) {paper_f} kHz")
        ax.set_ylabel("f [kHz]")
    for ax in axes[1]:
        ax.axhline(paper_w, color="tab:red", ls="--", label=f"paper (COMSOL) {paper_w} µm")
        ax.set_ylabel("mean |w| at the probes, 15 V, Q 54 [µm]")
    for ax in axes[:, 0]:
        ax.set_xlabel("1 / (elements per ceramic)² [-]  (0: Richardson limit, open black markers)")
    for ax in axes[:, 1]:
        ax.axvline(49, color="0.6", lw=0.8)
        ax.set_xlabel("plate width b [mm]  (mesh level %d)" % widths[MODELS[0]][0]["level"])
    axes[0, 0].set_title("original plate, b = 49 mm: mesh refinement")
    axes[0, 1].set_title("width: working and transverse modes mix")
    fig.suptitle(
        "lines: working mode (largest deflection); dots: modes within 1.5 kHz deflecting ≥ 20 % of it "
        "(size ∝ w, blue→red: transverse indicator 0→1)",
        fontsize=9,
    )
    for ax in axes.flat:
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", type=int, nargs="+", default=[6, 8, 10, 12])
    parser.add_argument("--widths-mm", type=float, nargs="+", default=[45, 47, 48, 49, 50, 51, 53, 56])
    parser.add_argument("--width-level", type=int, default=8)
    parser.add_argument("--figure", type=Path, default=FIGURE)
    args = parser.parse_args()
    studies = {piezo: mesh_study(args.levels, piezo) for piezo in MODELS}
    widths = {piezo: width_study(args.widths_mm, args.width_level, piezo) for piezo in MODELS}
    figure(studies, widths, args.figure)
    clean = lambda rows: [{k: v for k, v in row.items() if k != "_result"} for row in rows]  # noqa: E731
    print(
        json.dumps(
            {
                "mesh": {p: dict(studies[p], rows=clean(studies[p]["rows"])) for p in MODELS},
                "width": {p: clean(widths[p]) for p in MODELS},
                "figure": str(args.figure),
            }
        )
    )


if __name__ == "__main__":
    main()
