"""Rendezvous task (hetero_mas_v0): cost, LQR treatment of the common-position mode, closed-loop behaviour."""
import numpy as np
import pytest
import scipy.linalg as sla

from dobs_envs.design.subspaces import is_hurwitz
from dobs_envs.scenarios import ne1, rendezvous_scenario
from dobs_envs.scenarios.mas_tasks import (
    disagreement,
    mean_position,
    position_indices,
    rendezvous_cost,
    rendezvous_lqr,
    rendezvous_metrics,
    rest_norm,
)

POS = [0, 1, 2, 4, 6]


def test_positions_and_cost():
    assert position_indices(ne1()).tolist() == POS
    Q = rendezvous_cost(q_rest=0.1)
    assert np.allclose(Q, Q.T) and np.linalg.eigvalsh(Q).min() > -1e-12
    v = np.zeros(9); v[POS] = 1.0
    assert np.allclose(Q @ v, 0)  # the common position is free
    x = np.arange(9.0)
    p = x[POS]
    assert np.isclose(x @ Q @ x, np.sum((p - p.mean()) ** 2) + 0.1 * np.sum(np.delete(x, POS) ** 2))
    assert np.linalg.matrix_rank(Q) == 8


def test_care_with_Q_alone_has_no_stabilising_solution():
    """The reason for rho: (Q, A) is not detectable (common-position integrator), so the
    Hamiltonian has imaginary-axis eigenvalues and no CARE solution is stabilising."""
    sc = ne1()
    Q = rendezvous_cost()
    H = np.block([[sc.A, -sc.B @ sc.B.T], [-Q, -sc.A.T]])
    assert np.min(np.abs(np.linalg.eigvals(H).real)) < 1e-6
    try:  # scipy may still return a (non-stabilising) solution silently
        X = sla.solve_continuous_are(sc.A, sc.B, Q, np.eye(5))
    except (ValueError, np.linalg.LinAlgError):
        return
    assert not is_hurwitz(sc.A - sc.B @ sc.B.T @ X)


def test_lqr_rho_positive_is_stabilising_with_one_slow_mode():
    sc = rendezvous_scenario()  # rho = 1e-3
    X, K = rendezvous_lqr(rho=1e-3)
    assert np.array_equal(K, sc.K)
    Acl = sc.A + sc.B @ K
    Qr = sc.Q + 1e-3 * np.outer(np.isin(np.arange(9), POS), np.isin(np.arange(9), POS)) / 5
    res = sc.A.T @ X + X @ sc.A - X @ sc.B @ sc.B.T @ X + Qr
    assert np.abs(res).max() < 1e-9
    ev = np.linalg.eigvals(Acl)
    ev = ev[np.argsort(-ev.real)]
    assert is_hurwitz(Acl)
    assert abs(ev[0].imag) < 1e-12 and -0.06 < ev[0].real < -0.04  # ~ -1.47 sqrt(rho)
    assert ev[1].real < -0.5  # every other mode is >10x faster
    # the slow mode is (to O(sqrt(rho))) the common position at rest
    w = np.linalg.eig(Acl)[1][:, np.argmax(np.linalg.eigvals(Acl).real)].real
    v = np.zeros(9); v[POS] = 1.0
    assert abs(w @ v) / (np.linalg.norm(w) * np.linalg.norm(v)) > 0.99


def test_lqr_rho_zero_disagreement_coordinates():
    X, K = rendezvous_lqr(rho=0.0)
    sc = ne1()
    v = np.zeros(9); v[POS] = 1.0
    assert np.allclose(K @ v, 0, atol=1e-12) and np.allclose(X @ v, 0, atol=1e-12)
    ev = np.sort_complex(np.linalg.eigvals(sc.A + sc.B @ K))
    zero = np.abs(ev) < 1e-9
    assert zero.sum() == 1 and np.all(ev[~zero].real < -0.5)  # {0} U Hurwitz
    # rho -> 0 limit: the rho > 0 spectra approach this one, the slow eigenvalue like sqrt(rho)
    slow = []
    for rho in (1e-2, 1e-4, 1e-6):
        e = np.linalg.eigvals(sc.A + sc.B @ rendezvous_lqr(rho=rho)[1])
        slow.append(-e.real.max())
        assert np.allclose(np.sort_complex(e[np.argsort(-e.real)][1:]), ev[~zero], atol=5 * np.sqrt(rho))
    assert np.allclose(np.array(slow) / np.sqrt([1e-2, 1e-4, 1e-6]), 1.47, rtol=0.05)
    # x0' X x0 is the optimal cost of the environments' objective (disagreement + q_rest, R = I)
    x0 = rendezvous_scenario().x0
    # (Acl v = 0 and (Q + K'K) v = 0, so the cost lives on xi = W^T x with W^T v = 0)
    Acl = sc.A + sc.B @ K
    Wb = sla.null_space(v[None, :])
    Axi = Wb.T @ Acl @ Wb
    assert is_hurwitz(Axi)
    P = sla.solve_continuous_lyapunov(Axi.T, -(Wb.T @ (rendezvous_cost() + K.T @ K) @ Wb))
    assert np.isclose(x0 @ Wb @ P @ Wb.T @ x0, x0 @ X @ x0, rtol=1e-8)


