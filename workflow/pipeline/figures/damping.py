"""Figures of the Q(v) fit and of the design with Q(v).  Each function returns a Figure.

They take the result objects of :mod:`workflow.damping.fit` and
:mod:`workflow.damping.design`; saving is the caller's business.
"""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from workflow.damping.fit import DampingFit, LawFit, velocity_grid  # noqa: E402
from workflow.damping.likelihood import predicted_velocity  # noqa: E402
from workflow.units import KHZ, MM, UM  # noqa: E402


def q_of_v_figure(fit: DampingFit):
    """Q(v): posterior median and 90 % band of each sampled law, and the model-free
    half-power-bandwidth Q of each sweep at that sweep's peak velocity."""
    figure, ax = plt.subplots(figsize=(6, 4))
    velocity = velocity_grid(fit.log, 200)
    for name, law_fit in fit.fits.items():
        q05, q50, q95 = law_fit.quality_factor_quantiles(velocity)
        preferred = name == fit.preferred
        line = ax.plot(velocity, q50, lw=2 if preferred else 1, ls="-" if preferred else "--", label=f"{name} (median)")[0]
        ax.fill_between(velocity, q05, q95, color=line.get_color(), alpha=0.25 if preferred else 0.12, label=f"{name} 90 %")
    ax.plot(fit.sweeps.peak_velocity, fit.sweeps.quality_factor, "ko", label="half-power bandwidth, per sweep")
    ax.set_xlabel("peak velocity v [m/s]")
    ax.set_ylabel("quality factor Q")
    ax.set_title(f"Q(v): preferred law {fit.preferred}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    figure.tight_layout()
    return figure


def resonance_curves_figure(fit: DampingFit, draws: int = 200, points: int = 200, seed: int = 0):
    """Measured sweeps and the 90 % band of the preferred law's noise-free prediction."""
    best, log = fit.best, fit.log
    rng = np.random.default_rng(seed)
    theta = best.samples[rng.choice(len(best.samples), size=min(draws, len(best.samples)), replace=False)]
    figure, ax = plt.subplots(figsize=(7, 4.5))
    colours = plt.cm.viridis(np.linspace(0, 0.9, log.n_sweeps))
    for k in range(log.n_sweeps):
        mine = log.sweep == k
        grid = np.linspace(log.frequency[mine].min(), log.frequency[mine].max(), points)
        voltage = np.full(points, np.median(log.drive_voltage[mine]))
        predicted = predicted_velocity(theta, best.data.layout, grid, voltage, np.full(points, k))
        low, middle, high = np.quantile(predicted, [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(grid / KHZ, low, high, color=colours[k], alpha=0.3)
        ax.plot(grid / KHZ, middle, color=colours[k], lw=1)
        ax.plot(log.frequency[mine] / KHZ, log.velocity[mine], ".", color=colours[k], ms=3, label=f"{voltage[0]:g} V")
    ax.set_xlabel("frequency [kHz]")
    ax.set_ylabel("velocity amplitude [m/s]")
    ax.set_title(f"sweeps and posterior prediction ({fit.preferred} law, 90 % band)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    figure.tight_layout()
    return figure


def _corner_columns(law_fit: LawFit):
    """(label, values) of the parameters shown in the corner and trace plots."""
    natural = law_fit.data.layout.natural(law_fit.samples)
    shown = [name for name in natural if not name.startswith("f_r_") or name == "f_r_0"]
    return [(name, natural[name]) for name in shown]


def corner_figure(law_fit: LawFit, bins: int = 30):
    """Pairwise posterior histograms of the law, gain, noise and the first sweep's f_r."""
    columns = _corner_columns(law_fit)
    n = len(columns)
    figure, axes = plt.subplots(n, n, figsize=(1.6 * n + 1, 1.6 * n + 1), squeeze=False)
    for i, (name_i, x_i) in enumerate(columns):
        for j, (name_j, x_j) in enumerate(columns):
            ax = axes[i, j]
            if j > i:
                ax.set_axis_off()
                continue
            if i == j:
                ax.hist(x_i, bins=bins, color="C0", histtype="stepfilled", alpha=0.6)
                ax.set_yticks([])
            else:
                ax.hist2d(x_j, x_i, bins=bins, cmap="Blues")
            if i == n - 1:
                ax.set_xlabel(name_j, fontsize=8)
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(name_i, fontsize=8)
            elif j > 0:
                ax.set_yticklabels([])
            ax.tick_params(labelsize=6)
    figure.suptitle(f"posterior, {law_fit.law_name} law")
    figure.tight_layout()
    return figure


def trace_figure(law_fit: LawFit):
    """Walker traces of the sampled coordinates, burn-in shaded."""
    names = law_fit.data.layout.names
    shown = [i for i, name in enumerate(names) if not name.startswith("f_r_") or name == "f_r_0"]
    trace = law_fit.trace
    steps = np.linspace(0, law_fit.diagnostics.n_steps, len(trace))
    figure, axes = plt.subplots(len(shown), 1, figsize=(7, 1.3 * len(shown) + 0.5), sharex=True, squeeze=False)
    for ax, index in zip(axes[:, 0], shown):
        ax.plot(steps, trace[:, :, index], color="k", alpha=0.15, lw=0.5)
        ax.axvspan(0, law_fit.diagnostics.burn_in, color="C3", alpha=0.1)
        ax.set_ylabel(names[index], fontsize=8)
        ax.tick_params(labelsize=7)
    axes[-1, 0].set_xlabel("step")
    d = law_fit.diagnostics
    axes[0, 0].set_title(
        f"{law_fit.law_name}: {d.n_steps} steps, tau_max {d.tau_max:.0f}, acceptance {d.acceptance:.2f}, "
        f"{'converged' if d.converged else 'NOT converged'}",
        fontsize=9,
    )
    figure.tight_layout()
    return figure


FIT_FIGURES = {
    "q_of_v.png": q_of_v_figure,
    "resonance_curves.png": resonance_curves_figure,
}
"""File name -> figure function taking a :class:`DampingFit`."""


def fit_figures(fit: DampingFit) -> dict:
    """File name -> Figure for a fit: Q(v), resonance curves, and corner and trace plots of each law."""
    figures = {name: function(fit) for name, function in FIT_FIGURES.items()}
    for law_name, law_fit in fit.fits.items():
        figures[f"corner_{law_name}.png"] = corner_figure(law_fit)
        figures[f"trace_{law_name}.png"] = trace_figure(law_fit)
    return figures


def design_map_figure(maps, quantity: str = "deflection"):
    """Contour map over (lambda, h_i) with Q(v): the deflection [um] at the design voltage
    or the voltage [V] needed for the target deflection; the 25 kHz line, the h_i
    practical minimum and the optimum are marked.

    Parameters
    ----------
    maps : DampedMaps
        From :func:`workflow.damping.design.damped_maps`.
    quantity : {"deflection", "voltage"}
    """
    values = maps.deflection / UM if quantity == "deflection" else maps.required_voltage
    label = "deflection with Q(v) [um]" if quantity == "deflection" else "voltage for the target deflection [V]"
    figure, ax = plt.subplots(figsize=(6, 4.5))
    x, y = maps.wavelength / MM, maps.resonator_thickness / MM
    if quantity == "deflection":
        contour = ax.contourf(x, y, values.T, levels=20, cmap="viridis")
    else:  # spans orders of magnitude: logarithmic levels
        levels = np.geomspace(np.min(values), np.max(values), 21)
        contour = ax.contourf(x, y, values.T, levels=levels, norm=LogNorm(levels[0], levels[-1]), cmap="magma_r")
    figure.colorbar(contour, ax=ax, label=label, format="%.3g", ticks=contour.levels[::4])
    lines = ax.contour(x, y, maps.frequency.T / KHZ, levels=[maps.min_frequency / KHZ], colors="w", linewidths=1.5)
    ax.clabel(lines, fmt=lambda f: f"{f:g} kHz", fontsize=8)
    ax.axhline(maps.min_resonator_thickness / MM, color="w", ls="--", lw=1, label=f"h_i = {maps.min_resonator_thickness / MM:g} mm")
    if maps.optimum is not None:
        ax.plot(maps.optimum.plate.wavelength / MM, maps.optimum.plate.resonator_thickness / MM, "r*", ms=12, label="optimum with Q(v)")
    ax.set_xlabel("wavelength lambda [mm]")
    ax.set_ylabel("resonator thickness h_i [mm]")
    ax.set_title(f"h_p = {maps.ceramic_thickness / MM:g} mm, {maps.law_label}", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    figure.tight_layout()
    return figure
