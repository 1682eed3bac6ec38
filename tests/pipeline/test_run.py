"""``tactile run`` end to end on a tiny configuration; the report's links resolve."""

import contextlib
import io
import json
import re
from pathlib import Path

import pytest
from tiny_config import TINY
from user_facing import HIDDEN_REFERENCE

from workflow import progress
from workflow.cli import main
from workflow.errors import TactileError
from workflow.inputfiles import tomllib
from workflow.pipeline.figures import damping as damping_figures
from workflow.pipeline.config import default_config
from workflow.pipeline.outputs import RECORD
from workflow.pipeline.steps import STEPS, sweep_widths
from workflow.units import MM


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """(exit status, output folder, configuration, stderr) of a tiny run whose stderr is not a terminal."""
    folder = tmp_path_factory.mktemp("run")
    config = folder / "tiny.toml"
    config.write_text(TINY)
    out = folder / "report"
    with pytest.MonkeyPatch.context() as patch, contextlib.redirect_stderr(io.StringIO()) as stderr:
        patch.setenv("TACTILE_CACHE", str(folder / "cache"))
        patch.setattr(progress, "QUIET_TASK", 0.0)  # tiny steps, yet each batch reports
        status = main(["run", "--config", str(config), "--out", str(out)])
    return status, out, config, stderr.getvalue()


