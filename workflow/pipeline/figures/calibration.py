"""Figure of a calibration: the posterior's pairs (histograms and scatter), prior bounds marked."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from workflow.calibration.calibration import Calibration  # noqa: E402

LABELS = {
    "ceramic_modulus_factor": "ceramic c^E factor [-]",
    "resonator_modulus_factor": "resonator E factor [-]",
    "glue_modulus_factor": "glue E factor [-]",
    "glue_um": "glue [µm]",
    "resonator_offset_um": "h_i offset [µm]",
}


def pairs_figure(calibration: Calibration, max_points: int = 2000):
    """Pairs plot of the posterior samples in display units, each axis spanning the prior's support."""
    parameters = calibration.settings.parameters
    n = len(parameters)
    scale = np.array([p.display_scale for p in parameters])
    samples = calibration.samples / scale
    shown = samples[np.linspace(0, len(samples) - 1, min(max_points, len(samples))).astype(int)]
    limits = [(p.low / p.display_scale, p.high / p.display_scale) for p in parameters]
    figure, axes = plt.subplots(n, n, figsize=(2.3 * n, 2.3 * n), squeeze=False)
    for i in range(n):
        for j in range(n):
            ax = axes[i, j]
            if j > i:
                ax.axis("off")
                continue
            if i == j:
                ax.hist(samples[:, i], bins=40, range=limits[i], color="tab:blue", alpha=0.8)
                ax.set_yticks([])
            else:
                ax.scatter(shown[:, j], shown[:, i], s=2, alpha=0.3, color="tab:blue", rasterized=True)
                ax.set_ylim(limits[i])
            ax.set_xlim(limits[j])
            if i == n - 1:
                ax.set_xlabel(LABELS.get(parameters[j].name, parameters[j].name), fontsize=8)
            if j == 0 and i > 0:
                ax.set_ylabel(LABELS.get(parameters[i].name, parameters[i].name), fontsize=8)
            ax.tick_params(labelsize=7)
    names = ", ".join(f"{Path(p.name).name} {p.frequency / 1e3:.3f} kHz" for p in calibration.plates)
    figure.suptitle(f"Calibration posterior ({len(samples)} samples) from {names}", fontsize=9)
    figure.tight_layout()
    return figure
