"""Output folders (docs/cli.md, "Output folders"): a command overwrites only the files it wrote,
a rerun into the same folder works, and ``--force`` overwrites the others."""

import json

import pytest
from user_facing import SAMPLE_CAMPAIGN, run_cli

from workflow.errors import InputFileError
from workflow.pipeline.outputs import RECORD, output_folder

FOREIGN = b"a file tactile did not write\n"


def _write(folder, name, data: bytes):
    (folder / name).parent.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(data)


def _recorded(folder) -> set:
    return set(json.loads((folder / RECORD).read_text())["files"])


def test_a_foreign_file_is_refused_before_the_work_and_left_unchanged(tmp_path):
    _write(tmp_path, "figure.png", FOREIGN)
    ran = []
    with pytest.raises(InputFileError, match="figure.png.*--force"):
        with output_folder(tmp_path, ("*.png",)):
            ran.append(True)
    assert not ran and (tmp_path / "figure.png").read_bytes() == FOREIGN


def test_files_of_other_names_are_not_the_commands_business(tmp_path):
    _write(tmp_path, "notes.txt", FOREIGN)
    with output_folder(tmp_path, ("*.png",)) as folder:
        _write(folder, "figure.png", b"ours")
    assert _recorded(tmp_path) == {"figure.png"}


def test_a_rerun_overwrites_its_own_files_and_records_new_ones(tmp_path):
    with output_folder(tmp_path, ("*.png", "sub/*.json")) as folder:
        _write(folder, "a.png", b"first")
        _write(folder, "sub/fit.json", b"{}")
    with output_folder(tmp_path, ("*.png", "sub/*.json")) as folder:
        _write(folder, "a.png", b"second, longer")
        _write(folder, "b.png", b"new")
    assert _recorded(tmp_path) == {"a.png", "b.png", "sub/fit.json"}
    with output_folder(tmp_path, ("*.png", "sub/*.json")):
        pass


def test_one_of_our_files_edited_since_is_refused(tmp_path):
    with output_folder(tmp_path, ("*.md",)) as folder:
        _write(folder, "report.md", b"tactile's report\n")
    _write(tmp_path, "report.md", b"tactile's report\nwith the user's notes\n")
    with pytest.raises(InputFileError, match="report.md"):
        with output_folder(tmp_path, ("*.md",)):
            pass


def test_force_overwrites_and_records_the_file(tmp_path):
    _write(tmp_path, "figure.png", FOREIGN)
    with output_folder(tmp_path, ("*.png",), force=True) as folder:
        _write(folder, "figure.png", b"ours")
    assert _recorded(tmp_path) == {"figure.png"}
    with output_folder(tmp_path, ("*.png",)):
        pass


def test_files_written_before_a_failure_are_recorded(tmp_path):
    with pytest.raises(RuntimeError):
        with output_folder(tmp_path, ("*.png",)) as folder:
            _write(folder, "half.png", b"written before the failure")
            raise RuntimeError("the step failed")
    with output_folder(tmp_path, ("*.png",)):
        pass


def test_a_damaged_record_is_refused_and_force_replaces_it(tmp_path):
    _write(tmp_path, RECORD, b'{"version": 1, "files": {"a.png": 3}}')
    with pytest.raises(InputFileError, match=RECORD):
        with output_folder(tmp_path, ("*.png",)):
            pass
    with output_folder(tmp_path, ("*.png",), force=True) as folder:
        _write(folder, "a.png", b"ours")
    assert _recorded(tmp_path) == {"a.png"}


MAPS = ("maps", "--hp-mm", "1", "--grid", "3", "--out")


@pytest.fixture
def maps_folder(tmp_path):
    return tmp_path / "maps"


def test_maps_refuses_a_foreign_figure_reruns_and_overwrites_with_force(maps_folder, capsys):
    _write(maps_folder, "map_analytical_hp1mm.png", FOREIGN)
    status, out, err = run_cli(capsys, *MAPS, maps_folder)
    assert status == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "map_analytical_hp1mm.png" in err and "--force" in err
    assert (maps_folder / "map_analytical_hp1mm.png").read_bytes() == FOREIGN
    assert run_cli(capsys, *MAPS, maps_folder, "--force")[0] == 0
    figure = (maps_folder / "map_analytical_hp1mm.png").read_bytes()
    assert figure.startswith(b"\x89PNG")
    assert run_cli(capsys, *MAPS, maps_folder)[0] == 0
    assert _recorded(maps_folder) == {"map_analytical_hp1mm.png"}


@pytest.mark.parametrize("command, name", [
    (("fit-damping", "LOG", "--out"), "fit.json"),
    (("fit-damping", "LOG", "--out"), "posterior.npz"),
    (("run", "--out"), "report.md"),
    (("run", "--out"), "damping/q_of_v.png"),
])
def test_fit_damping_and_run_refuse_a_foreign_output_before_any_work(tmp_path, capsys, command, name):

    out = tmp_path / "out"
    _write(out, name, FOREIGN)
    argv = [str(SAMPLE_CAMPAIGN) if part == "LOG" else part for part in command]
    status, _, err = run_cli(capsys, *argv, out)
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert name in err and "--force" in err
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == [name]
    assert (out / name).read_bytes() == FOREIGN
