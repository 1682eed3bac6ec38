"""What a reader needs from the figures: units on the axes, no offset texts, labelled reference
lines and shadings, legends off the data, every number beside its own point."""

import numpy as np
import pytest

from workflow.damping.fit import fit_damping
from workflow.damping.posterior import DampingPosterior
from workflow.damping.synthetic import simulate_campaign
from workflow.models.fem.result import ModeResult
from workflow.models.plate import ORIGINAL_PLATE
from workflow.optimise.damped import damped_maps
from workflow.optimise.fem_optimum import FemOptimum
from workflow.optimise.maps import DesignMap, WidthSweep
from workflow.optimise.problem import DesignProblem, Optimum
from workflow.optimise.space_mapping.from_responses import ExtractedStep
from workflow.pipeline.figures.damping import corner_figure, design_map_figure, q_of_v_figure, trace_figure
from workflow.pipeline.figures.maps import map_figure, width_sweep_figure
from workflow.pipeline.figures.space_mapping import trajectory_figure
from workflow.units import KHZ, MM, UM


@pytest.fixture(scope="module")
def fit():
    campaign = simulate_campaign(seed=11, voltages=(3.0, 9.0, 15.0), points_per_sweep=25)
    return fit_damping(campaign, laws=("quadratic",), seed=3, max_steps=600)


def legend_texts(figure) -> list:
    return [text.get_text() for legend in figure.legends + [ax.get_legend() for ax in figure.axes if ax.get_legend()]
            for text in legend.get_texts()]


def test_corner_and_trace_axes_carry_units_and_no_offset_text(fit):
    law_fit = fit.fits["quadratic"]
    for figure in (corner_figure(law_fit), trace_figure(law_fit)):
        figure.canvas.draw()
        labels = [ax.get_xlabel() for ax in figure.axes] + [ax.get_ylabel() for ax in figure.axes]
        named = [label for label in labels if label and label != "step"]
        assert len(named) >= 6 and all(label.rstrip().endswith("]") and "[" in label for label in named), named
        offsets = [axis.get_offset_text().get_text() for ax in figure.axes for axis in (ax.xaxis, ax.yaxis)]
        assert not any(offsets), offsets
    assert any("burn-in" in text for text in legend_texts(trace_figure(law_fit)))


def test_q_of_v_states_the_band_width_and_the_half_power_bias(fit):
    figure = q_of_v_figure(fit)
    texts = legend_texts(figure)
    assert any("90 % band up to +/-" in text for text in texts)
    assert any("half-power" in text and "below Q(v_peak)" in text for text in texts)
    band_panel = figure.axes[1]
    assert "band" in band_panel.get_ylabel() and len(band_panel.collections) == len(fit.fits)


def test_voltage_map_has_the_design_and_bench_limit_contours(tmp_path):
    posterior = DampingPosterior("quadratic", {"q0": np.full(5, 150.0), "alpha": np.full(5, 0.25)})
    maps = damped_maps(posterior, DesignProblem(1e-3), grid=15, draws=2)
    figure = design_map_figure(maps, "voltage", design_voltage=15.0, voltage_limit=30.0)
    ax = figure.axes[0]
    levels = sorted(float(level) for contour in ax.collections if len(getattr(contour, "levels", ())) == 1
                    for level in contour.levels)
    assert 15.0 in levels and 30.0 in levels
    texts = legend_texts(figure)
    assert any("15 V design" in text for text in texts) and any("30 V bench limit" in text for text in texts)
    figure.canvas.draw()
    ticks = [label.get_text() for label in figure.axes[1].get_yticklabels() if label.get_text()]
    assert ticks and all(text.replace(".", "").isdigit() for text in ticks), ticks  # plain volts, no 1e+01
    figure.savefig(tmp_path / "voltage.png")


