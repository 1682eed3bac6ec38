"""Figures of the Q(v) fit and of the design with Q(v).  Each function returns a Figure.

They take the result objects of :mod:`workflow.damping.fit` and
:mod:`workflow.optimise.damped`; saving is the caller's business.
"""

import dataclasses
import textwrap
from functools import partial

import matplotlib

matplotlib.use("Agg")

import matplotlib.patheffects as patheffects  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator  # noqa: E402

from instruments.drivers.amplifier import DEFAULT_CERAMIC_VOLTAGE_LIMIT  # noqa: E402
from workflow.damping.fit import DampingFit, LawFit, parameter_summary, sweep_estimates, velocity_grid  # noqa: E402
from workflow.damping.likelihood import predicted_velocity  # noqa: E402
from workflow.models.materials import DESIGN_VOLTAGE  # noqa: E402
from workflow.pipeline.figures.marks import label_contour, legend_below, mark_design_limits, optimum_point  # noqa: E402
from workflow.units import KHZ, MM, PM_PER_V, UM  # noqa: E402

PERCENT = 1e-2
"""One per cent [-] (axis unit)."""
DISPLAY_UNITS = {"gain": ("pm/V", PM_PER_V), "sigma_rel": ("%", PERCENT), "sigma_abs": ("µm/s", UM),
                 "heating": ("1e-7 kg/J", 1e-7)}
"""Parameter -> (unit on the axis, its size in SI) where the SI value would need an exponent."""
LOG_AXES = ("sigma_abs",)
"""Parameters drawn on a logarithmic axis: their posterior spans decades (down to the prior's floor)."""
WHITE_EDGE = [patheffects.withStroke(linewidth=3.5, foreground="white")]
"""Edge of the reference-voltage contours, so that they stand out on dark and light colours."""
PLAIN = FuncFormatter(lambda value, _: f"{value:g}")
"""Tick labels as plain numbers, never an offset or a power of ten."""


def _posterior_draws(law_fit: LawFit, draws: int, seed: int) -> np.ndarray:
    """Up to ``draws`` posterior samples (sampled coordinates), drawn without replacement."""
    rng = np.random.default_rng(seed)
    return law_fit.samples[rng.choice(len(law_fit.samples), size=min(draws, len(law_fit.samples)), replace=False)]


def _drawn_height(ax, span) -> float:
    """Height on the page [points] of a span in y data units, once the layout is done."""
    ax.figure.draw_without_rendering()
    low, high = ax.get_ylim()
    return float(np.max(span)) / (high - low) * ax.get_window_extent().height * 72 / ax.figure.dpi


def _band_note(ax, band_width, relative_width, line_width: float) -> str:
    """How wide a 90 % band is: its largest relative half-width, and whether it is thinner than its line."""
    note = f"90 % band up to +/-{100 * np.max(relative_width) / 2:.2g} %"
    return note + (", thinner than the line" if _drawn_height(ax, band_width) < line_width else "")


def _band_panels():
    """A figure with a tall panel for the curves and a short one for relative widths and residuals [%]."""
    return plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=(3, 1.25), layout="constrained")


def _finish_band_figure(figure, handles, columns: int, title: str, ylabels, xlabel: str):
    """Legend under the panels, title and labels, a zero line on the lower panel, grids."""
    top, bottom = figure.axes[:2]
    figure.legend(handles=handles, fontsize=8, ncol=columns, loc="outside lower center", frameon=False)
    top.set_title("\n".join(textwrap.wrap(title, 80)))
    for ax, label in zip((top, bottom), ylabels):
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    bottom.axhline(0, color="k", lw=0.6)
    bottom.set_xlabel(xlabel)
    return figure


