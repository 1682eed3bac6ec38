"""``tactile run``'s damping step on a small configuration: sweeps and ring-downs simulated with softening, fitted
jointly with the softening and the drift; the report and fit.json show them and the ring-down agreement."""

import json

from test_run import TINY

from workflow.pipeline.config import load_config
from workflow.pipeline.report import write_report
from workflow.pipeline.runner import RunContext, run_steps
from workflow.pipeline.steps import STEPS


def test_the_run_fits_sweeps_and_ringdowns_jointly_and_reports_them(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY + "[run]\ncache = false\n")
    config = load_config(path)
    context = RunContext(config=config, out=tmp_path)
    run_steps(context, [step for step in STEPS if step.key in ("logs", "damping_fit")])
    assert [p.name for p in context.results["logs"]] == ["simulated_campaign.csv", "simulated_ringdown.csv"]
    summary = json.loads((tmp_path / "damping" / "fit.json").read_text())
    assert summary["forward_model"] == {"softening": True, "drift": True}
    kappa = summary["parameters"]["kappa"]
    assert kappa["p05"] <= config["simulator"]["softening_s2_m2"] <= kappa["p95"]
    ringdown = summary["ringdown"]
    assert ringdown["n_bursts"] == 2 and ringdown["n_samples"] == 80
    assert [b["voltage_v"] for b in ringdown["bursts"]] == [5.0, 15.0]
    assert ringdown["agreement"]["agree"] and len(ringdown["agreement"]["v_m_s"]) == 5
    report = write_report(context).read_text()
    assert "**Ring-downs** (2 bursts, 80 samples" in report
    assert "Agreement of the two measurements of Q" in report and "amplitude softening" in report
    assert "damping/ringdown.png" in report and (tmp_path / "damping" / "ringdown.png").is_file()
