"""``tactile run`` gives the same numbers locally and on a Dask cluster (issue 6)."""


import numpy as np
from dataclasses import replace

import pytest
from tiny_config import TINY as SMALL

from workflow.pipeline.config import load_config
from workflow.pipeline.runner import RunContext, RunResults, run_steps
from workflow.pipeline.steps import STEPS

# a fixed tiny mesh (accuracy 0): the distribution of FEM evaluations is what is tested, not the accuracy control
# and the damping fit of sweeps alone (the ring-downs and softening are tested in test_run)
TINY = (SMALL.replace("accuracy = 0.05", "accuracy = 0.0").replace("ringdown_voltages_v = [5.0, 15.0]", "ringdown_voltages_v = []")
        .replace("[damping]\n", "[damping]\nsoftening = false\ndrift = false\n") + "[run]\ncache = false\n")

DISTRIBUTED_STEPS = ("damped_design", "fem_optima", "fem_maps", "width_sweep")


def _run(context: RunContext, keys) -> RunResults:
    return run_steps(context, [step for step in STEPS if step.key in keys]).results


def test_fem_evaluations_on_a_dask_cluster_equal_the_local_ones(monkeypatch):
    """The distribution itself, quickly: a batch of plates on a local pool and on a Dask cluster (SuperLU)."""
    distributed = pytest.importorskip("distributed")
    from workflow.models.fem import FemSettings
    from workflow.models.plate import ORIGINAL_PLATE
    from workflow.optimise.fem_model import FemModel

    monkeypatch.setenv("TACTILE_SPARSE_SOLVER", "superlu")
    mesh = FemSettings(elements_per_ceramic=2, elements_per_layer=1, elements_across_half_width=2, n_modes=3)
    plates = [ORIGINAL_PLATE.with_(wavelength=w) for w in (22e-3, 24e-3, 26e-3)]
    local = FemModel(settings=mesh, scheduler=None).evaluate_plates(plates)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        remote = FemModel(settings=mesh, scheduler=cluster.scheduler_address).evaluate_plates(plates)
    for a, b in zip(local, remote):
        np.testing.assert_array_equal(a.probe_model.eigenvalues, b.probe_model.eigenvalues)
        assert a.deflection == b.deflection


@pytest.mark.slow
def test_local_and_dask_runs_give_identical_numbers(tmp_path, monkeypatch):
    """Bit-identical with SuperLU (PARDISO's threaded factorisation differs in the last bits between process layouts).

    The damping fit runs once (its laws are not distributed with one law); the steps that distribute their
    evaluations run locally and on the cluster from its results."""
    distributed = pytest.importorskip("distributed")
    monkeypatch.setenv("TACTILE_SPARSE_SOLVER", "superlu")
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    config = load_config(path)
    fitted = _run(RunContext(config=config, out=tmp_path / "fit"), ("logs", "analytical_optima", "damping_fit"))
    local = _run(RunContext(config=config, out=tmp_path / "local", results=replace(fitted)), DISTRIBUTED_STEPS)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        remote = _run(RunContext(config=config, out=tmp_path / "dask", scheduler=cluster.scheduler_address,
                                 results=replace(fitted)), DISTRIBUTED_STEPS)
    hp = 1e-3
    design_local, design_remote = local.damped_design[0].optima[hp], remote.damped_design[0].optima[hp]
    for name in design_local.draws:
        np.testing.assert_array_equal(design_local.draws[name], design_remote.draws[name])
    optimum_local, optimum_remote = local.fem_optima[hp].space_mapping, remote.fem_optima[hp].space_mapping
    assert optimum_local.optimum.deflection == optimum_remote.optimum.deflection
    assert optimum_local.fine_evaluations == optimum_remote.fine_evaluations
    np.testing.assert_array_equal(local.fem_maps[hp].deflection, remote.fem_maps[hp].deflection)
    np.testing.assert_array_equal(local.width_sweep.frequency, remote.width_sweep.frequency)
