"""The RL-versus-analytic benchmark end to end on the tiny budget (2 training seeds, 2 workers), and the CLI."""
from __future__ import annotations

import csv
import json
import os

import numpy as np
import pytest

from agents.benchmark.driver import run_benchmark
from agents.benchmark.plan import AGENTS, ANALYTIC, BUDGETS, default_agents
from dobs_envs.cli import main

TINY = BUDGETS["tiny"]
#: the agents the tiny budget trains by default (--trainer sb3; the jitted ones: tests/test_agents_benchmark_jax.py)
TINY_AGENTS = {k: TINY["agents"][k] for k in default_agents("tiny")}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("bench"))
    summ = run_benchmark("tracking", "tiny", out, progress=False, workers=2)
    doc = json.load(open(os.path.join(out, "tracking", "results.json")))
    return out, summ, doc


def test_files_and_every_policy(tiny_run):
    out, summ, doc = tiny_run
    for f in ("summary.json", "summary.png", "tracking/results.csv", "tracking/results.json", "tracking/results.md",
              "tracking/error_norms.png", "tracking/learning_curves.png"):
        assert os.path.getsize(os.path.join(out, f)) > 0, f
    expected = {AGENTS[k].label for k in TINY_AGENTS} | set(ANALYTIC)
    assert {r["policy"] for r in doc["results"]} == expected
    with open(os.path.join(out, "tracking", "results.csv")) as fh:
        rows = list(csv.DictReader(fh))
    assert {r["policy"] for r in rows} == expected
    for r in rows:
        for key in ("cost_ratio_iqm", "cost_ratio_ci_low", "cost_ratio_ci_high", "transient_cost_iqm",
                    "steady_state_error_iqm", "failure_rate"):
            assert np.isfinite(float(r[key])), key
        assert float(r["cost_ratio_ci_low"]) <= float(r["cost_ratio_iqm"]) <= float(r["cost_ratio_ci_high"])
    for name in expected:
        assert name in doc["table"]
    assert summ["tables"]["tracking"] == doc["table"]


def test_runs_per_agent_and_the_paper_is_the_unit(tiny_run):
    _, _, doc = tiny_run
    res = {r["policy"]: r for r in doc["results"]}
    for k in TINY_AGENTS:
        assert res[AGENTS[k].label]["runs"] == TINY["seeds"]
        assert res[AGENTS[k].label]["kind"] == ("hybrid" if AGENTS[k].hybrid else "RL")
    p = res["paper (separation)"]
    assert p["runs"] == 1 and p["cost_ratio_iqm"] == p["cost_ratio_ci_low"] == p["cost_ratio_ci_high"] == 1.0
    # 1-second episodes: the oracle already pulls x towards x_r while the open-loop plant drifts
    assert res["oracle (full state)"]["final_tracking_error_iqm"] < res["zero input"]["final_tracking_error_iqm"]
    # different training seeds give different agents
    eps = doc["episodes_detail"][AGENTS["ppo"].label]
    assert eps["s0"][0]["cost"] != eps["s1"][0]["cost"]


def test_rows_state_information_budget_and_run_level_statistics(tiny_run):
    """The training run is the statistical unit: each row's IQM, CI, mean and probability of
    improvement are those of agents.stats applied to the per-run scores recomputed here from the
    stored per-episode costs; every row says what it sees, learned rows their budget."""
    from agents.stats import improvement_estimate, interval_estimate, mean_estimate, run_scores

    _, _, doc = tiny_run
    paper = np.array(doc["paper_cost"])
    for r in doc["results"]:
        assert r["information"], r["policy"]
        eps = doc["episodes_detail"][r["policy"]]
        cost = np.array([[e["cost"] for e in run] for run in eps.values()])
        s = run_scores(cost / paper)
        assert r["run_scores"] == pytest.approx(s.tolist(), rel=1e-12)
        est, mean, poi = interval_estimate(s), mean_estimate(s), improvement_estimate(cost, paper)
        assert (r["cost_ratio_iqm"], r["cost_ratio_ci_low"], r["cost_ratio_ci_high"]) == \
            pytest.approx((est["iqm"], est["ci_low"], est["ci_high"]), rel=1e-12)
        assert (r["cost_ratio_mean"], r["poi"], r["poi_ci_low"]) == \
            pytest.approx((mean["mean"], poi["poi"], poi["ci_low"]), rel=1e-12)
        learned = r["kind"] != "analytic"
        assert (r["env_steps"] is not None) == learned and (r["train_seconds_median"] is not None) == learned
    rows = {r["policy"]: r for r in doc["results"]}
    assert rows["paper (separation)"]["poi"] == 0.5  # ties with itself on every episode
    assert rows[AGENTS["ppo"].label]["env_steps"] == TINY["agents"]["ppo"]
    assert rows[AGENTS["ppo"].label]["information"] != rows[AGENTS["ppo_ma"].label]["information"]
    assert rows[AGENTS["ppo"].label]["train_seconds_median"] > 0


