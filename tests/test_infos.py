"""Infos have the same keys from ``reset`` on and numeric values only, in every adapter (issue 9).

Clients that build their info specs from the reset infos (TorchRL's PettingZooWrapper, BenchMARL)
break on a key that appears later or on a string value; these tests run every adapter through
a termination, a truncation and the next episode and compare the keys with the reset's.
"""
from __future__ import annotations

import numbers

import gymnasium as gym
import numpy as np
import pytest

import dobs_envs  # noqa: F401
from dobs_envs import hetero_mas_v0, tracking_v0
from dobs_envs.envs import REASONS, DObsVectorEnv, TrackingEnv


def _numeric(v) -> bool:
    if isinstance(v, (bool, np.bool_)):
        return True
    if isinstance(v, numbers.Number):
        return True
    return isinstance(v, np.ndarray) and (np.issubdtype(v.dtype, np.number) or v.dtype == bool)


def _check(info: dict, keys: set, where: str):
    assert set(info) == keys, f"{where}: keys {sorted(info)} != reset keys {sorted(keys)}"
    bad = {k: v for k, v in info.items() if not _numeric(v)}
    assert not bad, f"{where}: non-numeric info values {bad}"


def test_reason_table():
    assert REASONS == {0: "none", 1: "state_bound_exceeded", 2: "non_finite_state", 3: "horizon"}


@pytest.mark.parametrize("mod", [tracking_v0, hetero_mas_v0], ids=["tracking_v0", "hetero_mas_v0"])
def test_parallel_env_infos(mod):
    env = mod.parallel_env(max_cycles=3, state_bound=15.0)
    _, infos = env.reset(seed=0)
    keys = set(infos["controller_0"])
    assert {"estimation_error", "tracking_error", "gamma", "gamma_s", "termination_reason"} <= keys
    for a in env.possible_agents:
        _check(infos[a], keys, f"reset {a}")
        assert infos[a]["termination_reason"] == 0
    reasons = []
    for episode in range(3):  # a truncation, a termination (state bound), a truncation
        push = episode == 1
        while env.agents:
            acts = {a: (env.action_space(a).high if push else np.zeros(env.action_space(a).shape, np.float32))
                    for a in env.agents}
            _, _, term, trunc, infos = env.step(acts)
            for a in env.possible_agents:
                _check(infos[a], keys, f"episode {episode} {a}")
            ended = term["controller_0"] or trunc["controller_0"]
            assert (infos["controller_0"]["termination_reason"] != 0) == ended
        reasons.append(infos["controller_0"]["termination_reason"])
        _, infos = env.reset()
        _check(infos["controller_0"], keys, "reset after an episode")
    assert reasons[0] == reasons[2] == 3  # horizon (max_cycles)


def test_termination_code_on_state_bound():
    env = tracking_v0.parallel_env(state_bound=15.0)
    env.reset(seed=0)
    hi = {a: env.action_space(a).high for a in env.agents}
    while env.agents:
        _, _, term, _, infos = env.step(hi)
    assert term["controller_0"] and REASONS[infos["controller_0"]["termination_reason"]] == "state_bound_exceeded"


def test_aec_env_infos():
    env = tracking_v0.env(max_cycles=2)
    env.reset(seed=0)
    keys = set(env.infos["controller_0"])
    assert "termination_reason" in keys
    for _ in range(2):
        for agent in env.agent_iter():
            _, _, term, trunc, info = env.last()
            _check(info, keys, f"AEC {agent}")
            env.step(None if term or trunc else np.zeros(1, np.float32))
        env.reset()
        _check(env.infos["controller_0"], keys, "AEC reset")


def test_centralised_env_infos():
    _, info = gym.make("dobs_envs/HeteroMAS-v0").reset(seed=0)
    assert {"tracking_error", "estimation_errors", "gamma", "gamma_s", "disagreement", "termination_reason"} == set(info)
    env = gym.make("dobs_envs/Tracking-v0", max_episode_steps=3, state_bound=15.0)
    _, info = env.reset(seed=0)
    keys = set(info)
    assert info["termination_reason"] == 0
    codes = []
    for push in (False, True):
        done = False
        while not done:
            a = env.action_space.high if push else np.zeros(env.action_space.shape, np.float32)
            _, _, term, trunc, info = env.step(a)
            _check(info, keys, "step")
            done = term or trunc
        codes.append(info["termination_reason"])
        _, info = env.reset()
        _check(info, keys, "reset")
    assert codes == [0, 1]  # TimeLimit truncation: code 0; state bound: code 1


def test_vector_env_infos():
    venv = DObsVectorEnv(TrackingEnv, 3, max_episode_steps=3, state_bound=15.0)
    _, info = venv.reset(seed=0)
    keys = set(info)
    assert "termination_reason" in keys and "_termination_reason" in keys
    np.testing.assert_array_equal(info["termination_reason"], 0)
    acts = np.zeros((3, 5), np.float32)
    acts[1] = venv.single_action_space.high
    seen = set()
    for _ in range(8):
        _, _, term, trunc, info = venv.step(acts)
        _check(info, keys, "vector step")
        assert info["termination_reason"].shape == (3,) and info["_termination_reason"].all()
        np.testing.assert_array_equal(info["termination_reason"] != 0, term | trunc)
        seen.update(info["termination_reason"].tolist())
    assert {0, 1, 3} <= seen


@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize("diagnostics", [False, True])
def test_core_vec_env_infos(shared, diagnostics):
    from agents.vecenv.batched_core import CoreVecEnv
    from dobs_envs.envs import HeteroMASEnv

    expected = {"TimeLimit.truncated", "termination_reason"}
    if diagnostics:
        expected |= ({"estimation_error", "tracking_error", "gamma", "gamma_s"} if shared else
                     {"estimation_errors", "tracking_error", "gamma", "gamma_s"})
    hetero = CoreVecEnv(HeteroMASEnv.make_core(2), shared=shared, diagnostics=diagnostics)
    hetero.reset()
    assert set(hetero.reset_infos[0]) == expected | ({"disagreement"} if diagnostics else set())
    core = TrackingEnv.make_core(2, max_cycles=3, state_bound=15.0)
    venv = CoreVecEnv(core, shared=shared, diagnostics=diagnostics)
    venv.seed(0)
    venv.reset()
    keys = set(venv.reset_infos[0])
    assert keys == expected
    acts = np.zeros((venv.num_envs,) + venv.action_space.shape, np.float32)
    K = venv.n_agents
    acts[K:] = venv.action_space.high  # copy 1 leaves the state bound
    codes = set()
    for _ in range(6):
        _, _, dones, infos = venv.step(acts)
        for s, info in enumerate(infos):
            _check({k: v for k, v in info.items() if k != "terminal_observation"}, keys, f"slot {s}")
            assert ("terminal_observation" in info) == dones[s]
            codes.add(info["termination_reason"])
    assert {0, 1, 3} <= codes
    if diagnostics and shared:  # slot (copy b, agent k) reports agent k's node of copy b
        venv.reset()
        info = venv.reset_infos[K + 2]
        assert info["estimation_error"] == core.estimation_errors[1, core.links[2]]
