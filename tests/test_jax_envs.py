"""The JAX environments' interfaces: gymnax's (make, reset, step with auto-reset, spaces) and JaxMARL's
(make_marl), jit/vmap/scan composition, float32 and float64, the reset distributions, and bad input."""
from __future__ import annotations

import importlib
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from scipy import stats

jax = pytest.importorskip("jax")
jnp = jax.numpy

import dobs_envs  # noqa: E402,F401  (registers the Gymnasium ids)
from dobs_envs.envs.distributions import ResetDistribution  # noqa: E402
from dobs_envs.registry import ENVIRONMENTS  # noqa: E402
from dobs_envs.jax import Box, make, make_marl, registered_envs  # noqa: E402
from dobs_envs.jax import core as jcore  # noqa: E402

IDS = [e.gym_id for e in ENVIRONMENTS.values() if e.fault_free is None]


def test_import_dobs_envs_does_not_import_jax():
    code = ("import sys, dobs_envs, dobs_envs.envs, dobs_envs.tracking_v0, gymnasium as gym; "
            "gym.make('dobs_envs/Tracking-v0'); print('jax' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("env_id", IDS)
def test_spaces_are_the_gymnasium_envs(env_id):
    env, params = make(env_id)
    genv = gym.make(env_id)
    for mine, theirs in ((env.observation_space(params), genv.observation_space),
                         (env.action_space(params), genv.action_space)):
        assert mine.shape == theirs.shape and mine.dtype == theirs.dtype
        np.testing.assert_array_equal(mine.low, theirs.low)
        np.testing.assert_array_equal(mine.high, theirs.high)
    obs, state = env.reset(jax.random.PRNGKey(0), params)
    assert obs.shape == genv.observation_space.shape and obs.dtype == genv.observation_space.dtype
    assert env_id in registered_envs()


def test_reset_observation_equals_the_compiled_envs_from_the_same_state():
    with jax.enable_x64(True):
        env, params = make("dobs_envs/Tracking-v0", dtype="float64")
        genv = gym.make("dobs_envs/Tracking-v0")
        x0 = np.linspace(-1.0, 1.0, 9)
        obs, _ = genv.reset(seed=1, options={"x0": x0})
        state = jcore.initial_state(params, env.structure, x0)
        np.testing.assert_array_equal(np.asarray(env.get_obs(state, params)), obs)


def test_step_auto_resets_and_keeps_the_final_observation():
    env, params = make("dobs_envs/HeteroMAS-v0", state_bound=1e-3)  # every first step ends on the bound
    key = jax.random.PRNGKey(3)
    obs0, state = env.reset(key, params)
    obs, new, reward, term, trunc, info = env.step(jax.random.PRNGKey(4), state, jnp.zeros(5), params)
    assert bool(term) and not bool(trunc) and int(info["termination_reason"]) == 1
    assert int(new.time) == 0 and float(new.t) == 0.0  # a new episode
    assert not np.array_equal(np.asarray(info["final_observation"]), np.asarray(obs))
    assert float(reward) < 0 and set(info) >= {"tracking_error", "estimation_errors", "gamma", "gamma_s",
                                               "disagreement", "termination_reason", "final_observation",
                                               "terminated", "truncated"}


def test_truncation_after_max_episode_steps_with_the_horizon_code():
    env, params = make("dobs_envs/Tracking-v0", max_episode_steps=3)
    _, s = env.reset(jax.random.PRNGKey(0), params)
    for k in range(3):
        _, s, _, term, trunc, info = env.step(jax.random.PRNGKey(k), s, jnp.zeros(5), params)
    assert bool(trunc) and not bool(term) and int(info["termination_reason"]) == 3 and int(s.time) == 0


def test_jit_vmap_scan_over_copies_keys_and_parameters():
    env, params = make("dobs_envs/Tracking-v0")
    B, T = 6, 5
    bounds = jnp.array([1e3, 1e3, 1e3, 1e-3, 1e-3, 1e-3], dtype=params.state_bound.dtype)
    batch = jax.tree.map(lambda a: jnp.broadcast_to(a, (B,) + a.shape), params).replace(state_bound=bounds)
    obs, state = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(0), B), batch)

    @jax.jit
    def rollout(state, key):
        def body(s, k):
            obs, s, r, term, trunc, info = jax.vmap(env.step)(jax.random.split(k, B), s, jnp.zeros((B, 5)), batch)
            return s, (r, term)
        return jax.lax.scan(body, state, jax.random.split(key, T))

    _, (rewards, term) = rollout(state, jax.random.PRNGKey(1))
    assert rewards.shape == (T, B)
    term = np.asarray(term)
    assert not term[:, :3].any() and term[:, 3:].all()  # the copies with the tiny bound end every step
    assert len({tuple(np.asarray(o)) for o in obs}) == B  # every key drew its own initial state


