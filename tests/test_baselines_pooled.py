"""baselines.pooled: analytic baselines with the centralised agent's (pooled) information.

What the maths promises: the sampled-data Kalman filter on the pooled measurements, with the
simulator's exact transition, reconstructs ``x`` (noise-free: to the float32 rounding of the
observations) on every environment; with an exact prior it is exact from the first step; it
never needs ``env.state()``; where the pooled ``y`` is not detectable it uses the pooled
estimates, and refuses an observation without them; the LQ gains solve the average-cost problem.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from baselines import PooledKalmanPolicy, PooledLQGPolicy
from baselines.policies import SeparationPolicy
from baselines.pooled import PooledObservationError, lq_tracking_gains
from baselines.references import Centralized, DecentralizedPolicy, OraclePolicy, ZeroInputPolicy

ENVS = ("tracking_v0", "disturbance_rejection_v0", "hetero_mas_v0", "random_network_v0")


def _make(name, **kw):
    import importlib

    return importlib.import_module(f"dobs_envs.{name}").parallel_env(**kw)


def _run(env, policy, seed, steps):
    """Closed loop; returns ||xhat_c - x|| per step (x read here, by the test, never by the policy)."""
    obs, _ = env.reset(seed=seed)
    policy.reset()
    xs = env.state_layout()["x"]
    errs = []
    for _ in range(steps):
        acts = policy(obs)
        errs.append(float(np.linalg.norm(policy.filter.x - np.asarray(env.state(), dtype=np.float64)[xs])))
        obs, _, term, trunc, _ = env.step(acts)
        assert not any(term.values())
        if any(trunc.values()):
            break
    return np.array(errs)


@pytest.mark.parametrize("name", ENVS)
@pytest.mark.parametrize("cls", [PooledKalmanPolicy, PooledLQGPolicy])
def test_estimate_converges_on_every_env(name, cls):
    env = _make(name, max_cycles=40)
    pol = cls(env)
    assert pol.filter.W.shape[1] == 0  # the pooled y is observable on the four default envs
    err = _run(env, pol, 20000, 40)
    scale = err[0]
    assert scale > 0.1  # the prior mean is not x(0)
    assert np.all(err[10:] < 1e-4 * max(1.0, scale)), err  # float32 observations, exact model
    env.close()


def test_exact_prior_is_exact_from_the_start():
    env = _make("tracking_v0", max_cycles=10, init_noise=0.0)  # x(0) = the paper's x0, known
    err = _run(env, PooledKalmanPolicy(env), 20000, 10)
    assert np.all(err < 1e-5), err
    env.close()


def test_matches_oracle_once_converged():
    """After the estimator converges the central estimate is x: the paper law on it acts as the oracle."""
    env = _make("tracking_v0", max_cycles=30)
    pk, orc = PooledKalmanPolicy(env), OraclePolicy(env)
    obs, _ = env.reset(seed=20001)
    pk.reset()
    orc.reset()
    for k in range(30):
        a, b = pk(obs), orc(obs)
        if k >= 5:
            for ag in a:
                np.testing.assert_allclose(a[ag], b[ag], rtol=1e-4, atol=1e-4)
        obs, *_ = env.step(a)
    env.close()


class _NoState(Exception):
    pass


def test_never_reads_the_state():
    env = _make("disturbance_rejection_v0", max_cycles=20)
    pols = [PooledKalmanPolicy(env), PooledLQGPolicy(env)]

    def forbidden(*a, **k):
        raise _NoState("the policy read privileged simulator state")

    cls = type(env)
    hidden = type("NoStateEnv", (cls,), {"state": forbidden, "estimation_errors": forbidden,
                                         "sim_state": property(forbidden), "applied_input": property(forbidden)})
    env.__class__ = hidden
    env.core.states = forbidden
    for pol in pols:
        obs, _ = env.reset(seed=20002)
        pol.reset()
        for _ in range(20):
            obs, _, term, trunc, _ = env.step(pol(obs))
            if any(trunc.values()):
                break
    env.__class__ = cls
    del env.core.states
    env.close()


def test_full_observation_ignores_privileged_components():
    """With observation="full" the privileged entries are there but unused: same actions as "local"."""
    loc, full = _make("tracking_v0", max_cycles=10), _make("tracking_v0", max_cycles=10, observation="full")
    p1, p2 = PooledLQGPolicy(loc), PooledLQGPolicy(full)
    o1, _ = loc.reset(seed=20003)
    o2, _ = full.reset(seed=20003)
    p1.reset()
    p2.reset()
    for _ in range(10):
        a1, a2 = p1(o1), p2(o2)
        for ag in a1:
            np.testing.assert_array_equal(a1[ag], a2[ag])
        o1, *_ = loc.step(a1)
        o2, *_ = full.step(a2)
    loc.close()
    full.close()


def test_refuses_observation_without_what_it_needs():
    env = _make("tracking_v0", observation=("xhat", "neighbors", "mask", "r"))
    with pytest.raises(PooledObservationError, match="'y'"):
        PooledKalmanPolicy(env)
    env.close()
    env = _make("tracking_v0", observation=("y", "xhat"))
    with pytest.raises(ValueError, match="'r'"):  # the task's tracking law reads r^k
        PooledKalmanPolicy(env)
    with pytest.raises(PooledObservationError, match="'r'"):
        PooledLQGPolicy(env)
    env.close()
    env = _make("disturbance_rejection_v0", observation=("y", "xhat"))
    PooledKalmanPolicy(env)  # y for the filter, the xhat slot for the substitution: enough
    PooledLQGPolicy(env)
    env.close()
    assert issubclass(PooledObservationError, ValueError)


def _unobservable_env(**kw):
    """NE2 with every controller linked to node 0 (it measures state 1 only): the pooled y is
    not detectable; the pooled estimates of nodes 0, 1 and 5 are."""
    from dobs_envs.envs import make_parallel_env
    from dobs_envs.scenarios.paper import ne2

    return make_parallel_env(dataclasses.replace(ne2(), links=(0, 0, 0, 0, 0)), **kw)


def test_undetectable_pooled_y_uses_the_pooled_estimates():
    env = _unobservable_env(max_cycles=200)
    with pytest.raises(PooledObservationError, match="not detectable"):
        PooledKalmanPolicy(env, estimates="none")
    pol = PooledKalmanPolicy(env)
    assert pol.filter.observable_dim < env.n_states and pol.filter.W.shape[1] > 0
    assert pol.filter.pool.est_nodes == [0, 1, 5]
    err = _run(env, pol, 20000, 200)
    node_err = env.estimation_errors()[[0, 1, 5]]
    assert err[-1] < 0.05 and err[-1] < 10 * node_err.min(), (err[-1], node_err)
    env.close()
    env = _unobservable_env(observation=("y", "r"))
    with pytest.raises(PooledObservationError, match="unobservable"):
        PooledLQGPolicy(env)
    env.close()


def test_random_disturbance_and_random_networks():
    env = _make("disturbance_rejection_v0", max_cycles=60, disturbance="random")
    pol = PooledKalmanPolicy(env)
    assert pol.filter.model == "random_walk"
    err = _run(env, pol, 20004, 60)
    assert np.all(err[20:] < 0.05), err
    env.close()
    for kw in ({"kind": "mas", "system_seed": 3}, {"unknown_input": True, "system_seed": 2}):
        env = _make("random_network_v0", max_cycles=40, **kw)
        for cls in (PooledKalmanPolicy, PooledLQGPolicy):
            err = _run(env, cls(env), 20005, 40)
            assert np.all(err[15:] < 1e-3), (kw, err)
        env.close()


def test_gymnasium_centralised_view_gives_the_parallel_actions():
    import gymnasium as gym

    import dobs_envs  # noqa: F401  (registers the ids)

    genv = gym.make("dobs_envs/Tracking-v0", max_episode_steps=15)
    pol = Centralized(genv, PooledKalmanPolicy)
    assert pol.name == PooledKalmanPolicy.name
    penv = _make("tracking_v0", max_cycles=15)
    ref = PooledKalmanPolicy(penv)
    obs, _ = genv.reset(seed=20006)
    pobs, _ = penv.reset(seed=20006)
    pol.reset()
    ref.reset()
    for _ in range(15):
        a = pol(obs)
        pa = ref(pobs)
        assert genv.action_space.contains(a.astype(np.float32))
        np.testing.assert_allclose(a, np.concatenate([pa[ag] for ag in penv.possible_agents]))
        obs, _, term, trunc, _ = genv.step(a)
        pobs, *_ = penv.step(pa)
        if term or trunc:
            break
    genv.close()
    penv.close()


def test_lq_gains_solve_the_average_cost_problem():
    rng = np.random.default_rng(0)
    n, m, nxi = 4, 2, 3
    Ad = np.eye(n) + 0.05 * rng.normal(size=(n, n))
    Bd = 0.05 * rng.normal(size=(n, m))
    c, s = np.cos(0.05), np.sin(0.05)
    Phi = np.eye(nxi)
    Phi[:2, :2] = [[c, s], [-s, c]]
    Gd = 0.05 * rng.normal(size=(n, nxi))
    M = rng.normal(size=(n, nxi))
    Q, R = np.eye(n), 0.5 * np.eye(m)
    Kx, Kxi, P = lq_tracking_gains(Ad, Bd, Gd, Phi, M, Q, R)
    from scipy.linalg import solve_discrete_are

    P2 = solve_discrete_are(Ad, Bd, Q, R)
    np.testing.assert_allclose(Kx, np.linalg.solve(R + Bd.T @ P2 @ Bd, Bd.T @ P2 @ Ad), rtol=1e-10)

    def cost(Kx_, Kxi_, steps=6000):
        x, xi, J = np.zeros(n), np.array([1.0, 0.0, 0.5]), 0.0
        for _ in range(steps):
            u = -Kx_ @ x - Kxi_ @ xi
            x = Ad @ x + Bd @ u + Gd @ xi
            xi = Phi @ xi
            e = x - M @ xi
            J += e @ Q @ e + u @ R @ u
        return J

    J0 = cost(Kx, Kxi)
    for _ in range(4):
        D = rng.normal(size=Kxi.shape)
        for eps in (0.05, -0.05):
            assert cost(Kx, Kxi + eps * D / np.linalg.norm(D) * np.linalg.norm(Kxi)) > J0


def test_every_baseline_states_what_it_sees():
    env = _make("hetero_mas_v0", max_cycles=5)
    for cls in (SeparationPolicy, OraclePolicy, DecentralizedPolicy, ZeroInputPolicy, PooledKalmanPolicy,
                PooledLQGPolicy):
        assert isinstance(cls.information, str) and cls.information
    for cls in (OraclePolicy, DecentralizedPolicy, ZeroInputPolicy, PooledKalmanPolicy, PooledLQGPolicy):
        assert isinstance(cls.name, str) and cls.name
    env.close()


def test_lq_regularises_only_an_unweighted_marginal_mode():
    """hetero_mas's rendezvous cost does not weigh the mean position (a mode on the unit circle):
    Q + 1e-6 lambda_max(Q) I; tracking's Q = I needs nothing. Both closed loops are Schur."""
    for name, reg in (("hetero_mas_v0", True), ("tracking_v0", False)):
        env = _make(name, max_cycles=5)
        p = PooledLQGPolicy(env)
        assert (p.q_regularization > 0) == reg
        n = p.filter.n
        Acl = p.filter.F[:n, :n] - p.filter.G[:n] @ p.Kx
        assert np.max(np.abs(np.linalg.eigvals(Acl))) < 1 - 1e-6
        env.close()