def q_of_v_figure(fit: DampingFit, draws: int = 200, seed: int = 0):
    """Q(v) of each sampled law (median, 90 % band) with the band's width drawn below; the half-power Q
    of each measured sweep beside the same estimate from the preferred law's noise-free curves."""
    figure, (top, bottom) = _band_panels()
    velocity = velocity_grid(fit.log, 200)
    lines = {}
    for name, law_fit in fit.fits.items():
        q05, q50, q95 = law_fit.quality_factor_quantiles(velocity)
        width = 2 if name == fit.preferred else 1.2
        line = top.plot(velocity, q50, lw=width, ls="-" if name == fit.preferred else "--")[0]
        top.fill_between(velocity, q05, q95, color=line.get_color(), alpha=0.3)
        order = 3 if name == fit.preferred else 2
        bottom.fill_between(velocity, 100 * (q05 / q50 - 1), 100 * (q95 / q50 - 1), color=line.get_color(), alpha=0.35,
                            zorder=order)
        bottom.plot(velocity, 100 * np.transpose([q05 / q50 - 1, q95 / q50 - 1]), color=line.get_color(), lw=1, zorder=order)
        lines[name] = (line, q95 - q05, (q95 - q05) / q50)
    if fit.selection == "mixture":
        q05, q50, q95 = np.quantile(fit.answer.law_from_samples().quality_factor(velocity[:, None]), (0.05, 0.5, 0.95), axis=1)
        top.plot(velocity, q50, "k:", lw=2, label="the close laws in equal shares (what the design uses): median, 90 %")
        top.plot(velocity, np.transpose([q05, q95]), "k:", lw=1)
    best = fit.best
    model_curves = dataclasses.replace(fit.log, velocity=np.median(_predicted_rows(best, fit.log, draws, seed), axis=0))
    estimated = sweep_estimates(model_curves)
    top.plot(fit.sweeps.peak_velocity, fit.sweeps.quality_factor, "ko",
             label="half-power Q of each measured sweep: below Q(v_peak), because off the peak the plate moves\n"
             "slower and damps less, so the resonance is wider than a linear one with the peak's Q")
    top.plot(estimated.peak_velocity, estimated.quality_factor, "s", ms=10, mfc="none", mec="k",
             label=f"the same estimate on the {fit.preferred} law's noise-free sweeps: the same bias")
    handles = [
        Line2D([], [], color=line.get_color(), lw=line.get_linewidth(), ls=line.get_linestyle(),
               label=f"{name} law: median, {_band_note(top, band, relative, line.get_linewidth())} (lower panel)")
        for name, (line, band, relative) in lines.items()
    ] + top.get_legend_handles_labels()[0]
    return _finish_band_figure(
        figure, handles, 1, f"Q(v): preferred law {fit.preferred} (PSIS-LOO); the design uses: "
        + (fit.answer.description if fit.selection == "mixture" else f"{fit.selection} ({fit.answer.description})"),
        ("quality factor Q [-]", "90 % band\n/ median - 1 [%]"), "peak velocity v [m/s]",
    )


def _predicted_rows(law_fit: LawFit, log, draws: int, seed: int) -> np.ndarray:
    """Noise-free velocity at every logged row for posterior draws, shape (draws, rows) [m/s]."""
    theta = _posterior_draws(law_fit, draws, seed)
    data = law_fit.data
    return predicted_velocity(theta, data.layout, log.frequency, log.drive_voltage, log.sweep, data.time_offset,
                              data.mode_factor, heat=data.heat)