def test_map_labels_stay_inside_and_fem_grid_points_are_shown():
    problem = DesignProblem(1e-3)
    wavelength, thickness = np.linspace(15, 40, 4) * MM, np.linspace(0.2, 3, 4) * MM
    frequency = 25 * KHZ * (thickness[None, :] / MM + 0.5) * (22 * MM / wavelength[:, None]) ** 2
    design_map = DesignMap("fem", problem, wavelength, thickness, frequency / frequency * UM, frequency)
    figure = map_figure(design_map)
    assert "4 x 4 grid" in figure.get_suptitle()
    figure.canvas.draw()
    for ax in figure.axes[:2]:  # the two maps; their colour bars follow
        grid = [line for line in ax.lines if len(line.get_xdata()) == 16]
        assert len(grid) == 1
        box = ax.get_window_extent()
        for text in ax.texts:
            extent = text.get_window_extent()
            assert box.x0 <= extent.x0 and extent.x1 <= box.x1 and box.y0 <= extent.y0 and extent.y1 <= box.y1, text
    assert all(not ax.get_legend() for ax in figure.axes)  # the legend is the figure's, under the axes


def test_width_sweep_legend_names_the_other_modes_and_the_design_width():
    widths = np.array([40, 45, 46, 47, 48, 49, 50, 60]) * MM
    modes = tuple((ModeResult(25e3, 0.1 * UM, 0.9), ModeResult(31e3, 1.4 * UM, 0.05)) for _ in widths)
    sweep = WidthSweep(ORIGINAL_PLATE, widths, np.full(len(widths), 1.4 * UM), np.full(len(widths), 31e3),
                       np.where(widths == 49 * MM, 0.3, 0.05), modes)
    figure = width_sweep_figure(sweep)
    texts = legend_texts(figure)
    assert any("other modes" in text for text in texts) and any("design width" in text for text in texts)
    vertical = [line for line in figure.axes[0].lines if np.ptp(line.get_xdata()) == 0 and len(line.get_xdata()) == 2]
    assert [line.get_xdata()[0] for line in vertical] == [pytest.approx(49)]


def test_trajectory_numbers_sit_next_to_their_own_points():
    """The h_p = 2 mm search of tactile run: point 3 (h_i 2.324 mm) lies just right of point 4, the
    answer; its number was drawn to its left, on the answer's star, so the answer read as point 3."""
    problem = DesignProblem(2e-3)
    points = [(29.041, 1.425, 0.8945, 23228.5, 0.15), (30.635, 2.024, 1.1043, 24541.1, 0.04),
              (31.433, 2.324, 1.0790, 24977.7, 0.03), (31.183, 2.260, 1.0785, 25002.2, 0.03)]
    steps = tuple(ExtractedStep(np.array([lam, h_i]) * MM, w * UM, f, t, lam * MM, w * UM) for lam, h_i, w, f, t in points)
    answer = Optimum(problem.plate(31.183 * MM, 2.260 * MM), 1.0785 * UM, 25002.2, 4, True, "test")
    figure = trajectory_figure({problem.ceramic_thickness: (FemOptimum(answer, "space-mapping", 4, 0, steps), None)}, 25 * KHZ)
    figure.canvas.draw()
    for ax in figure.axes:
        centres = ax.transData.transform([(s.thickness_mm, y) for s, y in zip(steps, _values(ax, steps))])
        for text in ax.texts:
            extent = text.get_window_extent()
            position = np.array([(extent.x0 + extent.x1) / 2, (extent.y0 + extent.y1) / 2])
            nearest = int(np.argmin(np.linalg.norm(centres - position, axis=1))) + 1
            assert nearest == int(text.get_text()), (ax.get_ylabel(), text.get_text())


def _values(ax, steps):
    """The y values the trajectory figure draws in ``ax`` (deflection [um] or frequency offset [%])."""
    if ax.get_ylabel().startswith("w_dyn"):
        return [s.deflection / UM for s in steps]
    return [100 * (s.frequency / (25 * KHZ) - 1) for s in steps]
