"""The sparse direct solvers of the FEM: PARDISO (MKL called directly) against SuperLU."""

import os
import threading
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from workflow.models import analytical
from workflow.models.fem import FemSettings
from workflow.models.fem import solvers
from workflow.models.fem.accuracy import mesh_for_level
from workflow.models.fem.assembly import assemble_system
from workflow.models.fem.evaluate import discretise
from workflow.models.fem.mesh import quarter_plate_mesh
from workflow.models.plate import ORIGINAL_PLATE

pytestmark = pytest.mark.skipif("pardiso" not in solvers.available_solvers(), reason="pypardiso is not installed")


def test_pardiso_solves_the_indefinite_shifted_matrix_like_superlu_without_refinement(monkeypatch):
    settings = FemSettings(elements_per_ceramic=4, elements_per_layer=2, elements_across_half_width=3)
    system = assemble_system(quarter_plate_mesh(ORIGINAL_PLATE, settings), ORIGINAL_PLATE, 15.0)
    shift = (2 * np.pi * float(analytical.resonance_frequency(ORIGINAL_PLATE))) ** 2
    matrix = system.stiffness - shift * system.mass
    rhs = np.random.default_rng(0).standard_normal((matrix.shape[0], 3))
    factor = solvers.factorise(matrix)
    mine = factor.solve(rhs)
    assert factor._analysis.iparm[7] == 0  # no iterative refinement steps in the solves
    # and still accurate, and a vector is solved like a column
    assert np.linalg.norm(matrix @ mine - rhs) <= 1e-10 * np.linalg.norm(rhs)
    assert np.allclose(factor.solve(rhs[:, 1]), mine[:, 1], rtol=1e-10, atol=0)
    monkeypatch.setenv(solvers.SOLVER_VARIABLE, "superlu")
    reference = solvers.factorise(matrix).solve(rhs)
    assert np.abs(mine - reference).max() <= 1e-8 * np.abs(reference).max()


def _shifted_system(level: int):
    _, system, _ = discretise(ORIGINAL_PLATE, 15.0, mesh_for_level(ORIGINAL_PLATE, level))
    return system, (2 * np.pi * float(analytical.resonance_frequency(ORIGINAL_PLATE))) ** 2


def test_factorisations_of_one_structure_share_its_analysis_and_each_solves_its_own_matrix():
    system, shift = _shifted_system(2)
    first, second = system.shifted(shift), system.shifted(1.1 * shift)
    rhs = np.random.default_rng(1).standard_normal(first.shape[0])
    factor_1 = solvers.factorise(first)
    factor_2 = solvers.factorise(second)
    assert factor_1._analysis is factor_2._analysis  # the pattern's structure is analysed once
    for factor, matrix in ((factor_1, first), (factor_2, second), (factor_1, first)):  # numbers factorised again
        assert np.linalg.norm(matrix @ factor.solve(rhs) - rhs) <= 1e-10 * np.linalg.norm(rhs)
    private = first.copy()  # a writeable structure is not shared: its own analysis
    assert solvers.factorise(private)._analysis is not factor_1._analysis


def test_a_factorisation_after_solves_under_a_one_thread_limit_does_not_crash():
    """Regression: PARDISO phases run with other MKL threads than the analysis made the next factorisation segfault
    (a crash takes the test's worker down, which fails the run)."""
    system, shift = _shifted_system(2)
    rhs = np.ones(system.mass.shape[0])
    factor = solvers.factorise(system.shifted(shift))
    with threadpool_limits(limits=1, user_api="blas"):
        factor.solve(rhs), factor.solve(np.column_stack([rhs, rhs]))
    again = system.shifted(0.9 * shift)
    assert np.linalg.norm(again @ solvers.factorise(again).solve(rhs) - rhs) <= 1e-10 * np.linalg.norm(rhs)


def test_a_factor_released_while_its_analysis_is_busy_does_not_deadlock():
    """Regression: a factor's finalizer (which releases its numbers) can run inside a call on the same analysis, when
    memory is allocated; with a plain lock the test's worker hung."""
    system, shift = _shifted_system(2)
    factor = solvers.factorise(system.shifted(shift))
    analysis = factor._analysis
    finished = threading.Event()

    def release_inside_a_call():
        with analysis.lock:
            analysis.release(analysis.holder)
        finished.set()

    worker = threading.Thread(target=release_inside_a_call, daemon=True)
    worker.start()
    worker.join(timeout=30)
    assert finished.is_set()
    rhs = np.ones(system.mass.shape[0])  # the released numbers are factorised again for the next solve
    assert np.linalg.norm(system.shifted(shift) @ factor.solve(rhs) - rhs) <= 1e-10 * np.linalg.norm(rhs)


def test_mkl_is_loaded_from_the_mkl_package_record_without_searching_or_leaving_the_variable(monkeypatch):
    monkeypatch.delenv(solvers.MKL_VARIABLE, raising=False)
    runtime = solvers._installed_mkl_runtime()
    assert runtime is not None and "libmkl_rt" in runtime
    solvers._pypardiso.cache_clear()
    try:
        assert solvers._pypardiso().libmkl._name == runtime
        assert solvers.MKL_VARIABLE not in os.environ
    finally:
        solvers._pypardiso.cache_clear()
