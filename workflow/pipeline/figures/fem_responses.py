"""Figures of the FEM responses.  Each function takes result objects and returns a Figure.

They take :class:`workflow.models.fem.FemResult` and the response objects of
:mod:`workflow.models.fem.responses`; saving is the caller's business.
"""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np

from workflow.models.fem import FemResult
from workflow.models.fem.responses import FrequencyResponse, TransientResponse
from workflow.optimise.maps import TRANSVERSE_THRESHOLD
from workflow.units import KHZ, UM

MS = 1e-3
"""One millisecond [s] (axis unit)."""


def _finish(figure, ax, xlabel: str, ylabel: str, title: str):
    """Labels, grid, and the legend under the axes (never over the curves)."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    figure.legend(fontsize=8, loc="outside lower center", ncol=2, frameon=False)
    ax.grid(alpha=0.3)
    return figure


def modes_figure(result: FemResult):
    """Deflection of every evaluated mode against its frequency, coloured by the transverse indicator."""
    figure, ax = plt.subplots(figsize=(6, 4.5), layout="constrained")
    frequency = np.array([m.frequency for m in result.modes]) / KHZ
    deflection = np.array([m.deflection for m in result.modes]) / UM
    transverse = np.array([m.transverse_indicator for m in result.modes])
    ax.vlines(frequency, 0, deflection, color="0.7")
    points = ax.scatter(frequency, deflection, c=transverse, cmap="coolwarm", vmin=0, vmax=1, zorder=3)
    ax.plot(result.frequency / KHZ, result.deflection / UM, "k*", ms=14, label="best (working) mode")
    bar = figure.colorbar(points, ax=ax, label="transverse indicator (0 = longitudinal)")
    bar.ax.axhline(TRANSVERSE_THRESHOLD, color="k", lw=1.5)
    bar.ax.text(0.5, TRANSVERSE_THRESHOLD, " mixed above", rotation=90, ha="center", va="bottom", fontsize=7)
    return _finish(figure, ax, "eigenfrequency [kHz]", "deflection at resonance [µm]", "FEM modes near the beam resonance")


def frequency_response_figure(response: FrequencyResponse):
    """|w|(f): mean deflection over the 44 probes, the modes marked."""
    figure, ax = plt.subplots(figsize=(6, 4.5), layout="constrained")
    ax.plot(response.frequency / KHZ, response.deflection / UM, lw=1.5, label=f"FEM response, Q = {response.q:g}")
    low, high = response.frequency.min(), response.frequency.max()
    others = [f for f in response.mode_frequencies if low <= f <= high and f != response.working_frequency]
    for number, frequency in enumerate(others):
        ax.axvline(frequency / KHZ, color="0.6", ls=":", lw=1, label="other modes" if number == 0 else None)
    ax.axvline(response.working_frequency / KHZ, color="k", ls="--", lw=1, label="working mode")
    return _finish(figure, ax, "drive frequency [kHz]", "mean |w| over the antinode probes [µm]", "frequency response")


def transient_figure(response: TransientResponse):
    """w(t) after the sine is switched on, its envelope and 1 - exp(-t/tau)."""
    figure, ax = plt.subplots(figsize=(7, 4.8), layout="constrained")
    time = response.time / MS
    ax.plot(time, response.deflection / UM, lw=0.3, color="0.6", label="w(t)")
    ax.plot(time, response.envelope / UM, lw=1.5, label="envelope")
    model = response.steady_amplitude * (1 - np.exp(-response.time / response.time_constant))
    ax.plot(time, model / UM, "k--", lw=1, label=f"w_s (1 - exp(-t/tau)) fitted, tau = {response.time_constant / MS:.3f} ms")
    ax.axvline(response.expected_time_constant / MS, color="r", ls=":",
               label=f"Q/(pi f_r) = {response.expected_time_constant / MS:.3f} ms (expected tau)")
    title = f"switch-on at f_r = {response.frequency / KHZ:.3f} kHz"
    return _finish(figure, ax, "time [ms]", "deflection [µm]", title)


def admittance_figure(designs: dict):
    """|Y| and phase of the electrical admittance of each design (coupled piezoelectric FEM).

    Parameters
    ----------
    designs : dict
        Label -> (frequencies [Hz], admittance [S] complex, f_r [Hz], f_a [Hz]).
    """
    figure, (magnitude, phase) = plt.subplots(2, 1, figsize=(6.5, 6), sharex=False, layout="constrained")
    for label, (frequencies, admittance, resonance, antiresonance) in designs.items():
        line, = magnitude.semilogy(frequencies / KHZ, np.abs(admittance) * 1e3, label=label)
        phase.plot(frequencies / KHZ, np.degrees(np.angle(admittance)), color=line.get_color())
        for f, marker in ((resonance, "v"), (antiresonance, "^")):
            magnitude.plot(f / KHZ, np.interp(f, frequencies, np.abs(admittance)) * 1e3, marker, color=line.get_color())
    magnitude.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    magnitude.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    magnitude.set_ylabel("|Y| [mS]")
    magnitude.set_title("Electrical admittance of the whole plate (coupled FEM; v f_r, ^ f_a)")
    phase.set_ylabel("phase of Y [deg]")
    phase.set_xlabel("frequency [kHz]")
    for ax in (magnitude, phase):
        ax.grid(alpha=0.3)
        ax.set_xlabel("frequency [kHz]")
    figure.legend(fontsize=8, loc="outside lower center", ncol=3, frameon=False)
    return figure
