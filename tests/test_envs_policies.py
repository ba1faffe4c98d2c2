"""Reference policies acting through the API: reproduction of reproduce.simulate on NE2 and
convergence at the default control period."""
import gymnasium as gym
import numpy as np
import pytest

import dobs_envs  # noqa: F401
from baselines.policies import CentralizedSeparationPolicy, SeparationPolicy, ZeroPolicy
from dobs_envs import disturbance_rejection_v0, hetero_mas_v0, tracking_v0
from dobs_envs.reproduce import simulate
from dobs_envs.scenarios.paper import ne2

T_END = 2.0


@pytest.fixture(scope="module")
def ne2_traj():
    return simulate(ne2(), t_end=T_END)


def _run_parallel(obs_dtype):
    sc = ne2()
    # substeps=1: control period = dt as in reproduce.simulate; bounds wide enough never to clip the paper run
    env = tracking_v0.parallel_env(substeps=1, horizon=T_END, obs_dtype=obs_dtype, action_bound=1e3)
    pol = SeparationPolicy(env)
    assert pol.kind == "tracking"
    obs, infos = env.reset(seed=123, options={"x0": sc.x0})
    pol.reset()
    xs, ee = [env.sim_state.x[0].copy()], [[infos[a]["estimation_error"] for a in env.possible_agents]]
    while env.agents:
        obs, rew, term, trunc, infos = env.step(pol(obs))
        xs.append(env.sim_state.x[0].copy())
        ee.append([infos[a]["estimation_error"] for a in env.possible_agents])
    return np.array(xs), np.array(ee), env


@pytest.mark.parametrize("obs_dtype,tol", [("float64", 1e-10), ("float32", 1e-5)])
def test_tracking_policy_reproduces_simulate_ne2(ne2_traj, obs_dtype, tol):
    xs, ee, env = _run_parallel(obs_dtype)
    tr = ne2_traj
    assert xs.shape == tr.x.shape
    assert np.max(np.abs(xs - tr.x)) < tol * max(1.0, np.abs(tr.x).max())
    # per-agent info = estimation error of its linked observer node (links = 0..4)
    assert np.max(np.abs(ee - tr.est_err[:, :5])) < 10 * tol
    assert np.linalg.norm(env.sim_state.x[0] - env.sim_state.x_r[0]) == pytest.approx(tr.tracking_error[-1], rel=10 * tol)


def test_centralized_policy_reproduces_simulate_ne2(ne2_traj):
    sc = ne2()
    env = gym.make("dobs_envs/Tracking-v0", substeps=1, obs_dtype="float64", action_bound=1e3,
                   max_episode_steps=int(round(T_END / 1e-3)))
    pol = CentralizedSeparationPolicy(env)
    obs, _ = env.reset(seed=0, options={"x0": sc.x0})
    pol.reset()
    xs = [env.unwrapped.parallel_env.sim_state.x[0].copy()]
    done = False
    while not done:
        obs, r, term, trunc, info = env.step(pol(obs))
        xs.append(env.unwrapped.parallel_env.sim_state.x[0].copy())
        done = term or trunc
    assert trunc and not term
    assert np.max(np.abs(np.array(xs) - ne2_traj.x)) < 1e-10


def _episode(env, pol, seed):
    obs, _ = env.reset(seed=seed)
    pol.reset()
    umax = 0.0
    while env.agents:
        act = pol(obs)
        umax = max(umax, max(float(np.max(np.abs(act[a] / env.action_space(a).high))) for a in act))
        obs, rew, term, trunc, info = env.step(act)
    return info["controller_0"], env, umax


def test_tracking_policy_converges_at_default_control_period():
    env = tracking_v0.parallel_env()  # 0.05 s control period, 400 steps = 20 s
    info, env, umax = _episode(env, SeparationPolicy(env), seed=0)
    assert info["tracking_error"] < 0.1 and env.estimation_errors().max() < 0.05
    assert umax < 1.0  # the default bounds are not reached by the reference policy


def test_adaptive_smc_policy_keeps_beta_and_needs_reset():
    env = disturbance_rejection_v0.parallel_env(max_cycles=400)
    pol = SeparationPolicy(env)
    assert pol.kind == "adaptive_sliding_mode"
    info, env, umax = _episode(env, pol, seed=1)
    assert info["tracking_error"] < 0.6 and umax < 1.0  # residual set of Theorem adsmthm (epsilon = 0.2)
    assert np.all(pol.beta > pol.beta0)
    pol.reset()
    assert np.all(pol.beta == pol.beta0)
    zero_info, *_ = _episode(env, ZeroPolicy(env), seed=1)
    assert zero_info["tracking_error"] > 10 * info["tracking_error"]


def test_hetero_mas_reference_policy_rendezvous():
    env = hetero_mas_v0.parallel_env()
    pol = SeparationPolicy(env)
    assert pol.kind == "feedback"
    info, env, umax = _episode(env, pol, seed=2)
    assert info["disagreement"] < 0.01 and env.estimation_errors().max() < 0.02 and umax < 1.0


def test_policy_requires_its_observation_components():
    env = tracking_v0.parallel_env(observation=("y", "xhat"))
    with pytest.raises(ValueError, match="'r'"):
        SeparationPolicy(env)
    with pytest.raises(ValueError, match="kind"):
        SeparationPolicy(tracking_v0.parallel_env(), kind="pid")
