"""Content-addressed disk cache: hits on rerun, reuse on refined grids, keys that follow the inputs."""

from pathlib import Path

import numpy as np

from workflow.execution.cache import (
    CACHE_VARIABLE,
    EvaluationCache,
    cached_map,
    content_key,
    default_directory,
)
from workflow.models.fem import FemSettings
from workflow.models.plate import ORIGINAL_PLATE
from workflow.optimise.fem_model import FemModel, FemTask, describe_fem_task

CALLS = []


def square(x):
    CALLS.append(x)
    return x * x


def describe(x):
    return {"model": "square", "x": x}


def test_rerun_is_served_from_disk_and_refined_grid_reuses_points(tmp_path):
    cache = EvaluationCache(tmp_path)
    CALLS.clear()
    coarse_grid = list(np.linspace(0.0, 1.0, 5))
    first = cached_map(square, coarse_grid, describe, cache, scheduler="synchronous")
    assert first == [x * x for x in coarse_grid] and len(CALLS) == 5
    CALLS.clear()
    again = cached_map(square, coarse_grid, describe, EvaluationCache(tmp_path), scheduler="synchronous")
    assert again == first and CALLS == []
    CALLS.clear()
    refined = list(np.linspace(0.0, 1.0, 9))  # every other point already known
    cached_map(square, refined, describe, cache, scheduler="synchronous")
    assert sorted(CALLS) == sorted(refined[1::2])


def test_duplicates_in_one_batch_are_computed_once(tmp_path):
    CALLS.clear()
    assert cached_map(square, [2.0, 2.0, 3.0], describe, EvaluationCache(tmp_path), scheduler="synchronous") == [4.0, 4.0, 9.0]
    assert sorted(CALLS) == [2.0, 3.0]


def test_key_follows_every_input():
    task = FemTask(ORIGINAL_PLATE, 54.0, 15.0, FemSettings())
    key = content_key(describe_fem_task(task))
    assert key == content_key(describe_fem_task(FemTask(ORIGINAL_PLATE, 54.0, 15.0, FemSettings())))
    variants = [
        FemTask(ORIGINAL_PLATE, 54.0, 15.0, FemSettings(elements_per_ceramic=8)),
        FemTask(ORIGINAL_PLATE, 55.0, 15.0, FemSettings()),
        FemTask(ORIGINAL_PLATE, 54.0, 10.0, FemSettings()),
        FemTask(ORIGINAL_PLATE.with_(width=55e-3), 54.0, 15.0, FemSettings()),
    ]
    keys = {content_key(describe_fem_task(v)) for v in variants}
    assert key not in keys and len(keys) == len(variants)


def test_writes_are_atomic_and_unreadable_entries_are_misses(tmp_path):
    cache = EvaluationCache(tmp_path)
    cache.store("ab" * 32, {"value": 1})
    assert cache.load("ab" * 32) == (True, {"value": 1})
    assert not list(Path(tmp_path).rglob("*.tmp"))
    path = next(Path(tmp_path).rglob("*.pkl"))
    path.write_bytes(b"garbage")
    assert cache.load("ab" * 32) == (False, None)


def test_default_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_VARIABLE, str(tmp_path))
    assert default_directory() == tmp_path
    monkeypatch.delenv(CACHE_VARIABLE)
    assert default_directory() == Path(".cache") / "tactile"


def test_fem_model_rerun_is_faster_and_identical(tmp_path):
    settings = FemSettings(elements_per_ceramic=2, elements_across_half_width=2, n_modes=3)
    plates = ORIGINAL_PLATE.with_(wavelength=np.array([23e-3, 24e-3]))
    first = FemModel(settings=settings, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    deflection, frequency = first(plates)
    second = FemModel(settings=settings, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    again = second(plates)
    assert second.cache.hits == 2 and second.cache.misses == 0
    np.testing.assert_array_equal(again[0], deflection)
    np.testing.assert_array_equal(again[1], frequency)
    assert frequency[0] > frequency[1]  # shorter wavelength resonates higher
