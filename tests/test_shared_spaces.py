"""The options ``normalized_actions`` and ``padded_observations`` (issue 9): identical agent spaces.

With both, every agent of every environment has the same action and observation space (what
parameter sharing in SuperSuit, RLlib, BenchMARL and TorchRL requires); the dynamics are those
of the plain environment with the actions scaled by the bounds and the observations padded.
"""
from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test

import dobs_envs  # noqa: F401
from dobs_envs import disturbance_rejection_v0, hetero_mas_v0, random_network_v0, tracking_v0
from dobs_envs.envs import DObsVectorEnv, RandomNetworkEnv

BOTH = {"normalized_actions": True, "padded_observations": True}
MODULES = [tracking_v0, disturbance_rejection_v0, hetero_mas_v0, random_network_v0]
IDS = [m.__name__.rsplit(".", 1)[1] for m in MODULES]
#: a random network whose agents differ in observation width and in number of input channels
HETERO = {"system_seed": 1, "generator_kwargs": {"inputs_per_controller": (1, 2)}}


def _pair(mod, **kw):
    return mod.parallel_env(**kw), mod.parallel_env(**kw, **BOTH)


@pytest.mark.parametrize("mod", MODULES, ids=IDS)
def test_identical_spaces_and_padded_observations(mod):
    plain, shared = _pair(mod)
    agents = shared.possible_agents
    obs_sp, act_sp = shared.observation_space(agents[0]), shared.action_space(agents[0])
    assert all(shared.observation_space(a) == obs_sp and shared.action_space(a) == act_sp for a in agents)
    M = max(plain.action_space(a).shape[0] for a in agents)
    W = max(plain.observation_space(a).shape[0] for a in agents)
    assert act_sp == gym.spaces.Box(-1.0, 1.0, (M,), np.float32)
    differ = len({plain.observation_space(a).shape for a in agents}) > 1
    # padding and the obs_mask only where the widths differ (issue 19: an all-ones mask doubled tracking's 31 to 62)
    assert obs_sp.shape == ((2 * W,) if differ else (W,)) and obs_sp.dtype == plain.observation_space(agents[0]).dtype
    assert shared.core.layout.masked == differ
    o_plain, _ = plain.reset(seed=3)
    o_shared, _ = shared.reset(seed=3)
    for a in agents:
        w = o_plain[a].size
        assert obs_sp.contains(o_shared[a])
        np.testing.assert_array_equal(o_shared[a][:w], o_plain[a])
        np.testing.assert_array_equal(o_shared[a][w:W], 0.0)
        if differ:
            np.testing.assert_array_equal(o_shared[a][W:], (np.arange(W) < w).astype(np.float32))
            assert shared.observation_layout(a)["obs_mask"] == slice(W, 2 * W)
        else:
            assert "obs_mask" not in shared.observation_layout(a)
        lay = plain.observation_layout(a)
        assert {k: v for k, v in shared.observation_layout(a).items() if k != "obs_mask"} == lay
        lo, hi = plain.observation_space(a).low, plain.observation_space(a).high
        assert np.all(obs_sp.low[:w] <= lo) and np.all(obs_sp.high[:w] >= hi)


def test_differing_channel_widths_pad_the_actions_and_ignore_the_padding():
    plain, shared = _pair(random_network_v0, **HETERO)
    widths = [plain.action_space(a).shape[0] for a in plain.possible_agents]
    assert sorted(set(widths)) == [1, 2]
    assert len({shared.observation_space(a).shape for a in shared.possible_agents}) == 1
    assert len({plain.observation_space(a).shape for a in plain.possible_agents}) > 1
    plain.reset(seed=0)
    shared.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        acts = {a: rng.uniform(-1.2, 1.2, 2).astype(np.float32) for a in shared.possible_agents}
        for a, w in zip(shared.possible_agents, widths):
            acts[a][w:] = 1e6  # padding: ignored
        phys = {a: np.asarray(acts[a][:w], np.float64) * plain.action_bound[sl]  # float64 bounds (the Box's are float32)
                for a, w, sl in zip(plain.possible_agents, widths, plain.channel_slices)}
        o1, r1, *_ = plain.step(phys)
        o2, r2, *_ = shared.step(acts)
        assert r1 == r2
        np.testing.assert_array_equal(shared.applied_input, plain.applied_input)
        for a in plain.possible_agents:
            np.testing.assert_array_equal(o2[a][:o1[a].size], o1[a])
    with pytest.raises(ValueError, match="controller_0"):  # wrong shape: named agent, as without the option
        shared.step({a: np.zeros(1) for a in shared.possible_agents})


def test_same_dynamics_as_the_plain_env_with_scaled_actions():
    plain, shared = _pair(tracking_v0, max_cycles=6)
    b = plain.action_bound
    plain.reset(seed=1)
    shared.reset(seed=1)
    rng = np.random.default_rng(1)
    while plain.agents:
        a = rng.uniform(-1.5, 1.5, 5)  # beyond [-1, 1]: clipped to the bound in both
        o1, r1, t1, tr1, i1 = plain.step({ag: a[k:k + 1] * b[k:k + 1] for k, ag in enumerate(plain.possible_agents)})
        o2, r2, t2, tr2, i2 = shared.step({ag: a[k:k + 1] for k, ag in enumerate(shared.possible_agents)})
        assert r1 == r2 and t1 == t2 and tr1 == tr2 and i1 == i2
    assert shared.agents == []


