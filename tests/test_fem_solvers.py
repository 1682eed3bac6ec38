"""The sparse direct solvers of the FEM: PARDISO (direct MKL calls, orderings reused) against SuperLU."""

import numpy as np
import pytest

from workflow.models import analytical
from workflow.models.fem import FemSettings
from workflow.models.fem import solvers
from workflow.models.fem.assembly import assemble_system
from workflow.models.fem.mesh import quarter_plate_mesh
from workflow.models.plate import ORIGINAL_PLATE

pytestmark = pytest.mark.skipif("pardiso" not in solvers.available_solvers(), reason="pypardiso is not installed")


def _shifted(plate):
    """K - sigma M and K of a small mesh."""
    settings = FemSettings(elements_per_ceramic=4, elements_per_layer=2, elements_across_half_width=3)
    system = assemble_system(quarter_plate_mesh(plate, settings), plate, 15.0)
    shift = (2 * np.pi * float(analytical.resonance_frequency(plate))) ** 2
    return system.stiffness - shift * system.mass, system.stiffness


def test_pardiso_solves_the_indefinite_shifted_matrix_like_superlu_and_reuses_its_ordering(monkeypatch):
    matrix, stiffness = _shifted(ORIGINAL_PLATE)
    rhs = np.random.default_rng(0).standard_normal((matrix.shape[0], 3))
    solvers._orderings.clear()
    first = solvers.factorise(matrix, pattern=stiffness).solve(rhs)
    assert len(solvers._orderings) == 1
    # another geometry of the same topology (its K - sigma M cancels exactly elsewhere): the cached ordering serves
    other, other_stiffness = _shifted(ORIGINAL_PLATE.with_(resonator_thickness=1.5e-3))
    reused = solvers.factorise(other, pattern=other_stiffness).solve(rhs)
    assert len(solvers._orderings) == 1
    solvers.factorise(other)  # keyed by its own pattern: a new ordering
    assert len(solvers._orderings) == 2
    monkeypatch.setenv(solvers.SOLVER_VARIABLE, "superlu")
    for mine, shifted in ((first, matrix), (reused, other)):
        reference = solvers.factorise(shifted).solve(rhs)
        # no iterative refinement in the solves, and still accurate
        assert np.linalg.norm(shifted @ mine - rhs) <= 1e-10 * np.linalg.norm(rhs)
        assert np.abs(mine - reference).max() <= 1e-8 * np.abs(reference).max()
    assert solvers.factorise(matrix).solve(rhs[:, 0]).shape == (matrix.shape[0],)
