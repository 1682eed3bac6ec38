"""The hostile corpus (issue 26; tests/data/hostile/): every bad input, file or option of the newer commands
(calibrate, --calibration, measure scan and ringdown, the built-plate simulator, the new configuration
sections) exits 2 with one error line naming the file, line or option; no exit 3, no traceback, no hang
(a time limit fails it), no input changed; and every hand-edited log of every procedure (the hold's too)
resumes appending only what is missing, or is refused byte for byte as it was."""

import json
import re
import shutil

import pytest
from hostile import CORPUS, MANIFEST, ROOT, Hung, cases, error_lines, prepare, resume_cases, run_in_process, run_process

from instruments.procedures.logwriter import INCOMPLETE_ROW
from workflow.models.limits import LIMITS

CASES = cases()


@pytest.fixture(autouse=True)
def shared_cache(tmp_path_factory, monkeypatch):
    """One FEM cache for the whole module (the simulated built plate is computed once)."""
    monkeypatch.setenv("TACTILE_CACHE", str(tmp_path_factory.getbasetemp() / "hostile-cache"))


def _refused(status: int, stderr: str, fragments) -> str:
    """The one error line of a refusal, after checking it: exit 2, no traceback, not an internal error, the fragments."""
    lines = error_lines(stderr)
    assert status == 2, f"exit {status}: {stderr[-2000:]}"
    assert "Traceback" not in stderr and len(lines) == 1 and "internal error" not in lines[0], stderr[-2000:]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


@pytest.mark.parametrize("case", CASES, ids=[case.id for case in CASES])
def test_a_hostile_input_is_refused_in_one_line_and_left_alone(case, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    prepared = prepare(case, tmp_path)
    try:
        status, _, err = (run_process if case.process else run_in_process)(prepared.argv)
    except Hung as hang:
        pytest.fail(str(hang))
    _refused(status, err, case.message)
    assert not prepared.changed()
    for path in case.absent:
        assert not (tmp_path / path.replace("{tmp}/", "")).exists(), f"{path}: written although the input was refused"


def test_the_corpus_holds_every_kind_of_input_the_issue_names():
    kinds = {case.kind for case in CASES}
    assert kinds == {"calibration", "log", "settings", "config", "posterior", "option", "output", "special file"}
    assert len(CASES) >= 90 and len(resume_cases()) == 6 * 12 + 1


@pytest.mark.parametrize("procedure, edit", resume_cases())
def test_a_hand_edited_log_resumes_appending_only_what_is_missing_or_is_refused_as_it_was(procedure, edit, tmp_path,
                                                                                        monkeypatch):
    monkeypatch.chdir(tmp_path)
    expected = MANIFEST["resume"]["edits"][edit]
    log = tmp_path / "log.csv"
    shutil.copyfile(CORPUS / "resume" / procedure / f"{edit}.csv", log)
    before = log.read_bytes()
    argv = [*MANIFEST["resume"]["commands"][procedure], "--out", str(log), "--json"]
    try:
        status, out, err = run_in_process(argv)
    except Hung as hang:
        pytest.fail(str(hang))
    if expected["outcome"] == "refuse":
        assert str(log) in _refused(status, err, expected["message"])
        assert log.read_bytes() == before
        return
    assert status == 0, err[-2000:]
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["measured"] == expected["missing"] * MANIFEST["resume"]["points_per_unit"].get(procedure, 1)
    assert expected.get("warning", "") in err
    after = log.read_bytes()
    cut = before.rfind(b"\n") + 1
    kept_as_comment = before[:cut] + INCOMPLETE_ROW.encode() + before[cut:] + b"\n"
    assert after.startswith(before) or after.startswith(kept_as_comment), "a resume changed what the log held"
    assert summary["measured"] or after == before, "nothing to measure, yet the log changed"
    status, out, err = run_in_process(argv)
    assert status == 0 and json.loads(out.strip().splitlines()[-1])["measured"] == 0, err[-2000:]
    assert log.read_bytes() == after


def test_the_plausible_ranges_documented_are_those_of_the_one_table():
    """docs/safety.md lists each physical quantity of LIMITS with its range (one source of truth)."""
    text = (ROOT / "docs" / "safety.md").read_text(encoding="utf-8").replace("\u2212", "-")
    for key, (low, high) in LIMITS.items():
        if "." in key:
            continue
        row = next((line for line in text.splitlines() if line.startswith("| ") and f"| `{key}` |" in line), None)
        assert row is not None, f"{key} missing from docs/safety.md"
        numbers = [float(value) * (1e6 if unit == "MHz" else 1) for value, unit in re.findall(r"(-?\d+(?:\.\d+)?)\s*(MHz)?",
                                                                                              row.split("|")[3])]
        assert numbers == [low, high], (key, row)


def test_logs_of_different_plates_are_read_with_a_warning_when_the_user_chooses_so():
    """--mixed-plates warn: the same logs the corpus refuses are read, with one warning naming both."""
    from workflow.calibration.parameters import default_settings
    from workflow.damping.logs import read_logs
    from workflow.pipeline.calibration_files import measured_plates

    sweeps, decays = CORPUS / "logs" / "p1.csv", CORPUS / "resume" / "ringdown" / "complete.csv"
    log = read_logs([sweeps, decays], mixed_plates="warn")
    assert log.n_sweeps == 1 and log.ringdown.n_bursts == 2
    assert any(str(sweeps) in warning and str(decays) in warning and "% apart" in warning for warning in log.warnings)
    warnings = []
    plates = measured_plates([sweeps, CORPUS / "logs" / "p1_scan_off_resonance.csv"], default_settings(),
                             mixed_plates="warn", warnings=warnings)
    assert len(plates) == 1 and plates[0].scan is not None and "another plate" in warnings[0]
