"""The benchmark on the environment with communication faults (issue 23, ``tracking_lossy``), tiny budget: it runs
end to end like any other env and every row has the degradation ``J / J_paper,fault-free`` (the paper's controller
on ``tracking`` on the same episodes), with the main ratio's statistics; ``--env all`` stays the fault-free tasks."""
from __future__ import annotations

import csv
import json
import os

import numpy as np
import pytest

from agents.benchmark.driver import run_benchmark
from agents.benchmark.plan import AGENTS, ANALYTIC, BUDGETS, PAPER, plan_runs
from agents.benchmark.report import DEGRADATION_COLUMNS, _fault_free_cost, write_env_report
from agents.config.envs import TASKS
from dobs_envs.cli import main

TINY = BUDGETS["tiny"]
ENV = "tracking_lossy"


@pytest.fixture(scope="module")
def lossy_run(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("bench_lossy"))
    summ = run_benchmark(ENV, "tiny", out, progress=False, workers=1, agents=["ppo", "ppo_ma"])
    doc = json.load(open(os.path.join(out, ENV, "results.json")))
    return out, summ, doc


def test_runs_end_to_end_with_every_policy_and_the_degradation_columns(lossy_run):
    out, summ, doc = lossy_run
    expected = {AGENTS["ppo"].label, AGENTS["ppo_ma"].label} | set(ANALYTIC)
    assert {r["policy"] for r in doc["results"]} == expected
    for f in ("results.csv", "results.md", "error_norms.png", "learning_curves.png"):
        assert os.path.getsize(os.path.join(out, ENV, f)) > 0, f
    assert doc["fault_free"]["env"] == "tracking" and "degradation" in doc["metrics_doc"]
    assert summ["fault_free"] == {ENV: "tracking"} and summ["degradation"] == doc["metrics_doc"]["degradation"]
    for _, header in DEGRADATION_COLUMNS:
        assert header in doc["table"] and header in summ["tables"][ENV]
    md = open(os.path.join(out, ENV, "results.md")).read()
    assert DEGRADATION_COLUMNS[0][1] in md and "communication faults" in md and "on tracking (no faults)" in md
    with open(os.path.join(out, ENV, "results.csv")) as fh:
        rows = list(csv.DictReader(fh))
    assert {r["policy"] for r in rows} == expected
    for r in rows:
        assert float(r["degradation_ci_low"]) <= float(r["degradation_iqm"]) <= float(r["degradation_ci_high"])
        assert np.isfinite(float(r["degradation_mean"]))
    res = {r["policy"]: r for r in summ["results"][ENV]}
    assert res[PAPER]["cost_ratio_iqm"] == 1.0  # the main ratio is still the paper on the faulted episode
    assert res[AGENTS["ppo"].label]["runs"] == TINY["seeds"]


def test_degradation_is_the_main_ratio_statistics_over_the_fault_free_paper(lossy_run):
    """Recomputed here from the stored per-episode costs with agents.stats: IQM, CI and mean over runs of the
    run means of J / J_paper,fault-free; the reference costs are those of the paper's controller on tracking."""
    from agents.evaluate import evaluate_policy
    from agents.stats import interval_estimate, mean_estimate, run_scores
    from baselines.policies import SeparationPolicy
    from dobs_envs import tracking_v0

    _, _, doc = lossy_run
    ideal = tracking_v0.parallel_env(**doc["env_kwargs"])
    ref = np.array([r.cost for r in evaluate_policy(ideal, SeparationPolicy(ideal), doc["episodes"],
                                                    doc["eval_seeds"][0], parallel=True)])
    ideal.close()
    np.testing.assert_array_equal(ref, doc["fault_free"]["paper_cost"])
    paper = np.array(doc["paper_cost"])
    assert not np.array_equal(ref, paper)  # the faults change the paper's cost
    for r in doc["results"]:
        cost = np.array([[e["cost"] for e in run] for run in doc["episodes_detail"][r["policy"]].values()])
        s = run_scores(cost / ref)
        est, mean = interval_estimate(s), mean_estimate(s)
        assert r["degradation_run_scores"] == pytest.approx(s.tolist(), rel=1e-12)
        assert (r["degradation_iqm"], r["degradation_ci_low"], r["degradation_ci_high"]) == \
            pytest.approx((est["iqm"], est["ci_low"], est["ci_high"]), rel=1e-12)
        assert (r["degradation_mean"], r["degradation_mean_ci_low"], r["degradation_mean_ci_high"]) == \
            pytest.approx((mean["mean"], mean["ci_low"], mean["ci_high"]), rel=1e-12)
    rows = {r["policy"]: r for r in doc["results"]}
    assert rows[PAPER]["degradation_mean"] == pytest.approx(float(np.mean(paper / ref)), rel=1e-12)


def test_same_episodes_on_both_networks(lossy_run):
    """The fault-free reference was evaluated on the faulted env's episodes: same seeds, same x(0)."""
    _, _, doc = lossy_run
    ff = doc["fault_free"]["episodes"]
    assert [e["seed"] for e in ff] == doc["eval_seeds"]
    for name, runs in doc["episodes_detail"].items():
        for eps in runs.values():
            np.testing.assert_array_equal([e["x0"] for e in eps], [e["x0"] for e in ff], err_msg=name)


def test_other_episodes_are_refused(lossy_run):
    _, _, doc = lossy_run
    paper = {"episodes": doc["episodes_detail"][PAPER]["deterministic"]}
    good = {"episodes": doc["fault_free"]["episodes"]}
    np.testing.assert_array_equal(_fault_free_cost(ENV, paper, good), doc["fault_free"]["paper_cost"])
    moved = {"episodes": [dict(e, x0=[v + 1e-9 for v in e["x0"]]) for e in good["episodes"]]}
    with pytest.raises(ValueError, match="not evaluated on the same episodes"):
        _fault_free_cost(ENV, paper, moved)
    with pytest.raises(ValueError, match="not evaluated on the same episodes"):
        _fault_free_cost(ENV, paper, {"episodes": good["episodes"][::-1]})


def test_the_reference_is_required_exactly_for_faulted_envs(tmp_path):
    plan = plan_runs(ENV, "tiny", str(tmp_path), agents=["ppo"])
    with pytest.raises(ValueError, match="missing"):
        write_env_report(str(tmp_path), ENV, plan, {}, {PAPER: {"episodes": []}})
    plan = plan_runs("tracking", "tiny", str(tmp_path), agents=["ppo"])
    with pytest.raises(ValueError, match="given for an env without faults"):
        write_env_report(str(tmp_path), "tracking", plan, {}, {PAPER: {"episodes": []}}, {"episodes": []})


def test_cli_prints_the_degradation_table(lossy_run, capsys):
    out, _, _ = lossy_run
    assert main(["benchmark", "--env", ENV, "--budget", "tiny", "--out", out, "--no-progress", "--workers", "1",
                 "--agents", "ppo,ppo_ma"]) == 0
    text = capsys.readouterr().out
    assert DEGRADATION_COLUMNS[0][1] in text and "J_paper,fault-free" in text and "on tracking (no faults)" in text


def test_env_all_is_the_fault_free_tasks(tmp_path):
    plan = plan_runs("all", "tiny", str(tmp_path))
    assert plan.envs == list(TASKS) == ["tracking", "disturbance_rejection", "hetero_mas", "random_network"]
    assert ENV in plan_runs(ENV, "tiny", str(tmp_path)).envs