def resonance_curves_figure(fit: DampingFit, draws: int = 200, points: int = 200, seed: int = 0):
    """Measured sweeps with the preferred law's noise-free prediction (median), and below, the
    residuals and the prediction's 90 % band relative to the median."""
    best, log = fit.best, fit.log
    theta = _posterior_draws(best, draws, seed)
    figure, (top, bottom) = _band_panels()
    colours = plt.cm.viridis(np.linspace(0, 0.9, log.n_sweeps))
    median_at_rows = np.median(_predicted_rows(best, log, draws, seed), axis=0)
    widths, relative = [], []
    for k in range(log.n_sweeps):
        mine = log.sweep == k
        grid = np.linspace(log.frequency[mine].min(), log.frequency[mine].max(), points)
        voltage = np.full(points, np.median(log.drive_voltage[mine]))
        factor = np.median(log.measurement_factor()[mine])
        predicted = factor * predicted_velocity(theta, best.data.layout, grid, voltage, np.full(points, k))
        low, middle, high = np.quantile(predicted, [0.05, 0.5, 0.95], axis=0)
        top.fill_between(grid / KHZ, low, high, color=colours[k], alpha=0.3)
        top.plot(grid / KHZ, middle, color=colours[k], lw=1)
        top.plot(log.frequency[mine] / KHZ, log.velocity[mine], ".", color=colours[k], ms=3, label=f"data, {voltage[0]:g} V peak")
        bottom.fill_between(grid / KHZ, 100 * (low / middle - 1), 100 * (high / middle - 1), color=colours[k], alpha=0.25)
        bottom.plot(log.frequency[mine] / KHZ, 100 * (log.velocity[mine] / median_at_rows[mine] - 1), ".",
                    color=colours[k], ms=3)
        widths.append(np.max(high - low))
        relative.append(np.max((high - low) / middle))
    handles = top.get_legend_handles_labels()[0] + [
        Line2D([], [], color="0.3", lw=1, label="posterior median"),
        Patch(color="0.3", alpha=0.3, label=_band_note(top, widths, relative, 1.0)),
    ]
    return _finish_band_figure(
        figure, handles, 4, f"sweeps and the posterior prediction of the {fit.preferred} law",
        ("velocity amplitude [m/s]", "data, band\n/ median - 1 [%]"), "frequency [kHz]",
    )


def _display_columns(law_fit: LawFit):
    """(name, axis label, conversion from SI, logarithmic) of the parameters in the corner and trace
    plots: the law, gain, noise and the first sweep's resonance (shown as its offset from a round value)."""
    columns = []
    for name, entry in parameter_summary(law_fit).items():
        if name.startswith("v0_") and name != "v0_0":
            continue
        if name.startswith("f_r_"):
            if name != "f_r_0":
                continue
            reference = round(entry["median"])
            data = law_fit.data
            volts = np.median(data.voltage[data.sweep == 0])
            label = f"f_r of the {volts:g} V sweep\n- {reference:g} Hz [Hz]"
            columns.append((name, label, lambda x, r=reference: x - r, False))
        elif name in DISPLAY_UNITS:
            unit, size = DISPLAY_UNITS[name]
            columns.append((name, f"{name} [{unit}]", lambda x, s=size: x / s, name in LOG_AXES))
        else:
            columns.append((name, f"{name} [{entry['unit']}]", lambda x: x, name in LOG_AXES))
    return columns


def _plain_ticks(axis, logarithmic: bool) -> None:
    """Few tick labels, plain numbers (no offset text, no exponent)."""
    if not logarithmic:
        axis.set_major_locator(MaxNLocator(4))
    axis.set_major_formatter(PLAIN)
    axis.set_minor_formatter(FuncFormatter(lambda *_: ""))