def test_float32_runs_and_float64_needs_x64():
    env, params = make("dobs_envs/DisturbanceRejection-v0", dtype="float32")
    assert params.A.dtype == jnp.float32
    obs, s = env.reset(jax.random.PRNGKey(0), params)
    obs, s, r, *_ = env.step(jax.random.PRNGKey(1), s, jnp.zeros(5), params)
    assert np.isfinite(float(r)) and s.z.dtype == jnp.float32
    if not jax.config.jax_enable_x64:
        with pytest.raises(ValueError, match="jax_enable_x64"):
            make("dobs_envs/Tracking-v0", dtype="float64")


def test_float32_costs_little_on_a_full_episode():
    """The paper controller's episode return in float32 against float64 (both from the same initial state):
    within 1e-3 relative (measured: up to 7e-5 on the evaluation episodes)."""
    from baselines.policies import SeparationPolicy
    from dobs_envs.jax import parity
    from dobs_envs.jax.env import _build

    entry = ENVIRONMENTS["tracking"]
    penv = importlib.import_module(entry.module).parallel_env(max_cycles=400)
    st32, p32, _ = _build(entry, {"dtype": "float32"})
    r64, r32, _ = parity.free_run_episode(penv, st32, p32, SeparationPolicy, seed=10_000, dtype=jnp.float32)
    assert abs(r32 - r64) <= 1e-3 * abs(r64)


def test_reset_draws_the_compiled_envs_distributions():
    """Initial states (tracking: x0 + U[-1, 1]^n; random_network: U[-s, s]^n), the exosystem's time shift
    (disturbance_rejection) and the random disturbance's parameters: two-sample KS tests against the numpy
    ResetDistribution's draws (fixed seeds)."""
    n_draw = 2000
    for name, opts in (("tracking", {}), ("random_network", {}), ("disturbance_rejection", {}),
                       ("disturbance_rejection", {"disturbance": "random"})):
        env, params = make(ENVIRONMENTS[name].gym_id, **opts)
        core = env.core
        states = jax.vmap(lambda k: jcore.reset(k, params, env.structure))(jax.random.split(jax.random.PRNGKey(5),
                                                                                                n_draw))
        dist = ResetDistribution(core.scenario, core.init_noise, core.disturbance, core.disturbance_amplitude)
        rng = np.random.default_rng(5)
        ref_x, ref_v, ref_sig = [], [], []
        for _ in range(n_draw):
            ref_x.append(dist.x0(rng))
            v, sig = dist.disturbance_params(rng)
            ref_v.append(v)
            ref_sig.append(sig)
        for j in range(core.n_states):
            assert stats.ks_2samp(np.asarray(states.x[:, j]), np.array(ref_x)[:, j]).pvalue > 1e-3, (name, "x", j)
        for j in range(core.n_unknown):
            assert stats.ks_2samp(np.asarray(states.v[:, j]), np.array(ref_v)[:, j]).pvalue > 1e-3, (name, "v", j)
        if core.disturbance == "random":
            sig = np.asarray(states.sig)
            np.testing.assert_allclose(sig[:, 0].sum(axis=-1), core.disturbance_amplitude, rtol=1e-5)
            ref = np.stack([np.stack(s) for s in ref_sig])
            for q in range(3):
                assert stats.ks_2samp(sig[:, q].ravel(), ref[:, q].ravel()).pvalue > 1e-3, (name, "sig", q)


