"""rl-zoo3 (the real client, ``clients`` extra) on agents/config/hyperparams/*.yaml: its own CLI trains
on ``dobs_envs/Tracking-v0`` with our file, and its own reading of every section it would use
gives the recipe agents/ trains with (one file serves both; issue 9).

rl-zoo3 runs in subprocesses only: ``import rl_zoo3`` patches Gymnasium's ``TimeLimit`` for the
whole process (an extra ``TimeLimit.truncated`` info key), which would leak into other tests."""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

from agents.config.hyperparam_files import ALGOS, HYPERPARAMS_DIR, read_hyperparams_file
from agents.config.envs import ENVS
from agents.training.recipes import resolve_recipe

if importlib.util.find_spec("rl_zoo3") is None:  # as conftest.require, without importing it here
    if os.environ.get("CI"):
        raise ImportError("rl_zoo3 is missing: .ci/run installs the clients extra")
    pytest.skip("rl_zoo3 comes with the clients extra: pip install '.[clients]'", allow_module_level=True)

HERE = os.path.dirname(os.path.abspath(__file__))
ENV = dict(os.environ, MPLBACKEND="Agg")


def test_rl_zoo3_cli_trains_with_our_file(tmp_path):
    """``python -m rl_zoo3.train ... -conf agents/config/hyperparams/ppo.yaml`` for 2k steps (one
    PPO rollout of 8 x 512), with the recipe's training-only state bound and [-1, 1] actions.
    The saved model is inspected in a subprocess too: it pickles rl-zoo3's schedule objects,
    so loading it imports rl_zoo3."""
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", "dobs_envs/Tracking-v0",
           "--gym-packages", "dobs_envs", "-conf", os.path.join(HYPERPARAMS_DIR, "ppo.yaml"),
           "-n", "2000", "--seed", "0", "-f", str(tmp_path / "logs"), "--eval-freq", "-1", "--num-threads", "1"]
    proc = subprocess.run(cmd, cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "env_kwargs={'state_bound': 30}" in proc.stdout
    run = tmp_path / "logs" / "ppo" / "dobs_envs-Tracking-v0_1"
    assert (run / "dobs_envs-Tracking-v0" / "vecnormalize.pkl").is_file()
    probe = ("import json, sys; from stable_baselines3 import PPO; m = PPO.load(sys.argv[1], device='cpu'); "
             "print(json.dumps([m.num_timesteps, str(m.action_space), m.policy.action_net.in_features, "
             "type(m.policy.mlp_extractor.policy_net[1]).__name__]))")
    proc = subprocess.run([sys.executable, "-c", probe, str(run / "dobs_envs-Tracking-v0.zip")], env=ENV,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    steps, space, width, activation = json.loads(proc.stdout.strip().splitlines()[-1])
    assert steps >= 2000
    assert space == str(gym.spaces.Box(-1.0, 1.0, (5,), np.float32))
    assert (width, activation) == (128, "Tanh")


@pytest.fixture(scope="module")
def zoo_readings():
    """rl-zoo3's ExperimentManager reading of every (algo, Gymnasium id), from a subprocess."""
    proc = subprocess.run([sys.executable, os.path.join(HERE, "rl_zoo3_reading.py")], env=ENV, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("name", sorted(ENVS))
def test_rl_zoo3_reads_the_recipe_agents_trains_with(algo, name, zoo_readings):
    """rl-zoo3's reading of the section it uses (the Gymnasium id's or ``default``) equals the
    centralised recipe of agents/ (constructor arguments, schedules, activation, envs, budget,
    normalisation, training-only env options, [-1, 1] actions, action noise)."""
    gym_id = ENVS[name][0]
    zoo = zoo_readings[f"{algo} {gym_id}"]
    ours = resolve_recipe(algo, name)
    assert zoo["n_envs"] == ours.n_envs and zoo["n_timesteps"] == ours.n_timesteps
    assert zoo["env_kwargs"] == ours.train_env_kwargs
    assert zoo["eval_env_kwargs"] == {}  # rl-zoo3 evaluates on the task's own env, as agents/ does
    assert zoo["normalize"] == ours.normalize
    assert not zoo["callbacks"] and not zoo["vec_env_wrapper"]

    assert ours.normalize_actions
    assert set(zoo["action_low"]) == {-1.0} and set(zoo["action_high"]) == {1.0}
    assert zoo["env_action_low"] != zoo["action_low"]  # the wrapper did rescale the env's bounds

    kw = dict(zoo["kwargs"])
    assert kw.pop("policy") == ours.policy
    noise_type, noise_std = kw.pop("noise_type", None), kw.pop("noise_std", None)
    # the agents-only `<env>` section holds what rl-zoo3 cannot read (td3.yaml's hetero_mas: pink noise)
    env_only = read_hyperparams_file(os.path.join(HYPERPARAMS_DIR, f"{algo}.yaml")).get(name, {})
    assert set(env_only) <= {"noise_type"}, f"extend this test to {algo}.yaml's section {name!r}: {env_only}"
    if "noise_type" in env_only:
        assert ours.action_noise_type == env_only["noise_type"] != noise_type
        assert noise_type in ("normal", "ornstein-uhlenbeck", None)
    else:
        assert noise_type == ours.action_noise_type
    assert noise_std == ours.action_noise_sigma

    ours_kw = dict(ours.algo_kwargs)
    ours_pk, zoo_pk = dict(ours_kw.pop("policy_kwargs")), dict(kw.pop("policy_kwargs"))
    assert zoo_pk.pop("activation_fn").lower() == ours_pk.pop("activation_fn")
    assert zoo_pk == ours_pk
    assert set(kw) == set(ours_kw)
    for key, value in ours_kw.items():
        if key in ("learning_rate", "clip_range"):  # rl-zoo3 wraps every value in a schedule
            v0 = float(value[4:]) if isinstance(value, str) else None
            expected = [p * v0 if v0 is not None else value for p in (1.0, 0.5, 0.1)]
            assert kw[key]["schedule"] == pytest.approx(expected, rel=1e-12), key
        else:
            assert kw[key] == value, key


def test_importing_the_suite_leaves_gymnasium_unpatched():
    """rl-zoo3's TimeLimit patch must not reach this process (see the module doc)."""
    assert "rl_zoo3" not in sys.modules
    assert gym.wrappers.TimeLimit.__module__.startswith("gymnasium.")
