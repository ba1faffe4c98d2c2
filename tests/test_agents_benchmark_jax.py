"""The benchmark's jitted rows (issue 40): ``--trainer jax`` on the tiny budget trains "PPO (JAX)" and
"PPO (JAX, shared)" with the real jitted trainer, each env's seeds of an agent vmapped in one task, one run
directory per seed counted as one run; stored runs are reused, an interrupted one is retrained (alone, as a
single-seed run that equals its vmapped run up to float32 round-off), a kept policy is evaluated again on other
episodes; ``--trainer`` usage errors."""
from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("optax")

from agents.benchmark.driver import run_benchmark  # noqa: E402
from agents.benchmark.plan import AGENTS, ANALYTIC, BUDGETS, TRAINERS, default_agents, plan_runs  # noqa: E402
from agents.training.provenance import run_provenance  # noqa: E402
from dobs_envs.cli import main  # noqa: E402
from jax_run_records import CONFIG_KEYS, MARL_CONFIG_KEYS, VMAPPED_KEY  # noqa: E402

TINY = BUDGETS["tiny"]
JAX_AGENTS = ("ppo_jax", "ppo_ma_jax")


def _results(out: str) -> dict:
    with open(os.path.join(out, "tracking", "results.json")) as fh:
        return json.load(fh)


def _run_dir(out: str, agent: str, seed: int) -> str:
    return os.path.join(out, "models", "tracking", "tiny", agent, f"s{seed}")


def _mtimes(out: str) -> dict:
    return {(a, s, f): os.stat(os.path.join(_run_dir(out, a, s), f)).st_mtime_ns
            for a in JAX_AGENTS for s in range(TINY["seeds"]) for f in ("policy.npz", "result.json")}


@pytest.fixture(scope="module")
def first(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("bench_jax"))
    summ = run_benchmark("tracking", "tiny", out, progress=False, workers=2, trainer="jax")
    return out, summ, _results(out)


@pytest.fixture(scope="module")
def second(first, tmp_path_factory):
    """The same command again through the CLI, into a copy of the first call's directory."""
    out = str(tmp_path_factory.mktemp("again") / "out")
    shutil.copytree(first[0], out)
    before = _mtimes(out)
    assert main(["benchmark", "--env", "tracking", "--budget", "tiny", "--trainer", "jax", "--out", out,
                 "--no-progress", "--workers", "2"]) == 0
    return out, before, _results(out)


def test_plan_trainer_selects_the_default_rows_and_budgets_are_equal():
    for budget, B in BUDGETS.items():
        sb3 = default_agents(budget, "sb3")
        jax = default_agents(budget, "jax")
        assert all(AGENTS[k].trainer == "sb3" for k in sb3) and all(AGENTS[k].trainer == "jax" for k in jax)
        assert default_agents(budget, "all") == sb3 + jax
        for k in jax:  # equal env steps to the SB3 counterpart
            assert B["agents"][k] == B["agents"][AGENTS[k].counterpart]
    assert set(default_agents("tiny", "jax")) == set(JAX_AGENTS) and set(TRAINERS) == {"sb3", "jax", "all"}
    assert {sp["agent"] for sp in plan_runs("tracking", "tiny", "x").specs} == set(default_agents("tiny"))
    assert AGENTS["ppo_jax"].information != AGENTS["ppo_ma_jax"].information


