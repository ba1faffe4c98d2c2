"""ParallelVecEnv: slot mapping, truncation vs termination, terminal observations,
seeding determinism, padding / one-hot ids, the VecEnv interface, close."""
from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agents.vecenv.parallel import ParallelVecEnv
from agents.vecenv.slots import SlotEncoder


class TinyParallel(ParallelEnv):
    """Two heterogeneous agents; obs = [t, noise...]; episode truncated after
    ``horizon`` steps, terminated when agent a0 sends an action > ``terminate_above``."""

    metadata = {"name": "tiny_v0", "render_modes": ["rgb_array"]}

    def __init__(self, horizon=4, terminate_above=np.inf, render_mode=None):
        self.possible_agents = ["a0", "a1"]
        self.agents = []
        self.horizon = horizon
        self.terminate_above = terminate_above
        self.render_mode = render_mode
        self._obs_spaces = {"a0": spaces.Box(-10, 10, (2,), np.float32), "a1": spaces.Box(-10, 10, (3,), np.float32)}
        self._act_spaces = {"a0": spaces.Box(-1, 1, (1,), np.float32), "a1": spaces.Box(-2, 2, (2,), np.float32)}
        self.rng = np.random.default_rng()
        self.closed = False
        self.received = []
        self.resets = 0

    def observation_space(self, agent):
        return self._obs_spaces[agent]

    def action_space(self, agent):
        return self._act_spaces[agent]

    def _obs(self):
        return {"a0": np.array([self.t, self.noise[0]], np.float32),
                "a1": np.array([self.t, self.noise[1], self.noise[2]], np.float32)}

    def reset(self, seed=None, options=None):
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self.resets += 1
        self.agents = list(self.possible_agents)
        self.t = 0
        self.noise = self.rng.normal(size=3)
        return self._obs(), {a: {"reset": True} for a in self.agents}

    def step(self, actions):
        self.received.append({a: np.array(v) for a, v in actions.items()})
        self.t += 1
        self.noise = self.rng.normal(size=3)
        rew = {"a0": float(self.t), "a1": 10.0 * self.t}
        terminate = float(np.asarray(actions["a0"])[0]) > self.terminate_above
        trunc = self.t >= self.horizon
        term = {a: terminate for a in self.agents}
        truncs = {a: trunc for a in self.agents}
        obs = self._obs()
        infos = {a: {"t": self.t} for a in self.agents}
        if terminate or trunc:
            self.agents = []
        return obs, rew, term, truncs, infos

    def render(self):
        return np.full((4, 4, 3), self.t, dtype=np.uint8)

    def close(self):
        self.closed = True


def make(n=2, **kw):
    return ParallelVecEnv([lambda: TinyParallel(**kw) for _ in range(n)])


def test_slot_mapping_and_spaces():
    venv = make(3)
    assert venv.num_envs == 6
    assert [venv.slot_info(s) for s in range(6)] == [(0, "a0"), (0, "a1"), (1, "a0"), (1, "a1"), (2, "a0"), (2, "a1")]
    assert venv.slot(2, "a1") == 5 and venv.slot(1, 0) == 2
    # padded to the largest agent: obs 3, action 2
    assert venv.observation_space.shape == (3,)
    assert venv.action_space.shape == (2,)
    np.testing.assert_array_equal(venv.action_space.low, [-2, -2])
    np.testing.assert_array_equal(venv.action_space.high, [2, 2])
    venv.seed(0)
    obs = venv.reset()
    assert obs.shape == (6, 3) and obs.dtype == np.float32
    # a0 observations are zero-padded; time is 0 at reset
    assert np.all(obs[0::2, 2] == 0.0)
    assert np.all(obs[:, 0] == 0.0)
    assert venv.reset_infos[1] == {"reset": True}