def test_multi_agent_view_matches_the_pettingzoo_env():
    for name in ("tracking_v0", "hetero_mas_v0", "random_network_v0"):
        env = make_marl(name, normalized_actions=True)
        pz = importlib.import_module(f"dobs_envs.{name}").parallel_env(normalized_actions=True)
        assert env.agents == list(pz.possible_agents) and env.num_agents == len(pz.possible_agents)
        for a in env.agents:
            for mine, theirs in ((env.observation_space(a), pz.observation_space(a)),
                                 (env.action_space(a), pz.action_space(a))):
                assert mine.shape == theirs.shape and mine.dtype == theirs.dtype
                np.testing.assert_array_equal(mine.low, theirs.low)
                np.testing.assert_array_equal(mine.high, theirs.high)
        obs, state = env.reset(jax.random.PRNGKey(0))
        acts = {a: env.action_space(a).sample(jax.random.PRNGKey(k)) for k, a in enumerate(env.agents)}
        obs, state, rewards, dones, infos = env.step(jax.random.PRNGKey(1), state, acts)
        assert set(dones) == set(env.agents) | {"__all__"} and set(rewards) == set(env.agents)
        assert all(v.shape == (env.num_agents,) for v in infos.values())
        assert all(obs[a].shape == env.observation_space(a).shape for a in env.agents)


def test_multi_agent_actions_reach_their_channels():
    """Agent k's action moves only its own inputs: u from the dict equals the concatenated channels."""
    env = make_marl("tracking", normalized_actions=False)
    acts = {a: jnp.full(env.action_space(a).shape, float(k + 1)) for k, a in enumerate(env.agents)}
    u = np.asarray(env.inputs(acts))
    pz = importlib.import_module("dobs_envs.tracking_v0").parallel_env()
    expected = np.zeros(pz.core.n_inputs)
    for k, sl in enumerate(pz.core.channel_slices):
        expected[sl] = k + 1
    np.testing.assert_array_equal(u, expected)


def test_box_samples_lie_in_the_box():
    box = Box(np.array([-1.0, 0.0, -np.inf]), np.array([1.0, np.inf, np.inf]), (3,))
    xs = jax.vmap(box.sample)(jax.random.split(jax.random.PRNGKey(0), 200))
    assert bool(jnp.all(jax.vmap(box.contains)(xs)))
    assert not bool(box.contains(jnp.array([2.0, 0.0, 0.0]))) and not bool(box.contains(jnp.zeros(2)))


@pytest.mark.parametrize("call,exc,match", [
    (lambda: make("dobs_envs/Nope-v0"), ValueError, "registered ids"),
    (lambda: make("dobs_envs/Tracking-v0", substep=3), TypeError, "unexpected keyword argument 'substep'"),
    (lambda: make("dobs_envs/Tracking-v0", max_cycles=3), TypeError, "max_episode_steps"),
    (lambda: make("dobs_envs/Tracking-v0", render_mode="human"), TypeError, "render_mode"),
    (lambda: make("dobs_envs/Tracking-v0", dtype="float16"), ValueError, "dtype"),
    (lambda: make("dobs_envs/Tracking-v0", max_episode_steps=0), ValueError, "max_episode_steps"),
    (lambda: make("dobs_envs/Tracking-v0", sparse="yes"), ValueError, "sparse"),
    (lambda: make("dobs_envs/TrackingLossy-v0", faults={"oo_period": 0.0123}), ValueError, "oo_period"),
    (lambda: make_marl("nope_v0"), ValueError, "registered names"),
])
def test_bad_input_gets_a_specific_error(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_bad_actions_get_a_specific_error():
    env, params = make("dobs_envs/Tracking-v0")
    _, s = env.reset(jax.random.PRNGKey(0), params)
    with pytest.raises(ValueError, match=r"shape \(5,\)"):
        env.step(jax.random.PRNGKey(0), s, jnp.zeros(4), params)
    menv = make_marl("tracking_v0")
    _, s = menv.reset(jax.random.PRNGKey(0))
    with pytest.raises(ValueError, match="one action per agent"):
        menv.step(jax.random.PRNGKey(0), s, {"controller_0": jnp.zeros(1)})


def test_a_float64_env_refuses_to_run_without_x64():
    with jax.enable_x64(True):
        env, params = make("dobs_envs/Tracking-v0", dtype="float64")
    with jax.enable_x64(False), pytest.raises(ValueError, match="64-bit JAX is off"):
        env.reset(jax.random.PRNGKey(0))