def test_sqrt_cost_jitted_agent_trains_on_the_sqrt_reward_and_is_scored_on_the_task_cost():
    """``ppo_sqrt_jax`` is ``ppo_sqrt``'s jitted counterpart: the full budget trains it (its counterpart's env steps),
    its training-only env option (the reward ``-sqrt(c) T``) reaches the env the jitted trainer builds, and the env
    its runs are scored on has no such option (every row is scored on the task's cost)."""
    from agents.benchmark.plan import _training_overrides
    from agents.training.jax.run import build_run

    a = AGENTS["ppo_sqrt_jax"]
    assert a.train_env_kwargs == AGENTS["ppo_sqrt"].train_env_kwargs == (("reward", "sqrt"),)
    assert (a.algo, a.multi_agent, a.trainer, a.information) == ("ppo", False, "jax", AGENTS["ppo_sqrt"].information)
    assert "ppo_sqrt_jax" in default_agents("full", "jax") and "ppo_sqrt_jax" not in default_agents("full", "sb3")
    spec = next(sp for sp in plan_runs("tracking", "full", "x", trainer="jax").specs if sp["agent"] == "ppo_sqrt_jax")
    assert spec["steps"] == BUDGETS["full"]["agents"]["ppo_sqrt"] and "reward" not in spec["env_kwargs"]
    hp = _training_overrides(spec)
    assert hp["env_kwargs"]["reward"] == "sqrt"
    setup = build_run("ppo", "tracking", "dobs_envs/Tracking-v0", hp, 4096)
    plain = build_run("ppo", "tracking", "dobs_envs/Tracking-v0", _training_overrides({**spec, "agent": "ppo_jax"}), 4096)
    assert setup.env.structure.reward_code == 2 and plain.env.structure.reward_code == 0
    assert setup.fields["train_env_kwargs"]["reward"] == "sqrt" and setup.fields["env_kwargs"] == {}


@pytest.mark.parametrize("trainer", ["sb3", "jax", "all"])
def test_named_agents_train_their_budgets_steps_whatever_the_trainer(trainer):
    """An agent named in ``agents`` trains its budget's env steps whichever trainer selects the default rows: with
    the default trainer (sb3) the jitted shared PPO once got the budget's longest (600k instead of its
    counterpart's 300k), so the archive test planned its stored runs again."""
    for budget, B in BUDGETS.items():
        plan = plan_runs("tracking", budget, "x", agents=list(B["agents"]), trainer=trainer)
        assert {sp["agent"]: sp["steps"] for sp in plan.specs} == B["agents"]


def test_jitted_rows_count_each_seed_as_a_run(first):
    """The table has the two jitted rows (runs = the budget's seeds, IQM inside its run-level CI, the counterpart's
    env steps) next to every analytic row, and their statistics are agents.stats' on the stored runs."""
    from agents.stats import interval_estimate, run_scores

    out, summ, doc = first
    assert summ["trainer"] == "jax"
    assert summ["provenance"] == run_provenance()  # the code and the machine of the command
    rows = {r["policy"]: r for r in doc["results"]}
    assert set(rows) == {AGENTS[k].label for k in JAX_AGENTS} | set(ANALYTIC)
    assert {"PPO (JAX)", "PPO (JAX, shared)"} <= set(rows)
    paper = np.array(doc["paper_cost"])
    for k in JAX_AGENTS:
        r = rows[AGENTS[k].label]
        assert r["runs"] == TINY["seeds"] and r["kind"] == "RL" and r["information"] == AGENTS[k].information
        assert r["env_steps"] == TINY["agents"][AGENTS[k].counterpart]
        assert np.isfinite(r["cost_ratio_iqm"]) and r["cost_ratio_ci_low"] <= r["cost_ratio_iqm"] <= r["cost_ratio_ci_high"]
        cost = np.array([[e["cost"] for e in eps] for eps in doc["episodes_detail"][r["policy"]].values()])
        est = interval_estimate(run_scores(cost / paper))
        assert r["cost_ratio_iqm"] == pytest.approx(est["iqm"], rel=1e-12)
        assert r["train_seconds_median"] > 0 and r["policy"] in summ["tables"]["tracking"]
        assert len(doc["learning_curves"][r["policy"]]["iqm"]) >= 2
    # different seeds, different policies
    eps = doc["episodes_detail"]["PPO (JAX)"]
    assert eps["s0"][0]["cost"] != eps["s1"][0]["cost"]