def corner_figure(law_fit: LawFit, bins: int = 30):
    """Pairwise posterior histograms of the law, gain, noise and the first sweep's f_r, in units on each axis."""
    natural = law_fit.data.layout.natural(law_fit.samples)
    columns = [(label, convert(natural[name]), log) for name, label, convert, log in _display_columns(law_fit)]
    edges = [np.geomspace(v.min(), v.max(), bins + 1) if log else np.linspace(v.min(), v.max(), bins + 1) for _, v, log in columns]
    n = len(columns)
    size = 1.9 * n + 1
    figure = plt.figure(figsize=(size, size))  # a fixed layout: constrained layout took half the drawing time here
    grid = figure.add_gridspec(n, n, left=1.0 / size, bottom=1.2 / size, right=1 - 0.1 / size, top=1 - 0.45 / size,
                               wspace=0.08, hspace=0.08)
    for i, (label_i, x_i, log_i) in enumerate(columns):
        for j, (label_j, x_j, log_j) in enumerate(columns[: i + 1]):  # the lower triangle only: no empty axes
            ax = figure.add_subplot(grid[i, j])
            if i == j:
                ax.hist(x_i, bins=edges[i], color="C0", histtype="stepfilled", alpha=0.6)
                ax.set_yticks([])
            else:
                ax.hist2d(x_j, x_i, bins=(edges[j], edges[i]), cmap="Blues")
                ax.set_yscale("log" if log_i else "linear")
                _plain_ticks(ax.yaxis, log_i)
            ax.set_xscale("log" if log_j else "linear")
            _plain_ticks(ax.xaxis, log_j)
            if i == n - 1:
                ax.set_xlabel(label_j, fontsize=8)
                ax.tick_params(axis="x", labelrotation=45)
            else:
                ax.tick_params(axis="x", labelbottom=False)
            if j == 0 and i > 0:
                ax.set_ylabel(label_i, fontsize=8)
            elif i != j:
                ax.tick_params(axis="y", labelleft=False)
            ax.tick_params(labelsize=7)
    figure.suptitle(f"posterior of the {law_fit.law_name} law ({len(law_fit.samples)} samples)")
    return figure


def trace_figure(law_fit: LawFit):
    """Walker traces of the shown parameters in their units, the discarded burn-in shaded."""
    trace = law_fit.trace
    steps = np.linspace(0, law_fit.diagnostics.n_steps, len(trace))
    natural = law_fit.data.layout.natural(trace.reshape(-1, trace.shape[-1]))
    columns = _display_columns(law_fit)
    figure, axes = plt.subplots(len(columns), 1, figsize=(7.5, 1.3 * len(columns) + 1), sharex=True, squeeze=False,
                                layout="constrained")
    d = law_fit.diagnostics
    for ax, (name, label, convert, log) in zip(axes[:, 0], columns):
        ax.plot(steps, convert(natural[name]).reshape(trace.shape[:2]), color="k", alpha=0.15, lw=0.5)
        ax.axvspan(0, d.burn_in, color="C3", alpha=0.15)
        ax.set_yscale("log" if log else "linear")
        _plain_ticks(ax.yaxis, log)
        ax.set_ylabel(label, fontsize=8)
        ax.tick_params(labelsize=7)
    axes[-1, 0].set_xlabel("step")
    handles = [Patch(color="C3", alpha=0.15, label=f"burn-in: first {d.burn_in} steps (discarded)"),
               Line2D([], [], color="k", alpha=0.4, lw=0.5, label=f"one walker ({d.n_walkers} in all)")]
    legend_below(figure, handles, columns=2)
    figure.suptitle(
        f"{law_fit.law_name}: {d.n_steps} steps, tau_max {d.tau_max:.0f}, acceptance {d.acceptance:.2f}, "
        f"{'converged' if d.converged else 'NOT converged'}",
        fontsize=9,
    )
    return figure


FIT_FIGURES = {
    "q_of_v.png": ("Q(v) with its 90 % credible band and the per-sweep half-power estimate", q_of_v_figure),
    "resonance_curves.png": ("resonance curves: data and posterior prediction", resonance_curves_figure),
}
"""File name -> (caption, figure function taking a :class:`DampingFit`) of a fit with sweeps."""


def fit_figures(fit: DampingFit) -> dict:
    """File name -> (caption, function drawing the Figure) of every figure of a fit, in order: Q(v), resonance curves,
    ring-downs, and corner and trace plots of each law (drawn only when called: the captions cost nothing)."""
    from workflow.pipeline.figures.ringdown import ringdown_figure

    figures = {name: (caption, partial(draw, fit)) for name, (caption, draw) in FIT_FIGURES.items() if fit.log.n_sweeps}
    if fit.log.ringdown is not None:
        figures["ringdown.png"] = ("ring-downs: envelopes with the law's decay, and the model-free Q from the decays",
                                   partial(ringdown_figure, fit))
    for law_name, law_fit in fit.fits.items():
        figures[f"corner_{law_name}.png"] = (f"posterior of the {law_name} law (corner plot)", partial(corner_figure, law_fit))
        figures[f"trace_{law_name}.png"] = (f"chains of the {law_name} law (trace plot)", partial(trace_figure, law_fit))
    return figures


