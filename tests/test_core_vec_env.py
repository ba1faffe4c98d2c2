"""The SB3 VecEnv over the batched core (agents.vecenv.batched_core.CoreVecEnv): the same streams as
today's DummyVecEnv of Gymnasium envs (centralised) and ParallelVecEnv of PettingZoo envs
(parameter-shared), autoreset/terminal observations, truncation flags, seeding, training."""
from __future__ import annotations

import numpy as np
import pytest

import gymnasium as gym
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

import dobs_envs  # noqa: F401
from agents.vecenv.batched_core import CoreVecEnv
from agents.training.env_factory import build_vec_env, core_of
from agents.vecenv.parallel import ParallelVecEnv
from dobs_envs import hetero_mas_v0, random_network_v0, tracking_v0
from dobs_envs.envs import HeteroMASEnv, RandomNetworkEnv, TrackingEnv


def _same_streams(va, vb, actions):
    oa, ob = va.reset(), vb.reset()
    np.testing.assert_array_equal(oa, ob)
    for act in actions:
        ra, rb = va.step(act), vb.step(act)
        np.testing.assert_array_equal(ra[0], rb[0])
        np.testing.assert_array_equal(ra[1], rb[1])
        np.testing.assert_array_equal(ra[2], rb[2])
        for ia, ib in zip(ra[3], rb[3]):
            assert ia["TimeLimit.truncated"] == ib["TimeLimit.truncated"]
            assert ("terminal_observation" in ia) == ("terminal_observation" in ib)
            if "terminal_observation" in ia:
                np.testing.assert_array_equal(ia["terminal_observation"], ib["terminal_observation"])


def test_centralised_matches_dummy_vec_env_of_gym_envs():
    n, steps = 3, 14
    core = TrackingEnv.make_core(n, horizon=float("inf"), state_bound=25.0)
    core.max_cycles = 6
    va = CoreVecEnv(core)
    vb = DummyVecEnv([lambda: gym.make("dobs_envs/Tracking-v0", max_episode_steps=6, state_bound=25.0)
                      for _ in range(n)])
    va.seed(7)
    vb.seed(7)
    rng = np.random.default_rng(1)
    acts = rng.uniform(-1, 1, size=(steps, n, 5)).astype(np.float32) * np.array([15, 30, 25, 125, 10], np.float32)
    acts[2:, 1] = [15, 30, 25, 125, 10]  # copy 1 terminates on the state bound
    _same_streams(va, vb, acts)


@pytest.mark.parametrize("agent_id,rescale", [(False, False), (True, True)])
def test_shared_matches_parallel_vec_env(agent_id, rescale):
    n, steps = 2, 12
    core = HeteroMASEnv.make_core(n, max_cycles=5)
    va = CoreVecEnv(core, shared=True, agent_id=agent_id, rescale_actions=rescale)
    vb = ParallelVecEnv([lambda: hetero_mas_v0.parallel_env(max_cycles=5) for _ in range(n)], agent_id=agent_id,
                        rescale_actions=rescale)
    assert va.observation_space == vb.observation_space and va.action_space == vb.action_space
    assert va.num_envs == vb.num_envs == 10
    assert va.seed(3) == vb.seed(3) == [3] * 5 + [4] * 5
    rng = np.random.default_rng(2)
    acts = rng.uniform(-1.5, 1.5, size=(steps, 10, 1)).astype(np.float32) * (1 if rescale else 8)
    _same_streams(va, vb, acts)


