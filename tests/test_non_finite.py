"""A non-finite simulated state terminates the episode cleanly (issue 11, part 4).

What happens on that terminal step (documented in the env docstrings, "Episode End"):
``terminated`` is True for every agent with ``info[agent]["termination_reason"] ==
"non_finite_state"``; observations and ``state()`` are cleaned (NaN -> 0, +-inf ->
+-largest finite value of the observation dtype); the reward is finite; ``info``
keeps the raw (possibly non-finite) diagnostics.
"""
import warnings

import gymnasium as gym
import numpy as np
import pytest

from dobs_envs import disturbance_rejection_v0, tracking_v0
from dobs_envs.envs.numpy_features import write_features_reference
from dobs_envs.envs.observation import write_features_packed


def _assert_clean_termination(env, obs, rew, term, trunc, info):
    for a in env.possible_agents:
        assert term[a] and not trunc[a]
        assert info[a]["termination_reason"] == "non_finite_state"
        assert np.all(np.isfinite(obs[a])) and env.observation_space(a).contains(obs[a])
        assert np.isfinite(rew[a])
    assert np.all(np.isfinite(env.state()))
    assert env.agents == []


@pytest.mark.parametrize("obs_dtype", ["float32", "float64"])
def test_overflowing_observer_terminates_through_the_public_api(obs_dtype):
    # huge inputs with a huge state bound: the adaptive gains gamma ~ phi ||eps||^2 and the
    # observer states overflow within one control step while ||x|| stays below the bound
    env = tracking_v0.parallel_env(state_bound=1e150, action_bound=1e30, obs_dtype=obs_dtype)
    env.reset(seed=0)
    out = env.step({a: np.full(1, 1e30) for a in env.possible_agents})
    assert np.all(np.isfinite(env.sim_state.x)) and not np.all(np.isfinite(env.sim_state.gamma))
    _assert_clean_termination(env, *out)


@pytest.mark.parametrize("field", ["x", "z", "gamma", "gamma_s", "v", "x_r"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_injected_non_finite_value_terminates(field, bad):
    env = disturbance_rejection_v0.parallel_env() if field == "v" else tracking_v0.parallel_env()
    env.reset(seed=1)
    s = env.sim_state
    arr = getattr(s, field).copy()
    arr.flat[arr.size // 2] = bad
    env._sim = s.replace(**{field: arr})  # inject (no public setter for the simulation state)
    out = env.step({a: np.zeros(env.action_space(a).shape, np.float32) for a in env.possible_agents})
    _assert_clean_termination(env, *out)


def test_gymnasium_view_terminates_cleanly():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        env = gym.make("dobs_envs/Tracking-v0", state_bound=1e150, action_bound=1e30)
    env.reset(seed=0)
    obs, rew, term, trunc, info = env.step(np.full(5, 1e30, np.float32))
    assert term and not trunc and info["termination_reason"] == "non_finite_state"
    assert np.all(np.isfinite(obs)) and np.isfinite(rew)


@pytest.mark.parametrize("field", ["x", "z", "gamma", "gamma_s", "v", "x_r"])
def test_kernel_finiteness_flag(field):
    env = disturbance_rejection_v0.parallel_env()
    env.reset(seed=2)
    s = env.sim_state
    L = env.layout

    def flags(state):
        res = []
        for fn in (write_features_packed, write_features_reference):
            W = np.zeros(L.size + env.n_nodes + env.n_inputs)
            out = np.empty(L.all_index.size)
            res.append(fn(state.x, state.z, state.x_r, state.gamma, state.gamma_s, state.v, float(state.t[0]),
                          W, env._SF, env._SI, env.has_reference, out)[3])
        return res

    assert flags(s) == [True, True]
    for bad in (np.nan, np.inf):
        arr = getattr(s, field).copy()
        arr.flat[-1] = bad
        assert flags(s.replace(**{field: arr})) == [False, False]