def test_a_rerun_reuses_the_cached_steps_and_their_files(tiny_run, capsys, monkeypatch):
    """A cached step's files come back from the cache as they were written (not drawn again), also when deleted."""
    _, out, config, _ = tiny_run
    monkeypatch.setenv("TACTILE_CACHE", str(out.parent / "cache"))
    corner, fit = out / "damping" / "corner_quadratic.png", out / "damping" / "fit.json"
    written, report = corner.read_bytes(), (out / "report.md").read_text()
    corner.unlink()
    monkeypatch.setattr(damping_figures, "fit_figures", lambda fit: pytest.fail("the fit's figures drawn again"))
    capsys.readouterr()
    assert main(["run", "--config", str(config), "--out", str(out), "--json"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert "Q(v) fit (emcee)" in record["from_cache"]
    assert corner.read_bytes() == written and str(corner) in json.loads(fit.read_text())["files"]["figures"]
    assert _figure_links((out / "report.md").read_text()) == _figure_links(report)


def _figure_links(report: str) -> list:
    return re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)


def test_the_run_records_every_file_it_wrote(tiny_run):
    """So that a rerun into the folder may overwrite them all without --force (test_outputs.py)."""
    _, out, _, _ = tiny_run
    written = {path.relative_to(out).as_posix() for path in out.rglob("*") if path.is_file() and path.name != RECORD}
    assert "report.md" in written and "damping/fit.json" in written
    assert set(json.loads((out / RECORD).read_text())["files"]) == written


def test_tiny_run_writes_a_report(tiny_run):
    status, out, _, _ = tiny_run
    assert status == 0
    text = (out / "report.md").read_text()
    assert "## Analytical optimum with constant Q" in text
    assert "## Run time" in text
    damping = text.split("## Damping: Q(v) fitted to the logs")[1].split("\n## ")[0]
    for shown in ("Preferred law by PSIS-LOO: **quadratic**", "(selection `", "elpd_loo ± se", "stacking weight",
                  "Misfit checks", "stated σ_rel", "damping/posterior.nc"):
        assert shown in damping, shown
    assert (out / "damping" / "posterior.nc").is_file()


def test_piped_progress_shows_every_step_and_the_long_computations_inside(tiny_run):
    *_, err = tiny_run
    for number, step in enumerate(STEPS, start=1):
        assert f"[{number}/{len(STEPS)}] {step.title} ..." in err
        assert re.search(rf"^\[{number}/{len(STEPS)}\] {re.escape(step.title)}: done in (\d+ min )?[\d.]+ s, .+ elapsed$", err, re.M)
    assert re.search(r"^emcee, quadratic law: \d+/\d+ steps", err, re.M), err
    assert re.search(r"^FEM evaluations: \d+/\d+ done in", err, re.M), err
    assert "\r" not in err  # no bar on a pipe


def test_the_report_opens_with_the_recommended_design(tiny_run):
    _, out, *_ = tiny_run
    text = (out / "report.md").read_text()
    sections = re.findall(r"^## (.+)$", text, flags=re.MULTILINE)
    assert sections[0] == "Recommended design"
    assert text.index("# Tactile plate design note") < text.index("## Recommended design")
    assert "Sensors and Actuators A: Physical (2010)" in text.split("## Recommended design")[0].replace("*", "")
    assert not HIDDEN_REFERENCE.search(text) and " um" not in text and "[um]" not in text
    recommended = text.split("## Recommended design")[1].split("\n## ")[0]
    assert "| 1 | FEM |" in recommended  # h_p = 1 mm from the FEM optimum


def test_the_reproduction_table_says_what_kind_of_comparison_each_row_is(tiny_run):
    _, out, *_ = tiny_run
    section = (out / "report.md").read_text().split("## Reproduction of the paper")[1].split("\n## ")[0]
    assert "| paper figure | kind | paper |" in section
    rows = {line.split("|")[1].strip(): line.split("|")[2].strip() for line in section.splitlines() if line.startswith("| ")}
    assert rows["plate Q at the original working point"] == "consistency check"
    assert rows["original plate, beam model, Q = 54, 15 V: deflection"] == "consistency check"
    assert rows["original plate, FEM, Q = 54, 15 V: resonance"] == "validation"


def test_the_width_sweep_marks_the_original_plate(tiny_run):
    _, out, *_ = tiny_run
    section = (out / "report.md").read_text().split("## Width sweep")[1].split("\n## ")[0]
    marked = [line for line in section.splitlines() if "original plate" in line and line.startswith("| ")]
    assert len(marked) == 1 and marked[0].startswith("| 49 |")
    assert [line.split("|")[1].strip() for line in section.splitlines() if line.startswith("| ")][1:] == [
        "30", "48", "49", "50", "65", "100"
    ]


def test_sweep_widths_join_the_coarse_and_fine_ranges_and_the_plate_width():
    fem = {"width_min_mm": 30.0, "width_max_mm": 100.0, "width_points": 15,
           "fine_width_min_mm": 45.0, "fine_width_max_mm": 56.0, "fine_width_step_mm": 1.0}
    widths = sweep_widths(fem, 49.5 * MM) / MM
    assert set(range(45, 57)) <= set(widths.round(9)) and 49.5 in widths and 100.0 in widths
    assert len(widths) == 15 + 12 - 3 + 1  # 45, 50, 55 are in both ranges
    with pytest.raises(TactileError, match="fine_width_step_mm"):
        sweep_widths({**fem, "fine_width_step_mm": 0.0}, 49 * MM)


def test_every_link_of_the_report_resolves(tiny_run):
    _, out, _, _ = tiny_run
    text = (out / "report.md").read_text()
    targets = re.findall(r"\]\(([^)]+)\)", text)
    for target in targets:
        if "://" not in target:
            assert (out / target).is_file(), target


def test_the_report_shows_every_figure_the_run_wrote_once(tiny_run):
    """The report links what the steps produced: each PNG in the output folder appears once, with a caption."""
    _, out, _, _ = tiny_run
    text = (out / "report.md").read_text()
    written = sorted(path.relative_to(out).as_posix() for path in out.rglob("*.png"))
    linked = re.findall(r"!\[([^]]+)\]\(([^)]+\.png)\)", text)
    assert written and sorted(target for _, target in linked) == written
    assert all(caption.strip() for caption, _ in linked)


def test_the_report_names_no_figure_file():
    """Figure names are written once, where a step writes the figure (the report asks the run what it produced)."""
    import workflow.pipeline.loop_report
    import workflow.pipeline.report

    for module in (workflow.pipeline.report, workflow.pipeline.loop_report):
        source = Path(module.__file__).read_text(encoding="utf-8")
        assert re.findall(r"[\w{}/.-]+\.png", source) == [], module.__name__


def test_print_config_shows_the_effective_configuration(capsys, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[design]\nvoltage_v = 10.0\n")
    assert main(["run", "--config", str(path), "--print-config"]) == 0
    printed = tomllib.loads(capsys.readouterr().out)
    expected = default_config()
    expected["design"]["voltage_v"] = 10.0
    assert printed == expected


def test_configuration_error_names_the_key(capsys, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[maps]\ngrid = 'many'\n")
    assert main(["run", "--config", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "maps.grid" in err[0]


def test_the_report_states_the_accuracy_of_its_fem_numbers(tiny_run):
    _, out, _, _ = tiny_run
    text = (out / "report.md").read_text()
    original = text.split("## FEM of the original plate")[1].split("\n## ")[0]
    assert re.search(r"FEM accuracy: estimated error of the working mode's frequency [+-]\d+\.\d\d %", original)
    assert "target 5 %" in original
    optima = text.split("## FEM optimum")[1].split("\n## ")[0]
    assert "f_r error estimate" in optima and re.search(r"\| [+-]\d+\.\d\d % \| (yes|\*\*no\*\*) \|", optima)
    assert "fixed mesh of the [fem] keys (error not estimated)" in text.split("## Width sweep")[1]
    assert "FEM accuracy: each FEM frequency above comes from a mesh refined" in text


def test_the_run_fits_sweeps_and_ringdowns_jointly_and_reports_them(tiny_run):
    """The tiny run's campaign has ring-downs and a softening plate: fitted jointly with the softening and the drift,
    fit.json and the report show them, each burst and the agreement of sweeps and ring-downs."""
    _, out, config, _ = tiny_run
    assert (out / "simulated_ringdown.csv").is_file()
    summary = json.loads((out / "damping" / "fit.json").read_text())
    assert summary["forward_model"] == {"softening": True, "drift": True, "heating": True}
    kappa = summary["parameters"]["kappa"]
    assert kappa["p05"] <= default_config()["simulator"]["softening_s2_m2"] <= kappa["p95"]
    ringdown = summary["ringdown"]
    assert ringdown["n_bursts"] == 2 and ringdown["n_samples"] == 80
    assert [b["voltage_v"] for b in ringdown["bursts"]] == [5.0, 15.0]
    assert ringdown["agreement"]["agree"] and len(ringdown["agreement"]["v_m_s"]) == 5
    report = (out / "report.md").read_text()
    assert "**Ring-downs** (2 bursts, 80 samples" in report
    assert "Agreement of the two measurements of Q" in report and "amplitude softening" in report
    assert "damping/ringdown.png" in report and (out / "damping" / "ringdown.png").is_file()


def test_the_report_states_what_each_design_renders_and_what_it_draws(tiny_run):
    _, out, _, _ = tiny_run
    section = (out / "report.md").read_text(encoding="utf-8").split("## Texture rendering and the amplifier")[1]
    section = section.split("\n## ")[0]
    rows = [line for line in section.splitlines() if line.startswith("| 1 |")]
    assert len(rows) == 2  # the h_p = 1 mm design: its gratings, then its electrical load
    periods = [float(text.strip(" ~≤")) for text in rows[0].split("|")[4].split("/")]
    assert periods[0] < periods[1] < periods[2]  # a faster finger needs a longer period
    current, power, apparent, peak = (float(cell) for cell in rows[1].split("|")[6:10])
    assert 0 < power <= apparent and current < peak
    assert (out / "rendering_periods.png").is_file()


def test_every_step_has_a_typed_result_field_and_an_unknown_key_is_refused():
    from dataclasses import fields

    from workflow.pipeline.runner import RunResults, Step

    assert [step.key for step in STEPS] == [f.name for f in fields(RunResults)]
    with pytest.raises(TypeError, match="not a field of RunResults"):
        Step("a step nobody declared", "undeclared", lambda context: None)
