"""Hybrid baselines: residual RL around the paper's controller and the behaviour-cloning warm start."""
from __future__ import annotations

import numpy as np
import pytest

from agents.config.envs import gym_factory, parallel_factory
from agents.evaluate import evaluate_policy
from agents.training.hybrid import (ResidualGymWrapper, ResidualParallelEnv, ResidualPolicy, behaviour_cloning_dataset,
                                    pretrain_ppo)
from baselines.policies import CentralizedSeparationPolicy, SeparationPolicy

KW = {"max_cycles": 40}


def test_zero_correction_is_the_paper_controller():
    penv = parallel_factory("tracking", KW)()
    paper = evaluate_policy(penv, SeparationPolicy(penv), 2, 5, parallel=True)
    zero = {a: np.zeros(1) for a in penv.possible_agents}
    res = evaluate_policy(penv, ResidualPolicy(penv, lambda o: zero, 0.2, parallel=True), 2, 5, parallel=True)
    assert [r.ret for r in res] == [r.ret for r in paper]
    genv = gym_factory("tracking", KW)()
    cres = evaluate_policy(genv, ResidualPolicy(genv, lambda o: np.zeros(5), 0.2, parallel=False), 2, 5,
                           parallel=False)
    np.testing.assert_allclose([r.ret for r in cres], [r.ret for r in paper], rtol=1e-12)


def test_residual_gym_wrapper_adds_the_bounded_correction():
    genv = gym_factory("tracking", KW)()
    b = genv.unwrapped.action_space.high.astype(np.float64)
    w = ResidualGymWrapper(gym_factory("tracking", KW)(), 0.2)
    assert w.action_space.shape == (5,) and np.all(w.action_space.low == -1) and np.all(w.action_space.high == 1)
    ref = CentralizedSeparationPolicy(genv)
    obs_ref, _ = genv.reset(seed=3)
    ref.reset()
    obs, _ = w.reset(seed=3)
    np.testing.assert_array_equal(obs, obs_ref)
    a = np.array([1.0, -1.0, 0.5, 0.0, 3.0])  # 3.0 is clipped to 1
    u_expected = np.clip(ref(obs_ref) + 0.2 * b * np.clip(a, -1, 1), -b, b)
    w.step(a)
    base = w.unwrapped.parallel_env
    np.testing.assert_allclose(base.applied_input, u_expected, rtol=1e-12)
    with pytest.raises(ValueError, match="residual action"):
        w.step(np.full(5, np.nan))
    with pytest.raises(ValueError, match="residual_scale"):
        ResidualGymWrapper(gym_factory("tracking", KW)(), -0.1)


def test_residual_parallel_env_passes_the_pettingzoo_api_test():
    from pettingzoo.test import parallel_api_test

    env = ResidualParallelEnv(parallel_factory("tracking", KW)(), 0.3)
    for a in env.possible_agents:
        sp = env.action_space(a)
        assert sp.shape == (1,) and sp.low[0] == -1 and sp.high[0] == 1
    parallel_api_test(env, num_cycles=50)


def test_behaviour_cloning_fits_the_paper_controller():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    from gymnasium.wrappers import RescaleAction

    make = gym_factory("tracking", {"max_cycles": 100})
    data = behaviour_cloning_dataset(make, 3, seed=0, noise=0.1)
    T = data["obs"].shape[0]
    assert data["act"].shape == (T, 5) and np.all(np.abs(data["act"]) <= 1) and data["done"].sum() == 3
    venv = VecNormalize(DummyVecEnv([lambda: RescaleAction(make(), np.float32(-1.0), np.float32(1.0))]), gamma=0.99)
    model = PPO("MlpPolicy", venv, seed=0, policy_kwargs={"net_arch": [64, 64]})
    before = float(np.mean((model.policy.predict(venv.normalize_obs(data["obs"]), deterministic=True)[0]
                            - data["act"]) ** 2))
    info = pretrain_ppo(model, data, epochs=20, seed=0)
    pred = model.policy.predict(venv.normalize_obs(data["obs"]), deterministic=True)[0]
    after = float(np.mean((pred - data["act"]) ** 2))
    assert info["samples"] == T
    # the normaliser saw the demonstrations (count grows by T) and the fit is 10x better than the random init
    assert venv.obs_rms.count > T and after < 0.1 * before
