"""What a user installs: every file the package reads at run time ships inside it, and no code path climbs
out of its package to find one.

Run against a wheel installed without ``-e`` (what ``.ci/run`` does), the first test fails when a data file
of the source tree is missing from the installed package; the second reads the files the run needs through
the installed package's resources.
"""

import ast
import re
from importlib import resources
from pathlib import Path

import pytest

import instruments
import workflow
from workflow.calibration.published import PUBLISHED_PLATES

SOURCE_TREE = Path(__file__).resolve().parents[1]
"""The checkout the tests live in (its package folders are compared with the installed ones)."""
PACKAGES = (workflow, instruments)


def _data_files(folder: Path) -> set:
    """Relative paths of the files under a package folder that are not Python sources or build litter."""
    return {
        path.relative_to(folder).as_posix()
        for path in folder.rglob("*")
        if path.is_file() and path.suffix not in (".py", ".pyc") and "__pycache__" not in path.parts
    }


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.__name__)
def test_every_data_file_of_the_source_tree_is_in_the_installed_package(package):
    source = SOURCE_TREE / package.__name__
    if not source.is_dir():
        pytest.skip("the tests run outside their checkout")
    installed = Path(package.__path__[0])
    missing = _data_files(source) - _data_files(installed)
    assert not missing, f"not in the installed package {installed} (package-data in pyproject.toml?): {sorted(missing)}"


def test_the_run_time_files_are_read_through_the_installed_package():
    published = resources.files("workflow.calibration.published")
    for name in PUBLISHED_PLATES.values():
        assert (published / name).read_text(encoding="utf-8").startswith("# Published built plate")
    for package, name in (("workflow.models", "materials.toml"), ("workflow.calibration", "calibration.toml")):
        assert resources.files(package).joinpath(name).is_file(), f"{package}/{name}"


CLIMBING = re.compile(r"__file__.*(parents\[\s*[1-9]|\.parent\s*\.\s*parent|\.\.)|\.\./")
"""A path computed from a module's location that leaves its folder, or a relative path upwards."""


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.__name__)
def test_no_source_computes_a_path_out_of_its_package(package):
    offenders = []
    for path in sorted(Path(package.__path__[0]).rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        ast.parse(text)  # a source the installed package cannot even parse would be found here too
        offenders += [f"{path.name}:{number}: {line.strip()}" for number, line in enumerate(text.splitlines(), 1)
                      if CLIMBING.search(line) and not line.lstrip().startswith("#")]
    assert not offenders, "paths leaving the package (ship the file as package data, read it with importlib.resources):\n" + "\n".join(offenders)