@pytest.mark.parametrize("kwargs, match", [
    ({"eval_seed": 20_000}, "evaluation range"),     # tuning episodes are not evaluation episodes
    ({"eval_seed": 19_999, "episodes": 2}, "evaluation range"),
    ({"seed": 9_990}, "training range"),              # its env copies would reach the evaluation range
    ({"seed": -1}, "training range"),
])
def test_seed_ranges_are_disjoint(kwargs, match, tmp_path):
    from agents.benchmark.plan import plan_runs

    with pytest.raises(ValueError, match=match):
        plan_runs("tracking", "tiny", str(tmp_path), **kwargs)


def test_same_seeds_and_initial_states_for_every_policy_and_run(tiny_run):
    _, _, doc = tiny_run
    seeds = doc["eval_seeds"]
    assert len(seeds) == TINY["episodes"] and len(set(seeds)) == len(seeds)
    ref = None
    for name, runs in doc["episodes_detail"].items():
        for run, eps in runs.items():
            assert [e["seed"] for e in eps] == seeds, (name, run)
            x0 = np.array([e["x0"] for e in eps])
            if ref is None:
                ref = x0
            np.testing.assert_array_equal(x0, ref, err_msg=f"{name} {run}")
    assert not np.array_equal(ref[0], ref[1])


def test_learning_curves_cover_training(tiny_run):
    out, _, doc = tiny_run
    for k, steps in TINY_AGENTS.items():
        c = doc["learning_curves"][AGENTS[k].label]
        assert c is not None and c["env_steps"][0] <= steps // TINY["curve_points"] and c["env_steps"][-1] >= steps
        assert all(lo <= m <= hi for lo, m, hi in zip(c["ci_low"], c["iqm"], c["ci_high"]))
        assert os.path.exists(os.path.join(out, "models", "tracking", "tiny", k, "s0", "curve.json"))


