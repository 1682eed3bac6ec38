"""The sparse direct solvers of the FEM: PARDISO (MKL called directly) against SuperLU."""

import numpy as np
import pytest

from workflow.models import analytical
from workflow.models.fem import FemSettings
from workflow.models.fem import solvers
from workflow.models.fem.assembly import assemble_system
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
    assert factor._iparm[7] == 0  # no iterative refinement steps in the solves
    # and still accurate, and a vector is solved like a column
    assert np.linalg.norm(matrix @ mine - rhs) <= 1e-10 * np.linalg.norm(rhs)
    assert np.allclose(factor.solve(rhs[:, 1]), mine[:, 1], rtol=1e-10, atol=0)
    monkeypatch.setenv(solvers.SOLVER_VARIABLE, "superlu")
    reference = solvers.factorise(matrix).solve(rhs)
    assert np.abs(mine - reference).max() <= 1e-8 * np.abs(reference).max()
