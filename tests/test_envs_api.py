"""API conformance of the environments: PettingZoo parallel/AEC tests, Gymnasium and SB3 env checkers."""
import warnings

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, parallel_seed_test

import dobs_envs
from dobs_envs import disturbance_rejection_v0, hetero_mas_v0, random_network_v0, tracking_lossy_v0, tracking_v0

MODULES = [tracking_v0, tracking_lossy_v0, disturbance_rejection_v0, hetero_mas_v0, random_network_v0]
IDS = ["tracking_v0", "tracking_lossy_v0", "disturbance_rejection_v0", "hetero_mas_v0", "random_network_v0"]


@pytest.mark.parametrize("mod", MODULES, ids=IDS)
def test_parallel_api(mod):
    env = mod.parallel_env()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # unbounded Box observations are by design
        parallel_api_test(env, num_cycles=60)  # sets env.max_cycles = 60: episodes end by truncation
    assert env.agents == []


@pytest.mark.parametrize("mod", MODULES, ids=IDS)
def test_aec_api_and_seed(mod):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        api_test(mod.env(max_cycles=20), num_cycles=30)
        parallel_seed_test(lambda: mod.parallel_env(max_cycles=20), num_cycles=25)


@pytest.mark.parametrize("mod", MODULES, ids=IDS)
def test_max_cycles(mod):
    max_cycles_test(mod)  # parallel and AEC forms end after exactly max_cycles steps


@pytest.mark.parametrize("mod", MODULES, ids=IDS)
def test_module_conventions(mod):
    env = mod.parallel_env()
    assert isinstance(env, mod.raw_env)
    md = env.metadata
    assert md["render_modes"] == ["human", "rgb_array"] and md["is_parallelizable"] is True
    assert md["name"] == mod.__name__.rsplit(".", 1)[1] and md["render_fps"] > 0
    assert env.possible_agents[0] == "controller_0"
    for a in env.possible_agents:
        assert env.observation_space(a) is env.observation_space(a)
        assert env.action_space(a).dtype == np.float32
    obs, _ = env.reset(seed=1)
    assert env.state_space.contains(env.state())
    for a, o in obs.items():
        assert env.observation_space(a).contains(o)


@pytest.mark.parametrize("env_id", list(dobs_envs.GYM_IDS))
def test_gymnasium_and_sb3_checkers(env_id):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id)
    assert env.spec.max_episode_steps == dobs_envs.GYM_IDS[env_id][1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # unnormalised action Box / unbounded obs: warnings only
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped)
    env.close()


def test_gym_timelimit_is_the_only_truncation():
    env = gym.make("dobs_envs/Tracking-v0", max_episode_steps=5)
    env.reset(seed=0)
    assert env.unwrapped.parallel_env.max_cycles is None  # the wrapped env never truncates by itself
    flags = []
    for _ in range(5):
        _, _, term, trunc, _ = env.step(np.zeros(5, np.float32))
        flags.append((term, trunc))
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])
    with pytest.raises(TypeError, match="max_episode_steps"):
        gym.make("dobs_envs/Tracking-v0", max_cycles=10)


def test_unknown_kwargs_rejected_with_valid_list():
    with pytest.raises(TypeError, match="valid arguments are") as exc:
        tracking_v0.parallel_env(substep=10)
    assert "substeps" in str(exc.value) and "substep'" in str(exc.value)
    with pytest.raises(TypeError, match="valid arguments"):
        gym.make("dobs_envs/DisturbanceRejection-v0", foo=1)
    with pytest.raises(TypeError):
        random_network_v0.parallel_env(scenario=None)