def test_the_paper_controller_acts_through_the_options():
    from baselines.policies import CentralizedSeparationPolicy, SeparationPolicy

    returns = []
    for kw in ({}, BOTH):
        env = tracking_v0.parallel_env(max_cycles=20, **kw)
        pol = SeparationPolicy(env)
        obs, _ = env.reset(seed=0)
        ret = 0.0
        while env.agents:
            obs, rew, *_ = env.step(pol(obs))
            ret += rew["controller_0"]
        returns.append(ret)
    np.testing.assert_allclose(returns[1], returns[0], rtol=1e-12)
    genv = gym.make("dobs_envs/Tracking-v0", max_episode_steps=20, **BOTH)
    pol = CentralizedSeparationPolicy(genv)
    obs, _ = genv.reset(seed=0)
    ret, done = 0.0, False
    while not done:
        obs, r, term, trunc, _ = genv.step(pol(obs))
        ret, done = ret + r, term or trunc
    np.testing.assert_allclose(ret, returns[0], rtol=1e-12)


def test_centralised_and_vector_views():
    penv = random_network_v0.parallel_env(**HETERO, **BOTH)
    genv = gym.make("dobs_envs/RandomNetwork-v0", **HETERO, **BOTH)
    m = penv.core.n_inputs
    assert genv.action_space == gym.spaces.Box(-1.0, 1.0, (m,), np.float32)  # one agent: no padding
    D = penv.observation_space("controller_0").shape[0]
    assert genv.observation_space.shape == (3 * D,)
    o, _ = genv.reset(seed=4)
    po, _ = penv.reset(seed=4)
    np.testing.assert_array_equal(o, np.concatenate([po[a] for a in penv.possible_agents]))
    assert genv.unwrapped.agent_observation_slices[1] == slice(D, 2 * D)
    venv = gym.make_vec("dobs_envs/RandomNetwork-v0", num_envs=2, **HETERO, **BOTH)
    assert venv.single_action_space == genv.action_space and venv.single_observation_space == genv.observation_space
    vo, _ = venv.reset(seed=4)
    np.testing.assert_array_equal(vo[0], o)
    a = np.array([0.5, -0.25, 1.0, -1.0, 0.75][:m], np.float32)
    o1, r1, *_ = genv.step(a)
    vo1, vr1, *_ = venv.step(np.stack([a, a]))
    np.testing.assert_array_equal(vo1[0], o1)
    assert vr1[0] == r1
    phys = a.astype(np.float64) * genv.unwrapped.core.action_bound
    np.testing.assert_array_equal(genv.unwrapped.parallel_env.applied_input, phys)  # |a| <= 1: not clipped
    venv.close()


@pytest.mark.parametrize("kw", [{}, HETERO], ids=["default", "channel_widths_1_2"])
def test_pettingzoo_api_with_the_options(kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        parallel_api_test(random_network_v0.parallel_env(**kw, **BOTH), num_cycles=20)
        api_test(random_network_v0.env(max_cycles=10, **kw, **BOTH), num_cycles=15)


def test_core_vec_env_uses_the_env_spaces():
    from agents.vecenv.batched_core import CoreVecEnv
    from agents.vecenv.parallel import ParallelVecEnv

    core = RandomNetworkEnv.make_core(2, max_cycles=5, **HETERO, **BOTH)
    va = CoreVecEnv(core, shared=True)
    vb = ParallelVecEnv([lambda: random_network_v0.parallel_env(max_cycles=5, **HETERO, **BOTH) for _ in range(2)])
    assert va.observation_space == vb.observation_space and va.action_space == vb.action_space
    va.seed(5)
    vb.seed(5)
    np.testing.assert_array_equal(va.reset(), vb.reset())
    rng = np.random.default_rng(5)
    for _ in range(7):
        act = rng.uniform(-1, 1, (va.num_envs,) + va.action_space.shape).astype(np.float32)
        ra, rb = va.step(act), vb.step(act)
        for x, y in zip(ra[:3], rb[:3]):
            np.testing.assert_array_equal(x, y)
    central = CoreVecEnv(RandomNetworkEnv.make_core(2, **HETERO, **BOTH))
    assert central.action_space == gym.spaces.Box(-1.0, 1.0, (core.n_inputs,), np.float32)


@pytest.mark.parametrize("name", ["normalized_actions", "padded_observations"])
def test_option_validation(name):
    with pytest.raises(ValueError, match=name):
        tracking_v0.parallel_env(**{name: "yes"})
    with pytest.raises(ValueError, match=name):
        gym.make_vec("dobs_envs/Tracking-v0", num_envs=2, **{name: 1})
    assert DObsVectorEnv(RandomNetworkEnv, 1, **{name: np.bool_(True)}).core.options.__getattribute__(name) is True


@pytest.mark.parametrize("mod", MODULES, ids=IDS)
def test_padding_only_where_widths_differ(mod):
    """Equal widths (tracking 31): the shared spaces keep the agents' width and the centralised view
    its width (155, not 310); differing widths (random_network 30/30/28): padding + mask, 2 W."""
    plain, shared = _pair(mod)
    widths = {plain.observation_space(a).shape[0] for a in plain.possible_agents}
    W = max(widths)
    assert {shared.observation_space(a).shape for a in shared.possible_agents} == {(W if len(widths) == 1 else 2 * W,)}
    entry = {tracking_v0: "Tracking", disturbance_rejection_v0: "DisturbanceRejection", hetero_mas_v0: "HeteroMAS",
             random_network_v0: "RandomNetwork"}[mod]
    g_plain = gym.make(f"dobs_envs/{entry}-v0")
    g_shared = gym.make(f"dobs_envs/{entry}-v0", padded_observations=True)
    if len(widths) == 1:
        assert g_shared.observation_space.shape == g_plain.observation_space.shape
    else:
        assert g_shared.observation_space.shape == (2 * W * len(plain.possible_agents),)