def test_run_directories_of_vmapped_seeds(first):
    """One ordinary jitted run directory per seed (evaluate --model reads it), trained in one vmapped task: its seed,
    the seeds sharing the run, its time the task's divided by the number of seeds."""
    out, _, _ = first
    n = TINY["seeds"]
    for k in JAX_AGENTS:
        for s in range(n):
            d = _run_dir(out, k, s)
            for f in ("config.json", "policy.npz", "policy.json", "curve.json", "train_curve.json", "result.json"):
                assert os.path.isfile(os.path.join(d, f)), (k, s, f)
            cfg = json.load(open(os.path.join(d, "config.json")))
            res = json.load(open(os.path.join(d, "result.json")))
            assert cfg["trainer"] == "jax" and cfg["status"] == "complete" and cfg["seed"] == s == res["seed"]
            assert cfg["multi_agent"] == AGENTS[k].multi_agent
            assert set(cfg) == (MARL_CONFIG_KEYS if cfg["multi_agent"] else CONFIG_KEYS) | {VMAPPED_KEY}
            assert cfg["vmapped"]["seeds"] == list(range(n)) and cfg["vmapped"]["runs"] == n
            for t in ("compile_seconds", "train_seconds", "train_cpu_seconds"):
                assert cfg[t] == pytest.approx(cfg["vmapped"][t] / n, rel=1e-12)
            assert cfg["train_env_kwargs"]["max_episode_steps"] == TINY["env_kwargs"]["max_cycles"]
            assert res["train_seconds_shared"]["runs"] == n
            assert res["train_seconds"] == pytest.approx(res["train_seconds_shared"]["seconds"] / n, rel=1e-12)
            assert res["train_seconds"] > cfg["vmapped"]["compile_seconds"] / n


def test_second_invocation_reuses_the_stored_runs(first, second):
    out, before, doc = second
    assert _mtimes(out) == before  # nothing trained or written again
    assert doc["train_seconds"] == {k: [0.0] * TINY["seeds"] for k in JAX_AGENTS}
    assert [r["cost_ratio_iqm"] for r in doc["results"]] == [r["cost_ratio_iqm"] for r in first[2]["results"]]


def test_interrupted_run_is_retrained_alone_and_equals_its_vmapped_run(second, tmp_path):
    """A run without result.json (interrupted: config.json still 'running') is trained again, alone (one seed:
    agents.training.jax.run.train_jax itself), the finished ones are kept; the single run equals the vmapped one
    up to float32 round-off (the
    batched and the single program are compiled separately: last-bit differences in the weights, ~1e-8 measured,
    grow along the closed-loop episodes of the curve). The centralised agent only (one compilation; the shared
    trainer's vmapped seeds against single runs: tests/test_jax_ippo.py)."""
    out, k = str(tmp_path / "out"), "ppo_jax"
    shutil.copytree(second[0], out)
    d = _run_dir(out, k, 1)
    old = dict(np.load(os.path.join(d, "policy.npz")))
    old_curve = json.load(open(os.path.join(d, "curve.json")))
    os.remove(os.path.join(d, "result.json"))
    cfg = json.load(open(os.path.join(d, "config.json")))
    json.dump({**cfg, "status": "running"}, open(os.path.join(d, "config.json"), "w"))
    before = _mtimes(second[0])
    from agents.benchmark.plan import pending_runs

    P = plan_runs("tracking", "tiny", out, trainer="jax")
    assert [(sp["agent"], sp["seed"]) for sp in pending_runs(P)] == [(k, 1)]
    run_benchmark("tracking", "tiny", out, progress=False, workers=2, trainer="jax")
    after = _mtimes(out)
    for key, t in before.items():
        assert (after[key] == t) == (key[:2] != (k, 1)), key  # only the interrupted run is written again
    cfg = json.load(open(os.path.join(d, "config.json")))
    assert cfg["status"] == "complete" and "vmapped" not in cfg and cfg["seed"] == 1  # train_jax's own run
    res = json.load(open(os.path.join(d, "result.json")))
    assert "train_seconds_shared" not in res and res["train_seconds"] == cfg["total_seconds"]
    new = np.load(os.path.join(d, "policy.npz"))
    assert sorted(new.files) == sorted(old)
    for name in new.files:
        np.testing.assert_allclose(new[name], old[name], rtol=1e-5, atol=1e-7, err_msg=name)
    curve = json.load(open(os.path.join(d, "curve.json")))
    assert [p["env_steps"] for p in curve["points"]] == [p["env_steps"] for p in old_curve["points"]]
    for p, q in zip(curve["points"], old_curve["points"]):
        np.testing.assert_allclose(p["cost_ratio"], q["cost_ratio"], rtol=1e-3)


