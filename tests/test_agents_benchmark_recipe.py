"""``dobs-envs benchmark --recipe AGENT=FILE``: AGENT's runs trained with a recipe file (e.g. ``dobs-envs
tune``'s ``best.yml``) as the agent ``AGENT@recipe``, next to the shipped recipe's runs in one --out."""
from __future__ import annotations

import hashlib
import json
import os

import pytest

from agents.benchmark.driver import run_benchmark
from agents.benchmark.plan import AGENTS, BUDGETS
from dobs_envs.cli import main

TINY = BUDGETS["tiny"]
#: values no shipped recipe uses, so that config.json can only show them if the file was read
TUNED = {"n_timesteps": 5000, "learning_rate": 0.000123, "gamma": 0.91, "ent_coef": 0.0017}


def _recipe(path, section="dobs_envs/Tracking-v0", values=TUNED):
    with open(path, "w") as fh:
        fh.write(f"{section}:\n" + "".join(f"  {k}: {v}\n" for k, v in values.items()))
    return str(path)


def _fast(out):
    return ["benchmark", "--env", "tracking", "--budget", "tiny", "--out", str(out), "--timesteps", "64",
            "--seeds", "1", "--episodes", "1", "--backend", "serial", "--no-progress"]


def test_recipe_agent_trains_with_the_file_beside_the_shipped_recipe(tmp_path, capsys):
    """The shipped recipe's stored run is reused for ``ppo`` and never for ``ppo@recipe``, which trains
    with the file's values (its config.json) in its own directory; the table has both rows and the
    results and summary name the file and its SHA-256."""
    out = tmp_path / "bench"
    assert main(_fast(out) + ["--agents", "ppo"]) == 0
    shipped = out / "models" / "tracking" / "tiny" / "ppo" / "s0"
    mtime = os.path.getmtime(shipped / "result.json")
    f = _recipe(tmp_path / "best.yml")
    capsys.readouterr()
    assert main(_fast(out) + ["--agents", "ppo", "--recipe", f"ppo={f}", "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("1 of 2 runs would train")
    assert lines[1] == f"  train tracking ppo@recipe seed 0: 64 steps -> {out}/models/tracking/tiny/ppo@recipe/s0"
    assert main(_fast(out) + ["--agents", "ppo", "--recipe", f"ppo={f}"]) == 0
    assert os.path.getmtime(shipped / "result.json") == mtime  # the shipped run was reused, not retrained
    tuned = out / "models" / "tracking" / "tiny" / "ppo@recipe" / "s0"
    hp = json.load(open(tuned / "config.json"))["hyperparams"]
    for k, v in TUNED.items():
        assert hp[k] == v, k
    for k, v in TINY["hyperparams"]["ppo"].items():  # the budget's overrides apply over the file's section
        if k != "bc":
            assert hp[k] == v, k
    shipped_hp = json.load(open(shipped / "config.json"))["hyperparams"]
    assert all(shipped_hp[k] != v for k, v in TUNED.items() if k != "n_timesteps")
    sha = hashlib.sha256(open(f, "rb").read()).hexdigest()
    want = {"agent": "ppo", "file": f, "sha256": sha, "label": AGENTS["ppo"].label + ", --recipe file"}
    doc = json.load(open(out / "tracking" / "results.json"))
    summ = json.load(open(out / "summary.json"))
    assert doc["recipe_files"] == summ["recipe_files"] == {"ppo@recipe": want}
    assert json.load(open(tuned / "result.json"))["recipe_file"] == {"file": f, "sha256": sha}
    policies = [r["policy"] for r in doc["results"]]
    assert policies[:2] == [AGENTS["ppo"].label, want["label"]]
    assert doc["train_steps"] == {"ppo": 64, "ppo@recipe": 64}
    # the same command again trains nothing: both rows come from the stored runs
    capsys.readouterr()
    assert main(_fast(out) + ["--agents", "ppo", "--recipe", f"ppo={f}", "--dry-run"]) == 0
    assert capsys.readouterr().out.startswith("0 of 2 runs would train")
    # another file's section is another recipe: its run would replace the stored one, so it needs --overwrite
    g = _recipe(tmp_path / "other.yml", "default", {**TUNED, "learning_rate": 0.000321})
    with pytest.raises(SystemExit) as exc:
        main(_fast(out) + ["--agents", "ppo", "--recipe", f"ppo={g}"])
    assert exc.value.code == 2 and "another configuration or recipe" in capsys.readouterr().err


def test_agents_may_name_only_the_recipe_agent(tmp_path, capsys):
    """``--agents ppo@recipe`` plans only the file's runs, with the base agent's budget."""
    from agents.benchmark.plan import plan_runs

    f = _recipe(tmp_path / "best.yml", "default")
    plan = plan_runs("all", "tiny", str(tmp_path / "o"), agents=["ppo_ma@recipe"], recipes={"ppo_ma": f})
    assert plan.steps == {"ppo_ma@recipe": TINY["agents"]["ppo_ma"]}
    assert {sp["agent"] for sp in plan.specs} == {"ppo_ma@recipe"}
    assert all(sp["recipe"] == TUNED for sp in plan.specs)
    assert plan.recipes["ppo_ma@recipe"]["file"] == f


@pytest.mark.parametrize("case,needle", [
    ("unknown", "unknown agent 'dqn'"), ("missing", "does not exist"), ("section", "has no section"),
    ("syntax", "expected AGENT=FILE"), ("twice", "two files for agent 'ppo'"),
    ("variant", "AGENT@recipe needs --recipe AGENT=FILE"), ("bad_key", "no_such_key")])
def test_recipe_usage_errors_exit_2(case, needle, tmp_path, capsys):
    good = _recipe(tmp_path / "best.yml")
    argv = {"unknown": ["--recipe", f"dqn={good}"],
            "missing": ["--recipe", f"ppo={tmp_path / 'nope.yml'}"],
            "section": ["--recipe", "ppo=" + _recipe(tmp_path / "hetero.yml", "dobs_envs/HeteroMAS-v0")],
            "syntax": ["--recipe", good],
            "twice": ["--recipe", f"ppo={good}", "--recipe", f"ppo={good}"],
            "variant": ["--agents", "ppo@recipe"],
            "bad_key": ["--recipe", "ppo=" + _recipe(tmp_path / "bad.yml", values={**TUNED, "no_such_key": 1})]}[case]
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main(_fast(out) + argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err
    assert not out.exists()


def test_run_benchmark_rejects_a_file_without_the_env_section(tmp_path):
    from agents.config.hyperparam_files import HyperparamsError

    f = _recipe(tmp_path / "hetero.yml", "dobs_envs/HeteroMAS-v0")
    with pytest.raises(HyperparamsError, match="has no section 'dobs_envs/Tracking-v0'"):
        run_benchmark("tracking", "tiny", str(tmp_path / "o"), recipes={"ppo": f}, progress=False)
    assert not (tmp_path / "o").exists()
