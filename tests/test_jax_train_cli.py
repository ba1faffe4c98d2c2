"""``dobs-envs train --trainer jax`` and ``evaluate --model`` on a jitted run, through the real CLI: one tiny
jitted PPO run on tracking (2 updates of 8 x 128 steps) shared by the tests; its run directory's records,
its evaluation by the existing harness on the compiled env, and the usage errors."""
from __future__ import annotations

import json
import math
import os
from importlib import metadata

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("optax")

from agents.training.provenance import run_provenance  # noqa: E402
from dobs_envs.cli import main  # noqa: E402
from jax_run_records import CONFIG_KEYS  # noqa: E402

#: a smaller rollout than the jitted trainer's tracking recipe (SB3's: 8 copies x 512 steps): 8 x 128 with
#: minibatches of 256 (2 updates within --timesteps 2048: a curve of 3 points)
HP = {"n_envs": 8, "n_steps": 128, "batch_size": 256, "n_epochs": 2}


@pytest.fixture(scope="module")
def jax_run(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("jaxrun") / "run")
    assert main(["train", "--trainer", "jax", "--env", "tracking", "--timesteps", "2048", "--seed", "3", "--out", out,
                 "--no-progress", "--hyperparams", json.dumps(HP)]) == 0
    return out


def _exit2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2, err
    assert "Traceback" not in err and err.count("\n") == 0, err
    return err


def test_run_directory_records(jax_run):
    from agents.training.recipes import resolve_recipe

    files = sorted(os.listdir(jax_run))
    assert files == ["config.json", "curve.json", "policy.json", "policy.npz", "train_curve.json"]  # nothing pickled
    cfg = json.load(open(os.path.join(jax_run, "config.json")))
    assert cfg["trainer"] == "jax" and cfg["library"] == "agents.training.jax" and cfg["algo"] == "ppo"
    assert cfg["jax_version"] == jax.__version__ and cfg["optax_version"] == metadata.version("optax")
    assert cfg["library_version"] == metadata.version("dobs-envs")
    assert cfg["env"] == "tracking" and cfg["env_id"] == "dobs_envs/Tracking-v0" and cfg["seed"] == 3
    assert cfg["timesteps"] == 2048 and cfg["timesteps_done"] == 2048 and cfg["n_updates"] == 2
    assert cfg["status"] == "complete" and set(cfg) == CONFIG_KEYS
    assert cfg["provenance"] == run_provenance()  # the code and the machine that trained it
    # the recipe: SB3 PPO's (agents/config/hyperparams/ppo.yaml) with the --hyperparams overrides
    recipe = resolve_recipe("ppo", "tracking", overrides=HP, trainer="jax")  # the jitted trainer's recipe
    assert cfg["hyperparams"] == json.loads(json.dumps(recipe.hyperparams))
    for k in ("setup_seconds", "compile_seconds", "compile_cpu_seconds", "train_seconds", "train_cpu_seconds",
              "curve_seconds"):
        assert math.isfinite(cfg[k]) and cfg[k] > 0, k
    with np.load(os.path.join(jax_run, "policy.npz"), allow_pickle=False) as z:
        width = recipe.hyperparams["policy_kwargs"]["net_arch"][0]  # tracking-jax's [64, 64]
        assert z["pi_w0"].shape == (155, width) and np.all(np.isfinite(z["pi_w0"]))
    tc = json.load(open(os.path.join(jax_run, "train_curve.json")))
    assert tc["steps"] == [1024, 2048] and len(tc["episode_return"]) == 2


def test_learning_curve_in_the_benchmarks_format(jax_run):
    """curve.json as agents.training.curves writes it for SB3 runs; its last point is the exported policy's
    cost ratio on the curve episodes (the final snapshot is the exported policy), scored by the harness."""
    from agents.benchmark.report import _curve_stats
    from agents.config.envs import gym_factory
    from agents.evaluate import evaluate_policy
    from agents.training.curves import paper_costs
    from agents.training.jax.numpy_policy import NumpyPolicy

    curve = json.load(open(os.path.join(jax_run, "curve.json")))
    assert curve["seeds"] == [20000, 20001, 20002]  # the tuning range, as the benchmark's curves
    ref = paper_costs("tracking", {}, curve["seeds"])
    np.testing.assert_allclose(curve["paper_cost"], ref, rtol=1e-12)
    assert [p["env_steps"] for p in curve["points"]] == [0, 1024, 2048]
    for p in curve["points"]:
        assert len(p["cost_ratio"]) == 3 and all(math.isfinite(r) and r > 0 for r in p["cost_ratio"])
    env = gym_factory("tracking", {})()
    costs = [r.cost for r in evaluate_policy(env, NumpyPolicy(jax_run), 3, 20000, parallel=False)]
    env.close()
    np.testing.assert_allclose(curve["points"][-1]["cost_ratio"], np.array(costs) / ref, rtol=1e-12)
    assert curve["points"][0]["cost_ratio"] != curve["points"][-1]["cost_ratio"]  # the snapshots differ
    stats = _curve_stats([{"curve": curve["points"]}])  # what the benchmark's report reads
    assert stats["env_steps"] == [0, 1024, 2048]


