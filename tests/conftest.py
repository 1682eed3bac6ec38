"""Shared pytest configuration: figures render off-screen; Hypothesis profiles; which package is under test.

The header names the folder ``workflow`` was imported from. With ``TACTILE_REQUIRE_INSTALLED=1`` (set by
``.ci/run``) the session stops at once when that folder is the checkout rather than an installed package,
so CI always tests what a user installs.

Hypothesis profiles (tests/cli/test_fuzz.py): ``default`` runs a few dozen examples per property
(a few seconds in all); ``long`` runs thousands, for the tests marked ``slow`` or for every
property with ``HYPOTHESIS_PROFILE=long``.
"""

import os
from pathlib import Path

import matplotlib
import pytest
from hypothesis import HealthCheck, settings

matplotlib.use("Agg")

settings.register_profile("default", max_examples=40, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("long", max_examples=3000, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))

CHECKOUT = Path(__file__).resolve().parents[1]
"""The source tree the tests belong to."""


def _package_folder() -> Path:
    import workflow

    return Path(workflow.__path__[0]).resolve()


def pytest_report_header(config):
    return f"tactile under test: {_package_folder()}"


THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def pytest_configure(config):
    """Under pytest-xdist, the workers share the cores: each gets its share of threads for BLAS and PARDISO.

    Set before the workers start (they inherit the environment), unless the variables are set already.  On the 2-core
    machine two workers each running a 2-threaded factorisation oversubscribed the cores: the default suite took
    167-193 s with it, 153 s without (``/usr/bin/time``, user time 306 s -> 271 s)."""
    workers = len(getattr(config.option, "tx", None) or [])
    if workers > 1 and not os.environ.get("PYTEST_XDIST_WORKER"):
        share = str(max(1, (os.cpu_count() or 1) // workers))
        for name in THREAD_VARIABLES:
            os.environ.setdefault(name, share)


HEAVY_FIRST = (
    "pipeline/test_run.py",
    "calibration/test_coverage_studies.py",
    "models/test_fem_accuracy.py",
    "damping/test_fit_damping.py",
    "calibration/test_calibration.py",
    "calibration/test_calibration_likelihood.py",
    "models/test_fem.py",
    "damping/test_damping_laws.py",
    "pipeline/test_loop.py",
    "damping/test_softening.py",
)
"""Modules whose fixtures and tests take 7-45 s each (``--durations``), heaviest first: they run first.

pytest-xdist hands whole modules (``--dist loadscope``) to the workers in collection order (``--no-loadscope-reorder``: by default it orders them by their number of tests); the tiny ``tactile run``
(45 s) collected near the end left one worker busy while the other idled, and the suite's wall time varied by 20 s
from run to run with the same CPU time.  Started first, the long modules overlap and the short ones fill the gaps."""


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session, config, items):
    """Put the modules of :data:`HEAVY_FIRST` first, in its order (the rest keep theirs)."""
    tests = Path(__file__).parent  # as pytest names the items' paths
    missing = [name for name in HEAVY_FIRST if not (tests / name).is_file()]
    if missing:
        raise pytest.UsageError(f"tests/conftest.py HEAVY_FIRST names modules that do not exist: {missing}")
    rank = {tests / name: k for k, name in enumerate(HEAVY_FIRST)}
    items.sort(key=lambda item: rank.get(item.path, len(rank)))


def pytest_sessionstart(session):
    if os.environ.get("TACTILE_REQUIRE_INSTALLED") == "1" and _package_folder() == CHECKOUT / "workflow":
        raise pytest.UsageError(f"workflow was imported from the checkout ({_package_folder()}), not from an "
                                "installed package: run the installed environment's pytest, not python -m pytest")


@pytest.fixture(scope="session")
def calibration_cache_dir(tmp_path_factory):
    """One FEM cache for every calibration test (the coarse evaluations are shared between modules).

    Under pytest-xdist it is one folder for all the workers of the run (beside their own temporary folders): a module
    then finds what a module on another worker has already evaluated (the same plates' surrogates recur from module to
    module).  The evaluations are deterministic and the cache's writes atomic, so workers evaluating the same plate at
    the same time only both compute it.  Each run starts with an empty cache."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        folder = tmp_path_factory.getbasetemp().parent / "calibration-cache"
        folder.mkdir(exist_ok=True)
        return folder
    return tmp_path_factory.mktemp("calibration-cache")


@pytest.fixture(scope="session")
def coarse_model(calibration_cache_dir):
    """The FEM on the coarse mesh of calibration_setup.COARSE, cached, in process."""
    from calibration_setup import COARSE

    from workflow.execution.cache import EvaluationCache
    from workflow.optimise.fem_model import FemModel

    return FemModel(settings=COARSE, cache=EvaluationCache(calibration_cache_dir), scheduler="synchronous")


@pytest.fixture
def coarse_cli(monkeypatch, calibration_cache_dir):
    """The commands' FEM on the coarse mesh, in process, sharing the calibration tests' cache."""
    from calibration_setup import COARSE

    import workflow.optimise.fem_model as fem_evaluations

    monkeypatch.setenv("TACTILE_CACHE", str(calibration_cache_dir))
    model = fem_evaluations.FemModel

    def coarse(**options):
        return model(**{**options, "settings": COARSE, "scheduler": "synchronous"})

    monkeypatch.setattr(fem_evaluations, "FemModel", coarse)
