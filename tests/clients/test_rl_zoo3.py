"""rl-zoo3 (the real client, ``clients`` extra) on agents/hyperparams/*.yaml: its own CLI trains
on ``dobs_envs/Tracking-v0`` with our file, and its own reading of every section it would use
gives the recipe agents/ trains with (one file serves both; issue 9)."""
from __future__ import annotations

import argparse
import os
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from conftest import require

rl_zoo3 = require("rl_zoo3")
import torch.nn as nn  # noqa: E402
from rl_zoo3.exp_manager import ExperimentManager  # noqa: E402

import dobs_envs  # noqa: E402,F401  (registers the dobs_envs/* ids)
from agents.config import ALGOS, ENVS, HYPERPARAMS_DIR  # noqa: E402
from agents.train import resolve_recipe  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_rl_zoo3_cli_trains_with_our_file(tmp_path):
    """``python -m rl_zoo3.train ... -conf agents/hyperparams/ppo.yaml`` for 2k steps (one
    PPO rollout of 8 x 512), with the recipe's training-only state bound and [-1, 1] actions."""
    from stable_baselines3 import PPO

    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", "dobs_envs/Tracking-v0",
           "--gym-packages", "dobs_envs", "-conf", os.path.join(HYPERPARAMS_DIR, "ppo.yaml"),
           "-n", "2000", "--seed", "0", "-f", str(tmp_path / "logs"), "--eval-freq", "-1", "--num-threads", "1"]
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "env_kwargs={'state_bound': 30}" in proc.stdout
    run = tmp_path / "logs" / "ppo" / "dobs_envs-Tracking-v0_1"
    assert (run / "dobs_envs-Tracking-v0" / "vecnormalize.pkl").is_file()
    model = PPO.load(run / "dobs_envs-Tracking-v0.zip", device="cpu")
    assert model.num_timesteps >= 2000
    assert model.action_space == gym.spaces.Box(-1.0, 1.0, (5,), np.float32)
    assert model.policy.action_net.in_features == 128 and isinstance(model.policy.mlp_extractor.policy_net[1], nn.Tanh)


def _zoo_reading(algo: str, gym_id: str, tmp_path):
    """What rl-zoo3's ExperimentManager makes of our file for ``gym_id`` (before creating the model)."""
    em = ExperimentManager(argparse.Namespace(), algo, gym_id, str(tmp_path), config=os.path.join(
        HYPERPARAMS_DIR, f"{algo}.yaml"))
    hp, _ = em.read_hyperparameters()
    hp, env_wrapper, callbacks, vec_env_wrapper = em._preprocess_hyperparams(hp)
    assert not callbacks and vec_env_wrapper is None
    return em, hp, env_wrapper


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("name", sorted(ENVS))
def test_rl_zoo3_reads_the_recipe_agents_trains_with(algo, name, tmp_path):
    """rl-zoo3's reading of the section it uses (the Gymnasium id's or ``default``) equals the
    centralised recipe of agents/ (constructor arguments, schedules, activation, envs, budget,
    normalisation, training-only env options, [-1, 1] actions, action noise)."""
    gym_id = ENVS[name][0]
    em, hp, env_wrapper = _zoo_reading(algo, gym_id, tmp_path)
    ours = resolve_recipe(algo, name)
    assert em.n_envs == ours.n_envs and em.n_timesteps == ours.n_timesteps
    assert em.env_kwargs == ours.train_env_kwargs
    assert em.eval_env_kwargs == {}  # rl-zoo3 evaluates on the task's own env, as agents/ does
    assert em.normalize_kwargs == ours.normalize
    assert hp.pop("policy") == ours.policy

    wrapped = env_wrapper(gym.make(gym_id))
    assert ours.normalize_actions
    assert wrapped.action_space.low.min() == -1.0 and wrapped.action_space.high.max() == 1.0
    wrapped.close()

    noise_type, noise_std = hp.pop("noise_type", None), hp.pop("noise_std", None)
    assert (noise_std if noise_type == "normal" else None) == ours.action_noise_sigma

    ours_kw = dict(ours.algo_kwargs)
    ours_pk, zoo_pk = dict(ours_kw.pop("policy_kwargs")), dict(hp.pop("policy_kwargs"))
    assert zoo_pk.pop("activation_fn").__name__.lower() == ours_pk.pop("activation_fn")
    assert zoo_pk == ours_pk
    assert set(hp) == set(ours_kw)
    for key, value in ours_kw.items():
        if key in ("learning_rate", "clip_range"):  # rl-zoo3 wraps every value in a schedule
            ours_fn = (lambda p, v0=float(value[4:]): p * v0) if isinstance(value, str) else (lambda p, v=value: v)
            for progress in (1.0, 0.5, 0.1):
                assert hp[key](progress) == pytest.approx(ours_fn(progress), rel=1e-12)
        else:
            assert hp[key] == value, key


def test_rl_zoo3_version():
    assert tuple(int(x) for x in rl_zoo3.__version__.split(".")[:2]) >= (2, 9)