def test_other_episodes_evaluate_the_kept_policies_again(second, tmp_path):
    out = str(tmp_path / "out")
    shutil.copytree(second[0], out)
    before = _mtimes(out)
    from agents.benchmark.plan import pending_runs, reevaluated_runs

    P = plan_runs("tracking", "tiny", out, trainer="jax", eval_seed=10_100)
    assert pending_runs(P) == [] and len(reevaluated_runs(P)) == len(JAX_AGENTS) * TINY["seeds"]
    run_benchmark("tracking", "tiny", out, progress=False, workers=1, trainer="jax", eval_seed=10_100)
    after = _mtimes(out)
    for key, t in before.items():
        assert (after[key] == t) == (key[2] == "policy.npz"), key  # the policy kept, the result new
    doc = _results(out)
    assert all(e["seed"] >= 10_100 for eps in doc["episodes_detail"]["PPO (JAX)"].values() for e in eps)


def test_dry_run_names_the_vmapped_tasks(tmp_path, capsys):
    out = str(tmp_path / "b")
    assert main(["benchmark", "--budget", "tiny", "--trainer", "all", "--out", out, "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    n = len(default_agents("tiny", "all")) * TINY["seeds"]
    assert lines[0].startswith(f"{n} of {n} runs would train")
    for k in JAX_AGENTS:
        for s in range(TINY["seeds"]):
            assert (f"  train tracking {k} seed {s}: {TINY['agents'][k]} steps -> {out}/models/tracking/tiny/{k}/s{s} "
                    f"(jitted: {TINY['seeds']} seeds in one vmapped task)") in lines
    assert not os.path.exists(out)


@pytest.mark.parametrize("argv, match", [
    (["--trainer", "tf"], "invalid choice"),
    (["--trainer", "jax", "--agents", "ppo,ppo_jax"], "--agents ppo: not trained by --trainer jax"),
    (["--trainer", "sb3", "--agents", "ppo_ma_jax"], "--agents ppo_ma_jax: not trained by --trainer sb3"),
    (["--recipe", "ppo_jax=pyproject.toml"], "recipe files are for the SB3 agents"),
])
def test_trainer_usage_errors(argv, match, tmp_path, capsys):
    out = str(tmp_path / "b")
    with pytest.raises(SystemExit) as exc:
        main(["benchmark", "--budget", "tiny", "--out", out, *argv])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and match in err and "Traceback" not in err and err.count("\n") <= 1, err
    assert not os.path.exists(out)


def test_jitted_agents_without_the_jax_extra_are_a_usage_error(tmp_path, capsys, monkeypatch):
    """Without optax (the jax extra), --trainer jax stops before anything is written (a dry run still lists)."""
    import sys

    monkeypatch.setitem(sys.modules, "optax", None)  # importlib.util.find_spec then answers None: not installed
    out = str(tmp_path / "b")
    with pytest.raises(SystemExit) as exc:
        main(["benchmark", "--budget", "tiny", "--trainer", "jax", "--out", out])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and "pip install 'dobs-envs[jax]'" in err and "optax is missing" in err, err
    assert not os.path.exists(out)
    assert main(["benchmark", "--budget", "tiny", "--trainer", "sb3", "--out", out, "--dry-run"]) == 0