def test_evaluate_scores_the_jitted_run_with_the_harness(jax_run, tmp_path, capsys):
    from agents.config.envs import gym_factory
    from agents.evaluate import evaluate_policy, summarise
    from agents.training.jax.numpy_policy import NumpyPolicy
    from agents.training.loading import JaxTrainedAgent, load_agent

    assert isinstance(load_agent(jax_run), JaxTrainedAgent)
    out = str(tmp_path / "eval.json")
    assert main(["evaluate", "--model", jax_run, "--episodes", "2", "--seed", "10000", "--json", out]) == 0
    printed = capsys.readouterr().out
    summ = json.load(open(out))
    assert summ["policy"] == "PPO (JAX)" and summ["model"] == os.path.join(jax_run, "policy.npz")
    assert summ["seeds"] == [10000, 10001] and math.isfinite(summ["cost_mean"])
    assert "PPO (JAX)" in printed and "cost_mean" in printed
    env = gym_factory("tracking", {})()  # the same harness and env by hand: the same figures, the same keys
    ref = summarise(evaluate_policy(env, NumpyPolicy(jax_run), 2, 10000, parallel=False))
    env.close()
    assert {k: v for k, v in summ.items() if k not in ("policy", "model")} == json.loads(json.dumps(ref))


@pytest.mark.parametrize("extra, names", [
    (["--algo", "crossq"], ["--algo", "ppo | sac | td3", "crossq"]),
    (["--multi-agent", "--algo", "sac"], ["--algo sac", "ppo"]),
    (["--hybrid", "residual"], ["--hybrid"]),
    (["--resume", "runs/x"], ["--resume"]),
    (["--checkpoint-freq", "0"], ["--checkpoint-freq"]),
    (["--env", "Pendulum-v1"], ["Pendulum-v1", "tracking"]),
    (["--hyperparams", '{"target_kl": 0.02}'], ["target_kl"]),
])
def test_unsupported_options_exit_2_with_one_line(extra, names, tmp_path, capsys):
    out = tmp_path / "never"
    err = _exit2(["train", "--trainer", "jax", "--timesteps", "64", "--no-progress", "--out", str(out), *extra], capsys)
    for n in names:
        assert n in err, err
    assert not out.exists()


def test_existing_out_is_not_overwritten(jax_run, tmp_path, capsys):
    before = {f: open(os.path.join(jax_run, f), "rb").read() for f in os.listdir(jax_run)}
    base = ["train", "--trainer", "jax", "--env", "tracking", "--timesteps", "64", "--no-progress", "--out", jax_run]
    err = _exit2(base, capsys)
    assert "--overwrite" in err and "ppo run on tracking" in err
    # with --overwrite, a refused recipe stops before the run directory is touched
    _exit2(base + ["--overwrite", "--hyperparams", '{"target_kl": 0.02}'], capsys)
    assert {f: open(os.path.join(jax_run, f), "rb").read() for f in os.listdir(jax_run)} == before
    other = tmp_path / "notes"
    other.mkdir()
    (other / "mine.txt").write_text("x")
    assert "holds no run" in _exit2(base[:-1] + [str(other)], capsys)
    assert os.listdir(other) == ["mine.txt"]


@pytest.mark.parametrize("damage", ["truncated", "pickled_array", "other_env"])
def test_evaluate_refuses_a_damaged_jitted_run(damage, jax_run, tmp_path, capsys):
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(jax_run, bad)
    if damage == "truncated":
        data = (bad / "policy.npz").read_bytes()
        (bad / "policy.npz").write_bytes(data[:len(data) // 2])
    elif damage == "pickled_array":  # an object array needs unpickling: refused, never loaded
        with np.load(bad / "policy.npz") as z:
            arrays = dict(z)
        arrays["pi_w0"] = np.array([object()], dtype=object)
        np.savez(bad / "policy.npz", **arrays)
    else:
        meta = json.load(open(bad / "policy.json"))
        json.dump(dict(meta, env_id="dobs_envs/HeteroMAS-v0"), open(bad / "policy.json", "w"))
    err = _exit2(["evaluate", "--model", str(bad), "--episodes", "1"], capsys)
    assert "policy" in err, err
