"""Simulation core: compiled kernel vs numpy reference, purity, Euler-structure identities."""
from types import SimpleNamespace

import numpy as np
import pytest

from dobs_envs.sim import SimParams, estimates, step_env
from dobs_envs.sim.period_kernel import HAVE_NUMBA


def _random_design(rng, N=4, n=5, p=2, m=3, mv=2):
    P = np.zeros((N, n, n))
    for i in range(N):
        Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        k = int(rng.integers(1, n))
        P[i] = Q[:, :k] @ Q[:, :k].T
    adj = (rng.random((N, N)) < 0.6).astype(float)
    adj = np.triu(adj, 1)
    adj = adj + adj.T
    return SimpleNamespace(
        A=rng.normal(size=(n, n)) * 0.3, B=rng.normal(size=(n, m)), B_v=rng.normal(size=(n, mv)),
        C=rng.normal(size=(N, p, n)), E_bar=rng.normal(size=(N, n, n)) * 0.3,
        F_bar=rng.normal(size=(N, n, p)), G_bar=rng.normal(size=(N, n, p)),
        B_bar=rng.normal(size=(N, n, m)), P_u=P, adjacency=adj,
    )


def test_numba_is_installed():
    """numba is a dependency: without it the compiled paths fall back to numpy and the parity
    tests below would compare numpy with itself; fail instead of skipping."""
    assert HAVE_NUMBA


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_matches_numpy(seed):
    rng = np.random.default_rng(seed)
    d = _random_design(rng)
    prm = SimParams.from_design(d, dt=1e-3, substeps=37, exosystem=np.array([[0, 0.5], [-0.5, 0]]),
                                K_ref=rng.normal(size=(3, 5)) * 0.1, sigma=0.1, sigma_s=0.05, phi=0.3, phi_s=0.7)
    s = prm.initial_state(rng.normal(size=(3, 5)), z0=rng.normal(size=(3, 4, 5)), v0=[-2, 2],
                          x_r0=rng.normal(size=(3, 5)))
    u = rng.normal(size=(3, 3))
    r = rng.normal(size=(3, 3))
    a = s
    b = s
    for _ in range(5):
        a = step_env(a, u, prm, r, backend="numba")
        b = step_env(b, u, prm, r, backend="numpy")
    for f in ("t", "x", "z", "gamma", "gamma_s", "v", "x_r"):
        va, vb = getattr(a, f), getattr(b, f)
        # same operations, different summation order (fastmath reassociation):
        # relative agreement at the level of accumulated round-off over 185 steps
        np.testing.assert_allclose(va, vb, rtol=1e-10, atol=1e-10 * max(1.0, np.abs(vb).max()), err_msg=f)


def test_step_is_pure_and_validates():
    rng = np.random.default_rng(3)
    d = _random_design(rng)
    prm = SimParams.from_design(d, substeps=3)
    s = prm.initial_state(rng.normal(size=(2, 5)))
    x_before = s.x.copy()
    u = np.zeros((2, 3))
    s2 = step_env(s, u, prm)
    np.testing.assert_array_equal(s.x, x_before)
    assert s2 is not s and not np.shares_memory(s2.x, s.x)
    assert np.allclose(s2.t, 3e-3)
    with pytest.raises(ValueError, match=r"u must have shape \(2, 3\)"):
        step_env(s, np.zeros((2, 4)), prm)
    with pytest.raises(ValueError, match="NaN"):
        step_env(s, np.full((2, 3), np.nan), prm)
    with pytest.raises(ValueError, match="backend"):
        step_env(s, u, prm, backend="jax")


def test_params_validation():
    rng = np.random.default_rng(4)
    d = _random_design(rng)
    with pytest.raises(ValueError, match="phi must be"):
        SimParams.from_design(d, phi=[1.0, 2.0])
    with pytest.raises(ValueError, match="substeps"):
        SimParams.from_design(d, substeps=0)
    with pytest.raises(ValueError, match="exosystem"):
        SimParams.from_design(d, exosystem=np.eye(3))
    prm = SimParams.from_design(d)
    with pytest.raises(ValueError, match="x0"):
        prm.initial_state(np.zeros(4))


def test_exosystem_is_exact():
    rng = np.random.default_rng(5)
    d = _random_design(rng)
    S = np.array([[0.0, 0.5], [-0.5, 0.0]])
    prm = SimParams.from_design(d, dt=1e-2, substeps=100, exosystem=S)
    s = prm.initial_state(np.zeros((1, 5)), v0=[-2.0, 2.0])
    s = step_env(s, np.zeros((1, 3)), prm)
    t = 1.0
    expected = np.array([-2 * np.cos(0.5 * t) + 2 * np.sin(0.5 * t), 2 * np.sin(0.5 * t) + 2 * np.cos(0.5 * t)])
    np.testing.assert_allclose(s.v[0], expected, atol=1e-12)


def test_estimates_definition():
    rng = np.random.default_rng(6)
    d = _random_design(rng)
    prm = SimParams.from_design(d)
    s = prm.initial_state(rng.normal(size=(2, 5)), z0=rng.normal(size=(2, 4, 5)))
    xh = estimates(s, prm)
    i = 2
    expected = s.z[1, i] + d.G_bar[i] @ (d.C[i] @ s.x[1])
    np.testing.assert_allclose(xh[1, i], expected, atol=1e-12)


def test_kernel_args_built_once_and_follow_the_timing():
    from dobs_envs.sim import KernelArgs

    rng = np.random.default_rng(5)
    prm = SimParams.from_design(_random_design(rng), dt=1e-3, substeps=7)
    ka = prm.kernel_args
    assert isinstance(ka, KernelArgs) and prm.kernel_args is ka  # cached
    assert prm.kernel_tuple == tuple(ka) and prm.kernel_tuple is prm.kernel_tuple
    assert ka.A is prm.A and ka.degree is prm.degree and (ka.dt, ka.substeps) == (1e-3, 7)
    p2 = prm.with_timing(dt=2e-3, substeps=3)
    assert (p2.kernel_args.dt, p2.kernel_args.substeps) == (2e-3, 3)
    np.testing.assert_array_equal(p2.kernel_args.Phi_v, p2.Phi_v)
