"""Content-addressed disk cache: hits on rerun, reuse on refined grids, keys that follow the inputs."""

import dataclasses
import io
import pickle
import sys
from pathlib import Path

import numpy as np
import pytest

from workflow.execution import datafile
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


def test_writes_are_atomic_and_unreadable_entries_are_misses(tmp_path, capsys):
    cache = EvaluationCache(tmp_path)
    cache.store("ab" * 32, {"value": 1})
    assert cache.load("ab" * 32) == (True, {"value": 1})
    assert not list(Path(tmp_path).rglob("*.tmp"))
    path = next(Path(tmp_path).rglob("*.npz"))
    path.write_bytes(b"garbage")
    assert cache.load("ab" * 32) == (False, None)
    assert "ignoring cache entry" in capsys.readouterr().err


class _Plant:
    """Pickles to a call of ``open(marker, "w")``: code that must never run on loading."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_a_planted_pickle_is_never_executed(tmp_path, capsys):
    """A cache entry replaced by a pickle that runs code is ignored, not loaded."""
    cache, key, marker = EvaluationCache(tmp_path / "cache"), "cd" * 32, tmp_path / "planted-code-ran"
    cache.store(key, 1.0)
    path = next((tmp_path / "cache").rglob("*.npz"))
    path.write_bytes(pickle.dumps(_Plant(marker)))
    assert pickle.loads(path.read_bytes()) and marker.exists()  # the plant works when unpickled...
    marker.unlink()
    assert cache.load(key) == (False, None)  # ...and the cache does not unpickle it
    assert not marker.exists()
    assert "ignoring cache entry" in capsys.readouterr().err


def test_foreign_types_and_edited_entries_are_refused(tmp_path):
    """Only the project's dataclasses are rebuilt, and a tree edited after writing fails its checksum."""
    data = datafile.dumps({"plate": ORIGINAL_PLATE})
    archive = dict(np.load(io.BytesIO(data), allow_pickle=False))
    text = str(archive["tree"][()])
    assert "workflow.models.plate:Plate" in text
    for forged in (text.replace("workflow.models.plate:Plate", "os:system"), text.replace("24", "25")):
        buffer = io.BytesIO()
        np.savez(buffer, **{**archive, "tree": np.array(forged)})
        with pytest.raises(datafile.DataFileError):
            datafile.loads(buffer.getvalue())
    with pytest.raises(TypeError):
        datafile.dumps({"f": square})


def test_values_round_trip_bit_identically():
    value = {
        "tuple": (1, 2.5, "x", None, True),
        "floats": [0.1, float("inf"), -0.0, 1e-300],
        "complex": 1 + 2j,
        "array": np.linspace(0, 1, 7) * (1 + 1e-3j),
        "scalar": np.float64(0.1) / 3,
        "int keys": {1: "a", (2, 3): "b"},
        "plate": ORIGINAL_PLATE.with_(wavelength=np.array([23e-3, 24e-3])),
        "path": Path("reports") / "x.png",
    }
    back = datafile.loads(datafile.dumps(value))
    assert back.keys() == value.keys()
    assert back["tuple"] == value["tuple"] and type(back["tuple"]) is tuple
    assert [np.float64(x).tobytes() for x in back["floats"]] == [np.float64(x).tobytes() for x in value["floats"]]
    assert back["complex"] == value["complex"] and back["int keys"] == value["int keys"]
    assert back["array"].tobytes() == value["array"].tobytes() and back["array"].dtype == value["array"].dtype
    assert type(back["scalar"]) is np.float64 and back["scalar"] == value["scalar"]
    assert type(back["plate"]) is type(value["plate"])
    assert back["plate"].wavelength.tobytes() == value["plate"].wavelength.tobytes()
    assert back["path"] == value["path"]


def test_default_directory_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(CACHE_VARIABLE, str(tmp_path))
    assert default_directory() == tmp_path
    monkeypatch.delenv(CACHE_VARIABLE)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "user-cache"))  # platformdirs' Linux rule
    monkeypatch.chdir(tmp_path / "..")
    expected = tmp_path / "user-cache" / "tactile" if sys.platform.startswith("linux") else None
    assert default_directory().is_absolute(), "not relative to whatever folder the user is in"
    assert expected is None or default_directory() == expected


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


def _assert_identical(a, b, where="value"):
    """Equal to the bit, type for type, through dataclasses, containers and arrays."""
    assert type(a) is type(b), where
    if dataclasses.is_dataclass(a):
        for field in dataclasses.fields(a):
            _assert_identical(getattr(a, field.name), getattr(b, field.name), f"{where}.{field.name}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_identical(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for key in a:
            _assert_identical(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, (np.ndarray, np.generic)):
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), where
    else:
        assert a == b or (a != a and b != b), where


def test_cached_fem_results_are_bit_identical_to_fresh_ones(tmp_path):
    """Every field of a FEM result with design sensitivities, read back from the cache, equals a fresh solve."""
    settings = FemSettings(elements_per_ceramic=2, elements_across_half_width=2, n_modes=3)
    fresh = FemModel(settings=settings, cache=None, scheduler="synchronous").results(ORIGINAL_PLATE, with_tangents=True)
    FemModel(settings=settings, cache=EvaluationCache(tmp_path), scheduler="synchronous").results(
        ORIGINAL_PLATE, with_tangents=True
    )
    reader = FemModel(settings=settings, cache=EvaluationCache(tmp_path), scheduler="synchronous")
    cached = reader.results(ORIGINAL_PLATE, with_tangents=True)
    assert reader.cache.hits == 1 and reader.cache.misses == 0
    _assert_identical(cached, fresh)
