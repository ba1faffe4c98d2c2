"""The native Gymnasium VectorEnv (gym.make_vec(..., vectorization_mode="vector_entry_point")):
registration for every id, NEXT_STEP autoreset, seeding, Gymnasium's checkers where they apply,
and whole episodes identical to the single (Gymnasium and PettingZoo) adapters for the same seeds."""
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import (check_reset_seed_determinism, check_returned_data_not_reused,
                                        check_space_limit, data_equivalence)
from gymnasium.utils.passive_env_checker import env_reset_passive_checker
from gymnasium.vector.vector_env import AutoresetMode

import dobs_envs
from dobs_envs import disturbance_rejection_v0, tracking_v0
from dobs_envs.envs import DObsVectorEnv
from dobs_envs.sim.period_kernel import MIN_TILE

IDS = list(dobs_envs.GYM_IDS)


@pytest.mark.parametrize("env_id", IDS)
def test_make_vec_for_every_id(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # make_vec warns about a missing/invalid autoreset_mode
        venv = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    single = gym.make(env_id)
    assert isinstance(venv, DObsVectorEnv) and venv.num_envs == 3
    assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space
    assert venv.core.max_cycles == dobs_envs.GYM_IDS[env_id][1] == single.spec.max_episode_steps
    obs, info = venv.reset(seed=0)
    assert obs.shape == (3,) + single.observation_space.shape and obs in venv.observation_space
    obs, rew, term, trunc, info = venv.step(venv.action_space.sample())
    assert rew.shape == term.shape == trunc.shape == (3,) and rew.dtype == np.float64
    assert info["estimation_errors"].shape == (3, venv.core.n_nodes) and info["_tracking_error"].all()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # unbounded observations, unnormalised actions: by design
        check_space_limit(venv.single_observation_space, "observation")
        check_space_limit(venv.single_action_space, "action")
        check_reset_seed_determinism(venv)
        env_reset_passive_checker(venv)
        # (bool(terminated) of a batch is only defined for one copy)
        check_returned_data_not_reused(gym.make_vec(env_id, num_envs=1))
    venv.close()
    single.close()


def test_default_vectorization_and_big_batches():
    venv = gym.make_vec("dobs_envs/Tracking-v0", num_envs=1024)  # vector_entry_point is the default
    assert isinstance(venv, DObsVectorEnv) and venv.spec.max_episode_steps == 400
    obs, _ = venv.reset(seed=1)
    assert obs.shape == (1024, 155)
    obs, rew, term, trunc, _ = venv.step(np.zeros((1024, 5), np.float32))
    assert np.isfinite(rew).all() and not term.any()


def _single_episode(seed, steps, actions):
    env = gym.make("dobs_envs/DisturbanceRejection-v0", disturbance="random", max_episode_steps=steps)
    out = [env.reset(seed=seed)[0]]
    for k in range(steps):
        obs, r, term, trunc, info = env.step(actions[k])
        out += [obs, r, term, trunc, info["tracking_error"], info["estimation_errors"]]
    return out


def test_whole_episodes_identical_to_the_single_adapters():
    """Copies of a vector env (here a SIMD tile: B >= MIN_TILE) replay the single envs seeded
    with seed + c bit for bit: observations, rewards, flags, infos."""
    B, steps, seed = 20, 30, 11
    rng = np.random.default_rng(0)
    acts = rng.uniform(-12, 12, size=(steps, B, 5)).astype(np.float32)  # partly outside the bounds (clipped)
    assert B >= MIN_TILE
    venv = gym.make_vec("dobs_envs/DisturbanceRejection-v0", num_envs=B, disturbance="random",
                        max_episode_steps=steps)
    vec = [[o] for o in venv.reset(seed=seed)[0]]
    for k in range(steps):
        obs, r, term, trunc, info = venv.step(acts[k])
        for c in range(B):
            vec[c] += [obs[c], r[c], term[c], trunc[c], info["tracking_error"][c], info["estimation_errors"][c]]
    assert trunc.all()
    for c in (0, 7, B - 1):
        single = _single_episode(seed + c, steps, acts[:, c])
        assert len(single) == len(vec[c])
        for a, b in zip(single, vec[c]):
            assert data_equivalence(np.asarray(a), np.asarray(b), exact=True)
    # and the PettingZoo adapter: same observations and rewards, copy 2
    penv = disturbance_rejection_v0.parallel_env(disturbance="random", max_cycles=steps)
    o, _ = penv.reset(seed=seed + 2)
    assert np.array_equal(np.concatenate([o[a] for a in penv.possible_agents]), vec[2][0])
    for k in range(steps):
        o, r, *_ = penv.step({a: acts[k, 2, j:j + 1] for j, a in enumerate(penv.possible_agents)})
        assert np.array_equal(np.concatenate([o[a] for a in penv.possible_agents]), vec[2][1 + 6 * k])
        assert r["controller_0"] == vec[2][2 + 6 * k]


def test_next_step_autoreset():
    venv = DObsVectorEnv(tracking_v0.raw_env, 3, max_episode_steps=4, state_bound=20.0)
    obs0, _ = venv.reset(seed=[5, 6, 7])
    big = np.zeros((3, 5), np.float32)
    big[1] = venv.single_action_space.high  # copy 1 leaves the state bound
    done_at = {}
    for k in range(1, 7):
        obs, rew, term, trunc, info = venv.step(big)
        for c in range(3):
            if (term[c] or trunc[c]) and c not in done_at:
                done_at[c] = k
                if term[c]:
                    assert info["termination_reason"][c] == 1 and info["_termination_reason"][c]
        if k == done_at.get(1, -1) + 1:  # the step after copy 1's termination: reset, reward 0, no flags
            assert rew[1] == 0.0 and not term[1] and not trunc[1]
            assert venv.core.cycles[1] == 0
    assert done_at[0] == done_at[2] == 4 and done_at[1] < 4
    # after truncation at step 4, step 5 restarted copies 0 and 2 from their generators
    assert venv.core.cycles.tolist()[0] == 1


def test_seeding_reset_mask_and_errors():
    venv = DObsVectorEnv(tracking_v0.raw_env, 4)
    a, _ = venv.reset(seed=3)
    b, _ = venv.reset(seed=[3, 4, 5, 6])
    assert np.array_equal(a, b)
    c, _ = venv.reset(seed=4)
    assert np.array_equal(c[:3], a[1:]) and not np.array_equal(c[3], a[3])
    venv.step(np.zeros((4, 5)))
    before = venv.core.sim_state.t.copy()
    venv.reset(options={"reset_mask": np.array([True, False, False, True])})
    assert venv.core.sim_state.t.tolist() == [0.0, before[1], before[2], 0.0]
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 5)))
    with pytest.raises(TypeError, match="max_episode_steps"):
        gym.make_vec("dobs_envs/Tracking-v0", num_envs=2, max_cycles=3)
