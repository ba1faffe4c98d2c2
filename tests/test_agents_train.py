"""Training smoke tests: every algorithm trains a few hundred steps, saves, loads
(with VecNormalize statistics) and predicts inside the action space."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agents.training.algos import BACKENDS, LEGACY_LIBRARY, backend
from agents.config.hyperparam_files import ALGOS, load_hyperparams
from agents.training.loading import load_agent
from agents.training.provenance import run_provenance
from agents.training.train import train


class PointMasses(ParallelEnv):
    """Two agents, each pushing its own 1-D point mass to 0 (reward -x^2); horizon 16."""

    metadata = {"name": "point_masses_v0"}

    def __init__(self, horizon=16):
        self.possible_agents = ["p0", "p1"]
        self.agents = []
        self.horizon = horizon
        self.rng = np.random.default_rng()

    def observation_space(self, agent):
        return spaces.Box(-np.inf, np.inf, (2,), np.float32)

    def action_space(self, agent):
        return spaces.Box(-1, 1, (1,), np.float32)

    def _obs(self):
        return {a: self.s[j].astype(np.float32) for j, a in enumerate(self.possible_agents)}

    def reset(self, seed=None, options=None):
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self.agents = list(self.possible_agents)
        self.t = 0
        self.s = self.rng.uniform(-1, 1, size=(2, 2))
        return self._obs(), {a: {} for a in self.agents}

    def step(self, actions):
        self.t += 1
        for j, a in enumerate(self.possible_agents):
            x, v = self.s[j]
            v = v + 0.1 * float(np.asarray(actions[a])[0])
            self.s[j] = [x + 0.1 * v, v]
        rew = {a: -float(self.s[j, 0] ** 2) for j, a in enumerate(self.possible_agents)}
        trunc = self.t >= self.horizon
        out = self._obs(), rew, {a: False for a in self.agents}, {a: trunc for a in self.agents}, {a: {} for a in self.agents}
        if trunc:
            self.agents = []
        return out


SMALL = {
    "ppo": {"n_steps": 64, "batch_size": 32, "n_epochs": 1, "n_envs": 2},
    "sac": {"learning_starts": 50, "batch_size": 32, "buffer_size": 1000},
    "td3": {"learning_starts": 50, "batch_size": 32, "buffer_size": 1000},
}


def _check_saved(path, algo, multi_agent, normalize):
    assert os.path.exists(os.path.join(path, "model.zip"))
    assert os.path.exists(os.path.join(path, "vecnormalize.pkl")) == normalize
    cfg = json.load(open(os.path.join(path, "config.json")))
    assert cfg["algo"] == algo and cfg["multi_agent"] == multi_agent
    assert (cfg["library"], cfg["library_version"]) == (backend(algo).library, backend(algo).library_version())
    assert cfg["provenance"] == run_provenance()  # the code and the machine that trained it
    assert os.listdir(os.path.join(path, "checkpoints"))


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_centralised_smoke(algo, tmp_path):
    import gymnasium as gym

    out = str(tmp_path / algo)
    # normalisation on for every algorithm so the VecNormalize round trip is exercised
    hp = dict(SMALL[algo], normalize={"norm_obs": True, "norm_reward": False})
    res = train("Pendulum-v1", algo, timesteps=200, seed=0, out=out, progress=False, hyperparams=hp)
    assert res.model.num_timesteps >= 200
    _check_saved(out, algo, False, True)
    agent = load_agent(os.path.join(out, "model.zip"))
    assert agent.vecnorm is not None and agent.vecnorm.obs_rms.count > 1
    env = gym.make("Pendulum-v1")
    pol = agent.central_policy()
    obs, _ = env.reset(seed=1)
    for _ in range(5):
        act = pol(obs)
        assert env.action_space.contains(np.asarray(act, dtype=np.float32))
        obs, *_ = env.step(act)
    # loaded model gives the same deterministic action as the in-memory one
    o = np.asarray(obs, np.float32)[None]
    mem, _ = res.model.predict(agent.vecnorm.normalize_obs(o), deterministic=True)
    np.testing.assert_allclose(agent.predict(o), mem, rtol=1e-5, atol=1e-6)
    if backend(algo).library != LEGACY_LIBRARY:
        return  # SBX trained it; tests/test_agents_backends.py loads legacy runs of stable-baselines3
    # runs written before config.json recorded the library (results/*.tar.gz) still load
    cfg_path = os.path.join(out, "config.json")
    cfg = json.load(open(cfg_path))
    json.dump({k: v for k, v in cfg.items() if k not in ("library", "library_version")}, open(cfg_path, "w"))
    np.testing.assert_array_equal(load_agent(out).predict(o), agent.predict(o))


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_multi_agent_smoke(algo, tmp_path):
    out = str(tmp_path / f"{algo}_ma")
    res = train(PointMasses, algo, multi_agent=True, timesteps=150, seed=0, out=out, progress=False,
                hyperparams=SMALL[algo], env_name="point_masses")
    # SB3 counts one sample per agent: 2 agents
    assert res.model.num_timesteps >= 300
    assert res.config["n_agents"] == 2
    _check_saved(out, algo, True, bool(res.config["normalize"]))
    agent = load_agent(out)
    env = PointMasses()
    pol = agent.parallel_policy(env)
    obs, _ = env.reset(seed=3)
    while env.agents:
        acts = pol(obs)
        assert set(acts) == set(env.agents)
        for a, v in acts.items():
            assert env.action_space(a).contains(np.asarray(v, dtype=np.float32))
        obs, *_ = env.step(acts)


def test_multi_agent_rejects_td3(tmp_path):
    with pytest.raises(ValueError, match="multi-agent"):
        train(PointMasses, "td3", multi_agent=True, timesteps=10, out=str(tmp_path), progress=False)


def test_every_recipe_algorithm_has_a_backend():
    assert set(BACKENDS) == set(ALGOS)
    with pytest.raises(ValueError, match="unknown algorithm"):
        backend("a2c")


def test_hyperparams_lookup_order():
    default = load_hyperparams("ppo", "default")
    hp = load_hyperparams("ppo", "tracking")
    assert hp["n_envs"] == 8 and default["n_envs"] == 4  # env entry overrides default
    assert hp["env_kwargs"] == {"state_bound": 30}
    ma = load_hyperparams("ppo", "tracking", multi_agent=True)
    assert ma["agent_id"] is True and ma["n_envs"] == 4  # default-ma, then tracking, then tracking-ma
    res = load_hyperparams("ppo", "tracking", variant="residual")
    assert res["residual_scale"] == 0.2 and res["n_envs"] == 8
    over = load_hyperparams("ppo", "tracking", overrides={"policy_kwargs": {"net_arch": [8]}})
    assert over["policy_kwargs"]["net_arch"] == [8] and over["policy_kwargs"]["activation_fn"] == "tanh"
    with pytest.raises(ValueError, match="algorithm"):
        load_hyperparams("a2c", "default")


def test_training_leaves_nothing_in_the_temp_dir(tmp_path, monkeypatch):
    """SB3's default logger makes an empty SB3-<date> directory in the temp dir for every run; the
    runs log to stdout only (or to --tensorboard), so nothing is left behind."""
    import tempfile

    from agents.training.train import train

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    train("tracking", "ppo", timesteps=64, seed=0, out=str(tmp_path / "run"), progress=False,
          hyperparams={"n_envs": 1, "n_steps": 64, "batch_size": 32, "n_epochs": 1}, env_kwargs={"max_cycles": 20},
          checkpoint_freq=0)
    assert os.path.isfile(tmp_path / "run" / "model.zip")
    assert list(tmp.iterdir()) == []