def test_actions_routed_truncated_and_clipped():
    venv = make(2)
    venv.seed(1)
    venv.reset()
    acts = np.array([[0.5, 9.0], [1.5, -3.0], [-0.25, 7.0], [0.1, 0.2]], np.float32)
    venv.step(acts)
    got = [e.received[-1] for e in venv.envs]
    np.testing.assert_allclose(got[0]["a0"], [0.5])  # second component dropped
    np.testing.assert_allclose(got[0]["a1"], [1.5, -2.0])  # clipped to a1's bounds
    np.testing.assert_allclose(got[1]["a0"], [-0.25])
    np.testing.assert_allclose(got[1]["a1"], [0.1, 0.2])
    assert got[0]["a0"].shape == (1,) and got[0]["a1"].shape == (2,)


def test_truncation_flags_terminal_observation_and_autoreset():
    venv = make(2, horizon=3)
    venv.seed(5)
    venv.reset()
    zero = np.zeros((4, 2), np.float32)
    for k in range(2):
        obs, rew, done, infos = venv.step(zero)
        assert not done.any()
        assert all(info["TimeLimit.truncated"] is False for info in infos)
        np.testing.assert_allclose(rew, [k + 1, 10 * (k + 1)] * 2)
    obs, rew, done, infos = venv.step(zero)
    assert done.all()
    for s, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is True
        term = info["terminal_observation"]
        assert term[0] == 3.0  # last observation of the finished episode (t = horizon)
    assert np.all(obs[:, 0] == 0.0)  # autoreset: first observation of the next episode
    assert [e.resets for e in venv.envs] == [2, 2]


def test_termination_is_not_truncation():
    venv = make(2, horizon=10, terminate_above=0.5)
    venv.seed(0)
    venv.reset()
    acts = np.zeros((4, 2), np.float32)
    acts[0, 0] = 0.9  # copy 0, agent a0 triggers termination of copy 0 only
    obs, rew, done, infos = venv.step(acts)
    np.testing.assert_array_equal(done, [True, True, False, False])
    assert infos[0]["TimeLimit.truncated"] is False and infos[1]["TimeLimit.truncated"] is False
    assert "terminal_observation" in infos[0] and "terminal_observation" not in infos[2]
    assert obs[0, 0] == 0.0 and obs[2, 0] == 1.0


def rollout(seed, steps=7, agent_id=False):
    venv = ParallelVecEnv([lambda: TinyParallel(horizon=3) for _ in range(2)], agent_id=agent_id)
    seeds = venv.seed(seed)
    out = [venv.reset()]
    rng = np.random.default_rng(123)
    for _ in range(steps):
        out.append(venv.step(rng.uniform(-1, 1, size=(4, 2)).astype(np.float32))[0])
    venv.close()
    return seeds, np.stack(out)


def test_determinism_under_seed():
    s1, a = rollout(3)
    s2, b = rollout(3)
    _, c = rollout(4)
    assert s1 == s2 == [3, 3, 4, 4]  # one seed per copy, repeated for its slots
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # copies get different seeds -> different noise
    assert not np.array_equal(a[0, 0, 1], a[0, 2, 1])


def test_agent_one_hot_id():
    _, traj = rollout(0, steps=1, agent_id=True)
    obs = traj[0]
    assert obs.shape == (4, 3 + 2)
    np.testing.assert_array_equal(obs[:, 3:], [[1, 0], [0, 1], [1, 0], [0, 1]])


def test_vecenv_interface_and_close():
    venv = make(2)
    venv.seed(0)
    venv.reset()
    assert venv.get_attr("horizon") == [4, 4, 4, 4]
    venv.set_attr("horizon", 9, indices=[2])
    assert venv.get_attr("horizon") == [4, 4, 9, 9]
    # env_method runs once per distinct copy even when several of its slots are named
    before = [e.resets for e in venv.envs]
    venv.env_method("reset", indices=[0, 1])
    assert [e.resets for e in venv.envs] == [before[0] + 1, before[1]]
    assert venv.env_is_wrapped(TinyParallel) == [True] * 4
    assert venv.env_is_wrapped(SlotEncoder) == [False] * 4
    venv.step_async(np.zeros((4, 2), np.float32))
    obs, rew, done, infos = venv.step_wait()
    assert obs.shape == (4, 3) and rew.shape == (4,) and done.shape == (4,) and len(infos) == 4
    venv.close()
    assert all(e.closed for e in venv.envs)
    venv.close()  # idempotent