def test_cli_reuses_finished_runs(tiny_run, capsys):
    out, _, _ = tiny_run
    assert main(["benchmark", "--env", "tracking", "--budget", "tiny", "--out", out, "--no-progress",
                 "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "paper (separation)" in printed and "PPO (centralised)" in printed and "95% CI" in printed
    doc = json.load(open(os.path.join(out, "tracking", "results.json")))
    assert all(v == 0.0 for secs in doc["train_seconds"].values() for v in secs)


def test_markdown_table_has_every_policy_and_the_overlaps(tiny_run):
    out, _, doc = tiny_run
    md = open(os.path.join(out, "tracking", "results.md")).read().splitlines()
    rows = [line for line in md if line.startswith("| ") and not line.startswith("| policy")]
    assert [r.split(" | ")[0][2:] for r in rows] == [r["policy"] for r in doc["results"]]
    header = md[0].strip("| ").split(" | ")
    paper = dict(zip(header, next(r for r in rows if r.startswith("| paper (separation) |")).strip("| ").split(" | ")))
    # the unit, deterministic (no interval), ties with itself on every episode, no training budget
    assert paper["J / J_paper: IQM over runs [95% CI]"] == "1" and paper["P(J < J_paper) [95% CI]"] == "0.50"
    assert paper["env steps per run"] == "-" and paper["information"] == "own observer's estimate"
    ppo = dict(zip(header, next(r for r in rows if r.startswith("| PPO (centralised) |")).strip("| ").split(" | ")))
    assert ppo["env steps per run"] == str(TINY["agents"]["ppo"]) and "[" in ppo["P(J < J_paper) [95% CI]"]
    overlaps = md[-1]
    assert overlaps.startswith("Overlapping 95% CIs of the IQM of J / J_paper: ")
    for a, b in doc["ci_overlaps"]:
        assert f"{a} / {b}" in overlaps


def test_finished_runs_are_reused_only_with_the_same_recipe(tiny_run, tmp_path):
    """A cached result counts only if its run was trained with today's merged hyperparameters:
    editing a recipe file must retrain, never silently reuse the old recipe's result."""
    import shutil

    from agents.benchmark.plan import _finished_run
    from agents.training.recipes import resolve_recipe

    out, _, _ = tiny_run
    run = os.path.join(out, "models", "tracking", "tiny", "ppo", "s0")
    sig = json.load(open(os.path.join(run, "result.json")))["signature"]
    hp = dict(TINY["hyperparams"]["ppo"])
    today = resolve_recipe("ppo", "tracking", overrides=hp).hyperparams
    assert _finished_run(run, sig, today)["cached"] is True
    edited = resolve_recipe("ppo", "tracking", overrides={**hp, "learning_rate": 1e-4}).hyperparams
    assert _finished_run(run, sig, edited) is None
    assert _finished_run(run, {**sig, "seed": 99}, today) is None
    copy = str(tmp_path / "run")
    shutil.copytree(run, copy)
    os.remove(os.path.join(copy, "config.json"))
    assert _finished_run(copy, sig, today) is None


def test_finished_runs_are_reused_only_with_the_same_library(tiny_run, tmp_path):
    """A cached result counts only if the implementation that would train the run today trained it
    (config.json ``library``; stable-baselines3 for runs that record none): installing the jax extra
    (SBX) must never pass an SB3 result off as SBX's, or the reverse."""
    import shutil

    from agents.benchmark.plan import _finished_run
    from agents.training.recipes import resolve_recipe

    out, _, _ = tiny_run
    run = os.path.join(out, "models", "tracking", "tiny", "ppo", "s0")
    sig = json.load(open(os.path.join(run, "result.json")))["signature"]
    today = resolve_recipe("ppo", "tracking", overrides=dict(TINY["hyperparams"]["ppo"])).hyperparams
    assert json.load(open(os.path.join(run, "config.json")))["library"] == "stable-baselines3"
    assert _finished_run(run, sig, today, library="stable-baselines3")["cached"] is True
    assert _finished_run(run, sig, today, library="sbx-rl") is None
    legacy = str(tmp_path / "legacy")
    shutil.copytree(run, legacy)
    cfg = json.load(open(os.path.join(legacy, "config.json")))
    del cfg["library"], cfg["library_version"]
    json.dump(cfg, open(os.path.join(legacy, "config.json"), "w"))
    assert _finished_run(legacy, sig, today, library="stable-baselines3")["cached"] is True
    assert _finished_run(legacy, sig, today, library="sbx-rl") is None


def test_runs_keep_mean_trajectories_that_give_the_mean_over_every_episode(tiny_run):
    """A run stores its evaluation's errors averaged over the episodes (not every episode's); the
    error-norm figure's mean of the runs' means is the mean over every (run, episode), episodes
    that ended early padded with their last value -- also for runs stored with every episode."""
    from agents.benchmark.report import _run_means
    from agents.benchmark.tasks import mean_trajectory

    out, _, _ = tiny_run
    res = json.load(open(os.path.join(out, "models", "tracking", "tiny", "ppo", "s0", "result.json")))
    assert "tracking_error" not in res and "estimation_error" not in res
    assert len(res["tracking_error_mean"]) == len(res["estimation_error_mean"]) == len(res["t"])
    rng = np.random.default_rng(0)
    lengths = [[20, 20, 7], [13, 4, 20], [5, 5, 5]]  # three runs of three episodes; the last run ended early
    runs = [[rng.uniform(size=L) for L in ls] for ls in lengths]
    episodes = [e for r in runs for e in r]
    want = np.mean([np.concatenate([e, np.full(20 - len(e), e[-1])]) for e in episodes], axis=0)
    compact = [{"tracking_error_mean": mean_trajectory(r).tolist()} for r in runs]
    old = [{"tracking_error": [e.tolist() for e in r]} for r in runs]
    for stored in (compact, old):
        got = mean_trajectory([_run_means(r, "tracking_error") for r in stored])
        np.testing.assert_allclose(got, want, rtol=1e-14)


@pytest.mark.parametrize("argv", [["--seeds", "0"], ["--workers", "-1"], ["--env", "nope"], ["--episodes", "x"],
                                  ["--agents", "ppo,dqn"], ["--agents", "ppo,dqn", "--dry-run"],
                                  ["--agent-seeds", "ppo=0"], ["--agent-seeds", "ppo"], ["--agent-seeds", "dqn=2"],
                                  ["--agent-seeds", "sac=2", "--dry-run"],
                                  ["--agent-seeds", "ppo=2", "--agent-seeds", "ppo=3"]])
def test_cli_usage_errors_exit_2(argv, tmp_path, capsys):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main(["benchmark", "--budget", "tiny", "--out", str(out), *argv])
    assert exc.value.code == 2
    assert not out.exists()
    if argv[0] == "--agents":  # not an argparse choice: our one-line usage error, naming the agent
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "unknown agents ['dqn']" in err


def test_cli_dry_run_lists_the_runs_that_would_train(tiny_run, tmp_path, capsys):
    """``--dry-run`` tells which runs train and which stored results are reused; it writes nothing."""
    out, _, _ = tiny_run
    n = len(TINY_AGENTS) * TINY["seeds"]
    assert main(["benchmark", "--budget", "tiny", "--out", out, "--dry-run"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"0 of {n} runs would train; 0 kept models are evaluated again on other episodes; {n} stored results in "
        f"{out}/models are reused (same configuration and recipe)"]
    # another training budget is another run: nothing reusable
    assert main(["benchmark", "--budget", "tiny", "--out", out, "--dry-run", "--agents", "ppo", "--timesteps", "100"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"{TINY['seeds']} of {TINY['seeds']} runs would train")
    assert lines[1] == (f"  train tracking ppo seed 0: 100 steps -> {out}/models/tracking/tiny/ppo/s0 "
                        f"(replaces a finished run of another configuration: needs --overwrite)")
    empty = tmp_path / "empty"
    assert main(["benchmark", "--env", "all", "--budget", "tiny", "--out", str(empty), "--dry-run"]) == 0
    assert capsys.readouterr().out.startswith(f"{4 * n} of {4 * n} runs would train; 0 kept models")
    assert not empty.exists()


def test_an_agent_with_its_own_number_of_training_runs(tiny_run, tmp_path, capsys):
    """--agent-seeds AGENT=N: that agent trains seeds seed .. seed+N-1 while the others keep the budget's
    count; its row is computed over its N runs and says so (here N=1 from the stored seed 0: nothing trains)."""
    import shutil

    out, _, full = tiny_run
    mine = str(tmp_path / "out")
    shutil.copytree(os.path.join(out, "models"), os.path.join(mine, "models"))
    n = len(TINY_AGENTS) * TINY["seeds"]
    # more runs than stored: only the new seed trains
    assert main(["benchmark", "--budget", "tiny", "--out", mine, "--dry-run", "--agent-seeds", "ppo=3"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"1 of {n + 1} runs would train")
    assert lines[1] == f"  train tracking ppo seed 2: {TINY['agents']['ppo']} steps -> {mine}/models/tracking/tiny/ppo/s2"
    assert main(["benchmark", "--budget", "tiny", "--out", mine, "--no-progress", "--workers", "1",
                 "--agent-seeds", "ppo=1"]) == 0
    printed = capsys.readouterr().out
    assert f"training seeds {list(range(TINY['seeds']))}, ppo: [0]," in printed
    doc = json.load(open(os.path.join(mine, "tracking", "results.json")))
    assert doc["agent_training_seeds"] == {"ppo": [0]}
    assert all(v == 0.0 for secs in doc["train_seconds"].values() for v in secs)  # every run was stored
    rows = {r["policy"]: r for r in doc["results"]}
    before = {r["policy"]: r for r in full["results"]}
    ppo, shared = AGENTS["ppo"].label, AGENTS["ppo_ma"].label
    assert rows[ppo]["runs"] == 1 and list(doc["episodes_detail"][ppo]) == ["s0"]
    assert rows[ppo]["run_scores"] == before[ppo]["run_scores"][:1]
    assert rows[shared]["runs"] == TINY["seeds"] and rows[shared]["run_scores"] == before[shared]["run_scores"]
    assert json.load(open(os.path.join(mine, "summary.json")))["agent_training_seeds"] == {"ppo": [0]}


def test_cli_train_and_evaluate_residual(tmp_path, capsys):
    out = str(tmp_path / "run")
    assert main(["train", "--env", "tracking", "--algo", "ppo", "--multi-agent", "--hybrid", "residual",
                 "--timesteps", "64", "--seed", "1", "--out", out, "--no-progress",
                 "--hyperparams", json.dumps(TINY["hyperparams"]["ppo"])]) == 0
    cfg = json.load(open(os.path.join(out, "config.json")))
    assert cfg["hybrid"] == "residual" and cfg["residual_scale"] > 0
    # the recipe's training-only state bound is recorded apart from the task's env options
    assert cfg["env_kwargs"] == {} and cfg["train_env_kwargs"]["state_bound"] == 30
    assert main(["evaluate", "--model", out, "--episodes", "1", "--seed", "3", "--json", str(tmp_path / "e.json")]) == 0
    summ = json.load(open(tmp_path / "e.json"))
    assert summ["episodes"] == 1 and summ["seeds"] == [3] and summ["failure_rate"] == 0.0


def test_all_envs_one_summary(tmp_path):
    out = str(tmp_path)
    summ = run_benchmark("all", "tiny", out, progress=False, workers=2, agents=["ppo_res"], seeds=1)
    assert summ["envs"] == ["tracking", "disturbance_rejection", "hetero_mas", "random_network"]
    for env in summ["envs"]:
        rows = {r["policy"]: r for r in summ["results"][env]}
        assert rows["paper (separation)"]["cost_ratio_iqm"] == 1.0
        assert rows[AGENTS["ppo_res"].label]["runs"] == 1
        assert os.path.getsize(os.path.join(out, env, "results.json")) > 0
    assert os.path.getsize(os.path.join(out, "summary.png")) > 0


def test_bad_arguments_are_named(tmp_path):
    with pytest.raises(ValueError, match="unknown env"):
        run_benchmark("nope", "tiny", str(tmp_path))
    with pytest.raises(ValueError, match="unknown budget"):
        run_benchmark("tracking", "huge", str(tmp_path))
    with pytest.raises(ValueError, match="unknown agents"):
        run_benchmark("tracking", "tiny", str(tmp_path), agents=["ppo", "dqn"])


def test_a_finished_run_of_another_configuration_is_replaced_only_with_overwrite(tiny_run, tmp_path, capsys):
    """Another training budget (or recipe, or evaluation seeds) for the same (env, agent, seed) trains
    into the same directory: the benchmark refuses to replace the finished run there unless told to."""
    import shutil

    from agents.benchmark.plan import RunConflictError

    out, _, _ = tiny_run
    stored = os.path.join(out, "models", "tracking", "tiny", "ppo", "s0", "result.json")
    before = open(stored).read()
    with pytest.raises(SystemExit) as exc:
        main(["benchmark", "--budget", "tiny", "--out", out, "--agents", "ppo", "--timesteps", "100",
              "--no-progress"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "2 finished run(s)" in err and "--overwrite" in err
    assert open(stored).read() == before

    # overwrite=True retrains (on a copy of one run: the module's fixture stays as it is)
    mine = tmp_path / "bench"
    run = mine / "models" / "tracking" / "tiny" / "ppo_res" / "s0"
    shutil.copytree(os.path.join(out, "models", "tracking", "tiny", "ppo_res", "s0"), run)
    kw = dict(agents=["ppo_res"], seeds=1, timesteps=64, workers=1, progress=False)
    with pytest.raises(RunConflictError) as conflict:
        run_benchmark("tracking", "tiny", str(mine), **kw)
    assert conflict.value.paths == [str(run)]
    run_benchmark("tracking", "tiny", str(mine), overwrite=True, **kw)
    res = json.load(open(run / "result.json"))
    assert res["signature"]["steps"] == 64 and res["cached"] is False


def test_other_evaluation_episodes_evaluate_the_kept_models_again(tiny_run, tmp_path, capsys):
    """Only the evaluation changed (more episodes): the kept models are evaluated on the new episodes,
    nothing is trained again and the training record (model, config, learning curve) is untouched."""
    import shutil

    out, _, _ = tiny_run
    mine = tmp_path / "bench"
    run = mine / "models" / "tracking" / "tiny" / "ppo_res" / "s0"
    shutil.copytree(os.path.join(out, "models", "tracking", "tiny", "ppo_res", "s0"), run)
    before = json.load(open(run / "result.json"))
    model = (run / "model.zip").read_bytes()
    argv = ["benchmark", "--budget", "tiny", "--out", str(mine), "--agents", "ppo_res", "--seeds", "1",
            "--episodes", "3", "--workers", "1", "--no-progress"]
    assert main([*argv, "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines == ["0 of 1 runs would train; 1 kept models are evaluated again on other episodes; 0 stored results "
                     f"in {mine}/models are reused (same configuration and recipe)",
                     f"  evaluate again tracking ppo_res seed 0 -> {run}"]
    assert main(argv) == 0
    after = json.load(open(run / "result.json"))
    assert after["signature"] == {**before["signature"], "eval_seeds": [10_000, 10_001, 10_002]}
    assert len(after["episodes"]) == 3
    # the first two episodes are the ones evaluated before: same seeds, same deterministic policy
    assert [e["cost"] for e in after["episodes"][:2]] == [e["cost"] for e in before["episodes"]]
    assert after["train_seconds"] == before["train_seconds"] and after["curve"] == before["curve"]
    assert (run / "model.zip").read_bytes() == model
    doc = json.load(open(mine / "tracking" / "results.json"))
    assert doc["train_seconds"]["ppo_res"] == [0.0]
    capsys.readouterr()
    assert main([*argv, "--dry-run"]) == 0  # and now it is a stored result of this configuration
    assert capsys.readouterr().out.startswith("0 of 1 runs would train; 0 kept models are evaluated again on other "
                                              "episodes; 1 stored results")
