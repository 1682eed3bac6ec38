"""Figure of the ring-downs: measured envelopes with the preferred law's prediction, and Q(v) from the decays."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from workflow.damping.fit import DampingFit, velocity_grid  # noqa: E402
from workflow.damping.likelihood import predicted_decay  # noqa: E402
from workflow.damping.ringdown import decay_quality_factors  # noqa: E402
from workflow.units import MM  # noqa: E402

MS = MM
"""One millisecond [s] (the same factor as a millimetre)."""


def ringdown_figure(fit: DampingFit, draws: int = 200, seed: int = 0):
    """Left: each burst's envelope and the preferred law's noise-free decay (median, 90 % band); right: the
    model-free Q from neighbouring samples against the law's Q(v) band (antinode velocity)."""
    best, decays = fit.best, fit.log.ringdown
    data = best.data
    rng = np.random.default_rng(seed)
    theta = best.samples[rng.choice(len(best.samples), size=min(draws, len(best.samples)), replace=False)]
    predicted = predicted_decay(theta, data.layout, data.decays)
    low, middle, high = np.quantile(predicted, [0.05, 0.5, 0.95], axis=0)
    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5), layout="constrained")
    colours = plt.cm.viridis(np.linspace(0, 0.9, decays.n_bursts))
    for j in range(decays.n_bursts):
        mine = decays.burst == j
        t = decays.decay_time[mine] / MS
        left.plot(t, decays.velocity[mine], ".", ms=3, color=colours[j],
                  label=f"burst {j}, {np.median(decays.drive_voltage[mine]):g} V")
        left.plot(t, middle[mine], color=colours[j], lw=1)
        left.fill_between(t, low[mine], high[mine], color=colours[j], alpha=0.3)
    left.set_yscale("log")
    left.set_xlabel("time after the burst [ms]")
    left.set_ylabel("velocity envelope at the measurement point [m/s]")
    left.legend(fontsize=7)
    left.set_title(f"ring-downs and the {fit.preferred} law's decay (median, 90 % band)", fontsize=9)
    velocity, q = decay_quality_factors(decays.frequency, decays.velocity / decays.mode_factor, decays.burst,
                                        decays.decay_time)
    grid = velocity_grid(fit.log)
    q05, q50, q95 = best.quality_factor_quantiles(grid)
    right.fill_between(grid, q05, q95, color="C0", alpha=0.3, label=f"{fit.preferred} law, 90 % band")
    right.plot(grid, q50, color="C0", label="median")
    right.plot(velocity, q, "k.", ms=4, label="pi f dt / -d ln v between samples (model-free)")
    right.set_xlabel("peak velocity at the antinode v [m/s]")
    right.set_ylabel("quality factor Q [-]")
    right.legend(fontsize=7)
    right.set_title("Q(v) from the decays", fontsize=9)
    return figure