@pytest.mark.parametrize("rho, final", [(1e-3, 1e-3), (0.0, 1e-6)])
def test_full_state_lqr_disagreement_decays(rho, final):
    sc = rendezvous_scenario(rho=rho)
    Acl = sc.A + sc.B @ sc.K
    ts = np.linspace(0.0, 30.0, 31)
    xs = np.array([sla.expm(Acl * t) @ sc.x0 for t in ts])
    d = disagreement(xs, sc)
    assert d[0] > 6 and d[-1] / d[0] < final
    assert rest_norm(xs[-1], sc) < 0.1
    m = rendezvous_metrics(xs, sc)
    assert m["disagreement"].shape == (31,) and np.allclose(m["cost_rate"], np.einsum("ti,ij,tj->t", xs, sc.Q, xs))
    if rho == 0.0:  # the agents meet where the common mode put them; it does not drift
        assert abs(mean_position(xs[-1], sc) - mean_position(xs[-5], sc)) < 1e-6


def test_scenario_fields():
    sc = rendezvous_scenario()
    assert sc.controller == "feedback" and sc.mas_agents is not None
    assert sc.known == tuple((i,) for i in range(5)) and sc.links == tuple(range(5))
    assert np.array_equal(sc.x0, ne1().x0) and sc.graph == ne1().graph
    assert np.array_equal(sc.Q, rendezvous_cost()) and np.array_equal(sc.R, np.eye(5))
    assert sc.metadata["positions"] == POS and sc.metadata["rho"] == 1e-3
    assert disagreement(sc.x0, POS) == pytest.approx(disagreement(sc.x0, sc))
    d = sc.design  # MAS observer (obidynamicMAS)
    assert d.E_bar.shape == (5, 9, 9)
    with pytest.raises(ValueError, match="x0"):
        rendezvous_scenario(agents=ne1().mas_agents[:3])


_OK = (np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)))
_DBL = np.array([[0.0, 1.0], [0.0, 0.0]])


@pytest.mark.parametrize("agent, message, composes", [
    ((_DBL, np.ones((3, 1)), np.array([[1.0, 0.0]])), r"agents\[1\]: B must have 2 rows and C 2 columns, got B of shape \(3, 1\)", True),
    ((_DBL, np.array([[0.0], [1.0]]), np.ones((1, 3))), r"agents\[1\]: B must have 2 rows and C 2 columns, got B of shape \(2, 1\) and C of shape \(1, 3\)", True),
    ((np.array([[np.nan, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])), r"agents\[1\]\.A contains NaN or inf", False),
    ((np.zeros((2, 3)), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])), r"agents\[1\]\.A must be square \(n_i, n_i\), got shape \(2, 3\)", False),
    ((_DBL, np.array([[0.0], [np.inf]]), np.array([[1.0, 0.0]])), r"agents\[1\]\.B contains NaN or inf", False),
    ((_DBL, np.array([[0.0], [1.0]]), np.array([[1.0, 1j]])), r"agents\[1\]\.C must be real", False),
])
def test_bad_agents_are_named_as_the_caller_passed_them(agent, message, composes):
    """The rendezvous functions take ``agents``: their errors say ``agents[i]`` (not the Scenario/file key ``mas_agents``)."""
    agents = [_OK, agent]
    calls = [lambda: rendezvous_scenario(agents=agents, x0=np.zeros(3)), lambda: rendezvous_lqr(agents)]
    if not composes:  # block-by-block checks: every entry point refuses them by the same name
        calls += [lambda: rendezvous_cost(agents), lambda: position_indices(agents)]
    for call in calls:
        with pytest.raises(ValueError, match="^" + message) as ei:
            call()
        assert "mas_agents" not in str(ei.value)


def test_rho_zero_requires_equilibrium_common_mode():
    agents = [(np.array([[0.5]]), np.array([[1.0]]), np.array([[1.0]]))] * 2
    with pytest.raises(ValueError, match="rho > 0"):
        rendezvous_lqr(agents, rho=0.0)
    X, K = rendezvous_lqr(agents, rho=0.1)
    assert is_hurwitz(np.diag([0.5, 0.5]) + K)


def test_observer_based_rendezvous_short_run():
    """u_i = K_i xhat_i through the distributed observer: disagreement still shrinks (Theorem lfthm)."""
    from dobs_envs.reproduce import simulate

    sc = rendezvous_scenario()
    tr = simulate(sc, t_end=8.0, dt=2e-3)
    d = disagreement(tr.x, sc)
    assert d[-1] < 0.05 * d[0]
    assert tr.est_err[-1].max() < 0.05 * tr.est_err[0].max()
