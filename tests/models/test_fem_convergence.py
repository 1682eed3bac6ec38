"""Mesh convergence of the FEM cost (fast: coarse meshes; slow: the study of docs/fem.md)."""

import pytest

from workflow.models.fem import FemSettings, evaluate_fem
from workflow.models.fem.convergence import convergence_study, richardson
from workflow.models.fem.settings import DEFAULT_SETTINGS
from workflow.models.plate import ORIGINAL_PLATE

CLEAN = ORIGINAL_PLATE.with_(width=55e-3)
"""Original plate at a width without transverse interference, so the best mode stays the same mode."""
COARSEST = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=2)


def test_richardson_recovers_a_known_rate():
    factors = (1, 2, 4)
    values = [3.0 + 0.7 * r**-2.0 for r in factors]
    rate, limit = richardson(factors, values)
    assert rate == pytest.approx(2.0, rel=1e-9)
    assert limit == pytest.approx(3.0, rel=1e-12)


def test_frequency_differences_shrink_under_refinement():
    study = convergence_study(CLEAN, 54.0, 15.0, COARSEST, factors=(1, 2, 3))
    f1, f2, f3 = study.frequencies
    assert abs(f2 - f3) < 0.5 * abs(f1 - f2)
    rate, limit = study.frequency_extrapolation()
    assert rate > 1.0
    assert abs(f3 - limit) < abs(f2 - limit) < abs(f1 - limit)
    assert study.n_dofs[0] < study.n_dofs[1] < study.n_dofs[2]


@pytest.mark.slow
def test_default_mesh_is_within_half_a_percent_of_the_extrapolated_frequency():
    """Study of docs/fem.md: base (2, 1, 1, 2) refined 2, 3, 4 times (up to ~63k dofs)."""
    study = convergence_study(CLEAN, 54.0, 15.0, COARSEST, factors=(2, 3, 4))
    rate, limit = study.frequency_extrapolation()
    assert 1.0 < rate < 4.5
    default = evaluate_fem(CLEAN, 54.0, 15.0, DEFAULT_SETTINGS)
    assert abs(default.frequency / limit - 1) < 5e-3
    _, deflection_limit = study.deflection_extrapolation()
    assert abs(default.deflection / deflection_limit - 1) < 0.05
