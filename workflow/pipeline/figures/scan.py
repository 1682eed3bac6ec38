"""Figure of a deflection scan beside the FEM's map of the nominal plate, with their MAC.

Both maps show the signed deflection normalised to its largest magnitude: the FEM's complex
shape turned by the phase that makes it most nearly real (a standing wave is real up to one
phase), the measured one by the phase that best matches the FEM at the scan's points, so nodal
lines and antiphase regions show with the same sign on both sides.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from instruments.simulator.builtplate import BuiltPlateModel  # noqa: E402
from workflow.models.materials import PLATE_Q  # noqa: E402
from workflow.pipeline.builtplate import ScanLog, predicted_map  # noqa: E402
from workflow.units import KHZ, MM  # noqa: E402


def standing_phase(values) -> float:
    """The phase [rad] that turns complex ``values`` most nearly real (maximises the energy of the real part)."""
    return 0.5 * float(np.angle(np.sum(np.asarray(values, dtype=complex) ** 2)))


def signed_shape(values, phase: float) -> np.ndarray:
    """Real part of ``values`` turned by -``phase`` [rad], scaled to max |.| = 1 [-]."""
    turned = (np.asarray(values, dtype=complex) * np.exp(-1j * phase)).real
    return turned / np.max(np.abs(turned))


def scan_figure(scan: ScanLog, nominal: BuiltPlateModel, mac: float, q: float = PLATE_Q):
    """Measured map (left) and the nominal FEM's map at its working frequency (right); the MAC in the title."""
    figure, axes = plt.subplots(1, 2, figsize=(11, 3.8), layout="constrained", sharey=True)
    half_length, half_width = nominal.surface.half_length, nominal.surface.half_width
    x = np.linspace(-half_length, half_length, 241)
    y = np.linspace(-half_width, half_width, 81)
    xx, yy = np.meshgrid(x, y)
    fem = nominal.surface.deflection(xx.ravel(), yy.ravel(), nominal.resonance_frequency, q)
    phase = standing_phase(fem)
    predicted = signed_shape(fem, phase).reshape(xx.shape)
    at_points = predicted_map(scan, nominal, q)
    measured = signed_shape(scan.phasors, phase - np.angle(np.vdot(scan.phasors, at_points)))  # the FEM's sign
    style = dict(cmap="RdBu_r", vmin=-1, vmax=1)
    xs, ys = np.unique(scan.x), np.unique(scan.y)
    if len(xs) * len(ys) == len(scan.x) and len(xs) > 1 and len(ys) > 1:
        grid = np.full((len(ys), len(xs)), np.nan)
        grid[np.searchsorted(ys, scan.y), np.searchsorted(xs, scan.x)] = measured
        image = axes[0].pcolormesh(xs / MM, ys / MM, grid, shading="nearest", **style)
    else:
        image = axes[0].scatter(scan.x / MM, scan.y / MM, c=measured, s=60, edgecolors="0.3", **style)
    axes[0].plot(scan.x / MM, scan.y / MM, ".", color="0.2", markersize=3)
    axes[0].set_title(f"measured: {len(scan.x)} points at {np.median(scan.frequency) / KHZ:.3f} kHz, "
                      f"{np.median(scan.drive_voltage):g} V", fontsize=10)
    axes[1].pcolormesh(x / MM, y / MM, predicted, shading="auto", **style)
    axes[1].set_title(f"FEM, nominal plate: working mode at {nominal.resonance_frequency / KHZ:.3f} kHz", fontsize=10)
    axes[1].plot(scan.x / MM, scan.y / MM, ".", color="0.2", markersize=3)
    for ax in axes:
        ax.add_patch(plt.Rectangle((-half_length / MM, -half_width / MM), 2 * half_length / MM, 2 * half_width / MM,
                                   fill=False, color="0.4", linewidth=0.8))
        ax.set_xlim(-half_length / MM * 1.02, half_length / MM * 1.02)
        ax.set_ylim(-half_width / MM * 1.05, half_width / MM * 1.05)
        ax.set_aspect("equal")
        ax.set_xlabel("x along the length [mm]")
    axes[0].set_ylabel("y across [mm]")
    plate = scan.plate
    figure.colorbar(image, ax=axes, shrink=0.85, label="signed deflection / max [-]")
    figure.suptitle(f"Deflection scan of {Path(scan.source).name} (λ {plate.wavelength / MM:g} mm, h_i {plate.resonator_thickness / MM:g} mm, "
                    f"h_p {plate.ceramic_thickness / MM:g} mm, b {plate.width / MM:g} mm): MAC = {mac:.3f}")
    return figure