def test_render_rgb_array():
    venv = ParallelVecEnv([lambda: TinyParallel(render_mode="rgb_array") for _ in range(2)])
    venv.reset()
    imgs = venv.get_images()
    assert len(imgs) == 2 and imgs[0].shape == (4, 4, 3)
    assert venv.render(mode="rgb_array").ndim == 3


def test_works_with_sb3_checker_and_vecnormalize():
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    venv = VecNormalize(VecMonitor(make(2, horizon=3)))
    venv.seed(0)
    venv.reset()
    for _ in range(6):
        _, _, done, infos = venv.step(np.zeros((4, 2), np.float32))
    assert "episode" in infos[0]  # VecMonitor saw whole episodes
    assert infos[0]["episode"]["l"] == 3
    venv.close()


def test_rescaled_actions_map_onto_each_agents_bounds():
    venv = ParallelVecEnv([lambda: TinyParallel() for _ in range(1)], rescale_actions=True)
    np.testing.assert_array_equal(venv.action_space.low, [-1, -1])
    np.testing.assert_array_equal(venv.action_space.high, [1, 1])
    venv.reset()
    venv.step(np.array([[1.0, 0.3], [-1.0, 0.5]], np.float32))
    got = venv.envs[0].received[-1]
    np.testing.assert_allclose(got["a0"], [1.0])  # a0 bounds [-1, 1]
    np.testing.assert_allclose(got["a1"], [-2.0, 1.0])  # a1 bounds [-2, 2]: -1 -> -2, 0.5 -> 1
    venv.step(np.array([[5.0, 0.0], [0.0, -7.0]], np.float32))  # out of [-1, 1]: clipped first
    got = venv.envs[0].received[-1]
    np.testing.assert_allclose(got["a0"], [1.0])
    np.testing.assert_allclose(got["a1"], [0.0, -2.0])


@pytest.mark.parametrize("agent_id,rescale", [(False, False), (True, True)])
def test_batch_encoding_and_decoding_are_those_of_every_slot(agent_id, rescale):
    """SlotEncoder.encode_batch / decode_batch (what CoreVecEnv uses) give encode / decode of every slot,
    bit for bit, with agents of different widths and bounds that are not round numbers."""
    agents = ["a", "b", "c"]
    obs = {"a": spaces.Box(-1.0, 1.0, (4,)), "b": spaces.Box(-2.0, 3.0, (2,)), "c": spaces.Box(-5.0, 5.0, (3,))}
    act = {"a": spaces.Box(-np.float32(1.7), np.float32(1.7), (2,)), "b": spaces.Box(-0.3, 2.9, (1,)),
           "c": spaces.Box(np.float32(-np.pi), np.float32(np.e), (3,))}
    enc = SlotEncoder(agents, obs, act, agent_id=agent_id, rescale_actions=rescale)
    rng = np.random.default_rng(0)
    C = 4
    o = np.zeros((C, 3, 4))
    for j, a in enumerate(agents):
        o[:, j, :obs[a].shape[0]] = rng.normal(size=(C, obs[a].shape[0]))
    want = np.stack([enc.encode(j, o[c, j, :obs[a].shape[0]]) for c in range(C) for j, a in enumerate(agents)])
    got = enc.encode_batch(o)
    assert got.dtype == want.dtype == np.float32
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(enc.encode_batch(o[:, :, :3])[:, :3], want[:, :3])  # narrower padded rows
    shared = rng.uniform(-4.0, 4.0, size=(C * 3, enc.act_dim)).astype(np.float32)
    want = np.stack([np.concatenate([enc.decode(j, shared[c * 3 + j]) for j in range(3)]) for c in range(C)])
    got = enc.decode_batch(shared)
    assert got.dtype == want.dtype == np.float32 and got.shape == (C, 6)
    np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError, match=r"obs must have shape \(copies, 3, <= 4\)"):
        enc.encode_batch(np.zeros((2, 2, 4)))