def _volt_ticks(low: float, high: float) -> list:
    """1-2-5 steps of volts within [low, high] [V]."""
    decades = np.arange(np.floor(np.log10(low)), np.ceil(np.log10(high)) + 1)
    ticks = [step * 10.0**decade for decade in decades for step in (1, 2, 5)]
    return [tick for tick in ticks if low <= tick <= high]


def design_map_figure(maps, quantity: str = "deflection", design_voltage: float = DESIGN_VOLTAGE,
                      voltage_limit: float = DEFAULT_CERAMIC_VOLTAGE_LIMIT):
    """Contour map over (lambda, h_i) with Q(v): the deflection [um] at the design voltage
    or the voltage [V] needed for the target deflection; the 25 kHz line, the h_i
    practical minimum and the optimum are marked, and on the voltage map the design voltage
    and the bench's safety limit.

    Parameters
    ----------
    maps : DampedMaps
        From :func:`workflow.optimise.damped.damped_maps`.
    quantity : {"deflection", "voltage"}
    design_voltage, voltage_limit : float
        Peak voltage across the ceramics [V] of the design and of the bench's safety limit,
        drawn as contours on the voltage map.
    """
    figure, ax = plt.subplots(figsize=(6.5, 5.6), layout="constrained")
    x, y = maps.wavelength / MM, maps.resonator_thickness / MM
    references = []
    if quantity == "deflection":
        contour = ax.contourf(x, y, maps.deflection.T / UM, levels=20, cmap="viridis")
        figure.colorbar(contour, ax=ax, label="deflection with Q(v) [µm]")
    else:  # spans orders of magnitude: logarithmic levels, ticks in plain volts
        values = maps.required_voltage
        levels = np.geomspace(np.min(values), np.max(values), 21)
        contour = ax.contourf(x, y, values.T, levels=levels, norm=LogNorm(levels[0], levels[-1]), cmap="magma_r")
        bar = figure.colorbar(contour, ax=ax, label="voltage for the target deflection [V]")
        bar.ax.yaxis.set_major_locator(FixedLocator(_volt_ticks(levels[0], levels[-1])))
        bar.ax.yaxis.set_major_formatter(PLAIN)
        bar.ax.yaxis.set_minor_formatter(FuncFormatter(lambda *_: ""))
        for volts, style, what in ((design_voltage, "-", "design"), (voltage_limit, "--", "bench limit")):
            if levels[0] < volts < levels[-1]:
                line = ax.contour(x, y, values.T, levels=[volts], colors="tab:blue", linewidths=1.8, linestyles=style)
                line.set_path_effects(WHITE_EDGE)
                references.append((line, f"{volts:g} V {what}", style))
                bar.ax.axhline(volts, color="tab:blue", ls=style, lw=1.8)
    handles = mark_design_limits(
        ax, maps.wavelength, maps.resonator_thickness, maps.frequency, maps.min_frequency,
        maps.min_resonator_thickness, maps.optimum,
    )
    for line, text, style in references:
        label_contour(ax, line, text, optimum_point(maps.optimum), colour="tab:blue")
        handles.append(Line2D([], [], color="tab:blue", lw=1.8, ls=style, path_effects=WHITE_EDGE,
                              label=f"required voltage = {text}"))
    legend_below(figure, handles, columns=2)
    ax.set_title("\n".join(textwrap.wrap(f"h_p = {maps.ceramic_thickness / MM:g} mm, {maps.law_label}", 90)), fontsize=9)
    return figure
