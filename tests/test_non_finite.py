"""A non-finite simulated state terminates the episode cleanly (issue 11, part 4).

What happens on that terminal step (documented in the env docstrings, "Episode End"):
``terminated`` is True for every agent with ``info[agent]["termination_reason"] == 2``
(``REASONS[2] == "non_finite_state"``); observations and ``state()`` are cleaned (NaN -> 0, +-inf ->
+-largest finite value of the observation dtype); the reward is finite; ``info``
keeps the raw (possibly non-finite) diagnostics.
"""
import warnings

import gymnasium as gym
import numpy as np
import pytest

from dobs_envs import disturbance_rejection_v0, tracking_v0
from dobs_envs.envs import REASONS
from dobs_envs.envs.features import write_features
from dobs_envs.envs.numpy_features import write_features_reference


def _assert_clean_termination(env, obs, rew, term, trunc, info):
    for a in env.possible_agents:
        assert term[a] and not trunc[a]
        assert REASONS[info[a]["termination_reason"]] == "non_finite_state"
        assert np.all(np.isfinite(obs[a])) and env.observation_space(a).contains(obs[a])
        assert np.isfinite(rew[a])
    assert np.all(np.isfinite(env.state()))
    assert env.agents == []


@pytest.mark.parametrize("obs_dtype", ["float32", "float64"])
def test_overflowing_observer_terminates_through_the_public_api(obs_dtype):
    # inside the bound the simulation stays finite (the bound is at most the env's limit, issue 41:
    # tests/test_bounded_states.py); an initial state at the edge of the float range overflows
    # the plant, the adaptive gains gamma ~ phi ||eps||^2 and the observers within one control step
    env = tracking_v0.parallel_env(obs_dtype=obs_dtype)
    env.reset(seed=0, options={"x0": np.full(env.core.n_states, 1.7e308)})
    out = env.step({a: np.zeros(env.action_space(a).shape, np.float32) for a in env.possible_agents})
    assert not np.all(np.isfinite(env.sim_state.x)) and not np.all(np.isfinite(env.sim_state.gamma))
    _assert_clean_termination(env, *out)


def _inject(env, field, bad):
    """Put ``bad`` into one entry of the simulation state through the core's public setter."""
    s = env.sim_state
    arr = getattr(s, field).copy()
    arr.flat[arr.size // 2] = bad
    env.core.set_sim_state(s.replace(**{field: arr}))


@pytest.mark.parametrize("field", ["x", "z", "gamma", "gamma_s", "v", "x_r"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_injected_non_finite_value_terminates(field, bad):
    env = disturbance_rejection_v0.parallel_env() if field == "v" else tracking_v0.parallel_env()
    env.reset(seed=1)
    _inject(env, field, bad)
    out = env.step({a: np.zeros(env.action_space(a).shape, np.float32) for a in env.possible_agents})
    _assert_clean_termination(env, *out)


def test_core_reports_the_reason_code_per_copy():
    from dobs_envs.envs import DObsVectorEnv, TrackingEnv

    venv = DObsVectorEnv(TrackingEnv, 3, state_bound=50.0)
    venv.reset(seed=0)
    s = venv.core.sim_state
    s.z[1, 2, 3] = np.nan  # copy 1: non-finite observer state
    s.x[2] *= 100.0  # copy 2: beyond the state bound
    venv.core.set_sim_state(s)
    obs, rew, term, trunc, info = venv.step(np.zeros((3, 5), np.float32))
    np.testing.assert_array_equal(term, [False, True, True])
    np.testing.assert_array_equal(info["termination_reason"], [0, 2, 1])
    assert [REASONS[int(c)] for c in info["termination_reason"]] == ["none", "non_finite_state", "state_bound_exceeded"]
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))


def test_gymnasium_view_terminates_cleanly():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        env = gym.make("dobs_envs/Tracking-v0")
    env.reset(seed=0, options={"x0": np.full(9, 1.7e308)})
    obs, rew, term, trunc, info = env.step(np.zeros(5, np.float32))
    assert term and not trunc and REASONS[info["termination_reason"]] == "non_finite_state"
    assert np.all(np.isfinite(obs)) and np.isfinite(rew)


@pytest.mark.parametrize("field", ["x", "z", "gamma", "gamma_s", "v", "x_r"])
def test_kernel_finiteness_flag(field):
    env = disturbance_rejection_v0.parallel_env()
    env.reset(seed=2)
    core = env.core
    s = env.sim_state
    L = core.layout

    def flags(state):
        res = []
        for fn in (write_features, write_features_reference):
            W = np.zeros((1, L.size + core.n_nodes + core.n_inputs))
            obs = np.zeros((1, core.n_agents, core.obs_dim))
            fin = np.zeros(1, bool)
            fn(np.array([0]), (state.t, state.x, state.z, state.gamma, state.gamma_s, state.v, state.x_r), W, obs,
               *_static_nr(core), False, (np.zeros(1), np.zeros(1), np.zeros(1), fin))
            res.append(bool(fin[0]))
        return res

    assert flags(s) == [True, True]
    for bad in (np.nan, np.inf):
        arr = getattr(s, field).copy()
        arr.flat[-1] = bad
        assert flags(s.replace(**{field: arr})) == [False, False]


def _static_nr(core):
    """Static kernel arrays of a system without reference (NE3)."""
    from dobs_envs.envs.features import pack_static

    p, L, sc = core.params, core.layout, core.scenario
    return pack_static(p.C, p.G_bar, np.zeros((3, core.n_inputs)), core.Q, core.R,
                       L.offsets([c.shape[0] for c in sc.C]), L.padded_index, L.size)