def test_shared_rescaled_actions_decode_as_slot_encoder_with_bounds_that_are_not_float32():
    """RandomNetwork's calibrated bounds are not float32 numbers; the shared slots still map actions
    exactly as SlotEncoder.decode does with the agents' float32 Boxes (ParallelVecEnv, evaluation)."""
    n, steps = 3, 10
    core = RandomNetworkEnv.make_core(n, max_cycles=4)
    assert np.any(core.action_bound.astype(np.float32).astype(np.float64) != core.action_bound)
    va = CoreVecEnv(core, shared=True, agent_id=True, rescale_actions=True)
    vb = ParallelVecEnv([lambda: random_network_v0.parallel_env(max_cycles=4) for _ in range(n)], agent_id=True,
                        rescale_actions=True)
    assert va.action_space == vb.action_space and va.num_envs == vb.num_envs
    va.seed(5)
    vb.seed(5)
    acts = np.random.default_rng(4).uniform(-1.2, 1.2, size=(steps,) + (va.num_envs,) + va.action_space.shape)
    _same_streams(va, vb, acts.astype(np.float32))

def test_terminal_observation_truncation_and_autoreset():
    core = TrackingEnv.make_core(2, max_cycles=4, state_bound=15.0)
    venv = CoreVecEnv(core, shared=True, agent_id=True)
    venv.seed(0)
    obs = venv.reset()
    assert obs.shape == (10, 31 + 5)
    np.testing.assert_array_equal(obs[:5, 31:], np.eye(5))
    acts = np.zeros((10, 1), np.float32)
    acts[5:] = 200.0  # copy 1 (slots 5..9): clipped to its bounds, leaves the state bound
    for k in range(3):
        obs, rew, done, infos = venv.step(acts)
        assert not done[:5].any()
        if done[5]:
            break
    assert done[5:].all() and not done[:5].any()
    assert all(i["TimeLimit.truncated"] is False and i["termination_reason"] == 1 for i in infos[5:])
    assert all(i["termination_reason"] == 0 and "terminal_observation" not in i for i in infos[:5])
    assert "terminal_observation" in infos[5] and not np.array_equal(infos[5]["terminal_observation"], obs[5])
    assert rew[5] == rew[9] and rew[0] == rew[4]
    while not done[0]:
        obs, rew, done, infos = venv.step(np.zeros((10, 1), np.float32))
    assert infos[0]["TimeLimit.truncated"] is True and infos[0]["termination_reason"] == 3  # horizon
    assert core.cycles[0] == 0  # reset in the same step (SB3 convention)


def test_build_vec_env_uses_the_core_for_dobs_envs_only():
    venv = build_vec_env("tracking", n_envs=4, seed=0)
    assert isinstance(venv, VecMonitor) and isinstance(venv.venv, CoreVecEnv) and venv.num_envs == 4
    assert venv.venv.core.max_cycles == 400
    ma = build_vec_env("hetero_mas", multi_agent=True, n_envs=2, seed=0, agent_id=True)
    assert isinstance(ma.venv, CoreVecEnv) and ma.num_envs == 10 and ma.unwrapped.n_agents == 5
    pend = build_vec_env("Pendulum-v1", n_envs=2, seed=0)
    assert isinstance(pend, DummyVecEnv)
    res = build_vec_env("tracking", n_envs=2, seed=0, residual_scale=0.2)
    assert isinstance(res, DummyVecEnv)  # the residual wrappers of agents.training.hybrid
    assert core_of("dobs_envs/Tracking-v0", 2, {"horizon": 1.0}, False).max_cycles == 20
    assert core_of(tracking_v0.parallel_env, 2, None, True) is None


def test_episode_statistics_and_ppo_smoke():
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    venv = build_vec_env("tracking", n_envs=4, seed=0, env_kwargs={"max_cycles": 8}, normalize_actions=True)
    assert venv.action_space.high.tolist() == [1.0] * 5
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, verbose=0)
    model.set_logger(Logger(folder=None, output_formats=[]))  # SB3's default logger leaves an empty temp directory
    model.learn(64)
    assert model.num_timesteps >= 64
    venv.reset()
    for _ in range(8):
        _, _, done, infos = venv.step(np.zeros((4, 5), np.float32))
    assert done.all() and infos[0]["episode"]["l"] == 8
