"""The compiled faulted control period against its numpy reference (issue 23, phase 2).

:func:`~dobs_envs.sim.period_kernel.control_period_faulted_compiled` must do what
:func:`~dobs_envs.sim.numpy_step.control_period_faulted_numpy` specifies: every discrete quantity
(period counter, active graph, burst states, measurement noise, the period's deliveries, the C-O
bookkeeping) bitwise, the continuous state to the rounding of the two ways of summing (the same
1e-10 relative tolerance as the unfaulted kernel's parity test, ``tests/test_sim_core.py``: sparse
sums in column order with FMA contraction against numpy's einsum; measured: 1.2e-15 relative over 6 periods on NE2).
"""
from __future__ import annotations

import numpy as np
import pytest

from dobs_envs.scenarios.paper import ne2
from dobs_envs.sim import fault_rng, fault_state as fstate
from dobs_envs.sim.fault_kernel import co_link_compiled
from dobs_envs.sim.period_kernel import control_period_faulted_compiled
from dobs_envs.sim.fault_state import FaultState, co_link_numpy, fault_args, faulted_estimates, init_fault_state
from dobs_envs.sim.faults import Faults
from dobs_envs.sim.numpy_step import control_period_faulted_numpy
from dobs_envs.sim.state import SimParams

from test_faults_engine import _ne2, _random_network
from test_sim_core import _random_design

RTOL = 1e-10
DISCRETE = ("seed", "period", "bad", "graph", "noise")

RING = ne2().graph.adjacency
CUT = RING.copy()
CUT[0, 1] = CUT[1, 0] = CUT[3, 4] = CUT[4, 3] = 0.0

#: one setting per fault kind, and everything at once (NE2: 6 nodes)
CASES = {
    "ideal": dict(),
    "sampled": dict(oo_period=0.01),
    "drifting": dict(oo_period=0.03, oo_delay=2),  # 30 Euler steps: broadcasts drift across periods
    "loss": dict(oo_loss=0.3),
    "burst": dict(oo_burst={"p_good_bad": 0.2, "p_bad_good": 0.3, "loss_good": 0.05, "loss_bad": 0.9}),
    "delay": dict(oo_delay=3),
    "noise": dict(measurement_noise=0.05),
    "switching": dict(switching={"graphs": [RING, np.zeros((6, 6)), CUT],
                                 "transition": [[0.6, 0.2, 0.2], [0.3, 0.4, 0.3], [0.3, 0.3, 0.4]]}),
    "all": dict(oo_period=0.005, oo_loss=0.2, oo_delay=1, co_loss=0.3, co_delay=2, measurement_noise=0.05,
                switching={"graphs": [RING, CUT], "rate": 3.0}),
}


def _close(name, a, b):
    scale = max(1.0, float(np.abs(a).max(initial=0.0)))
    np.testing.assert_allclose(b, a, rtol=0, atol=RTOL * scale, err_msg=name)


def _compare(prm, state, faults, periods, seeds, u, r):
    fa = fault_args(faults, prm)
    fs0 = init_fault_state(prm, fa, state[0], state[1], seeds)
    a = b = state
    fa_, fb = fs0, fs0
    E = fa.sender.shape[0]
    for k in range(periods):
        lost = fstate.oo_losses(fa, fa_)
        want_delivered = (fa.weight[fa_.graph] > 0) & ~lost
        *a, fa_ = control_period_faulted_numpy(*a, u, r, prm, fa, fa_)
        delivered = np.zeros((state[0].shape[0], E), dtype=bool)
        *b, fb = control_period_faulted_compiled(*b, u, r, prm, fa, fb, delivered=delivered)
        np.testing.assert_array_equal(delivered, want_delivered, err_msg=f"deliveries, period {k}")
        for name in DISCRETE:
            np.testing.assert_array_equal(getattr(fb, name), getattr(fa_, name), err_msg=f"{name}, period {k}")
        for name, va, vb in zip(("x", "z", "gamma", "gamma_s", "v", "x_r"), a, b):
            _close(f"{name}, period {k}", va, vb)
        _close(f"received, period {k}", fa_.received, fb.received)
        _close(f"snapshots, period {k}", fa_.snapshots, fb.snapshots)
    return a, b, fa_, fb


@pytest.mark.parametrize("case", list(CASES))
def test_compiled_matches_numpy_on_ne2(case):
    prm, state, rng = _ne2(B=3, seed=1)
    u = 0.3 * rng.normal(size=(3, prm.n_inputs))
    r = rng.normal(size=(3, prm.n_inputs))
    a, b, fa_, _ = _compare(prm, state, Faults.from_value(CASES[case]), 6, [5, 6, 2**63 + 7], u, r)
    assert np.all(fa_.period == 6)
    assert all(np.all(np.isfinite(x)) for x in b)


@pytest.mark.parametrize("case", ["ideal", "loss", "all_random"])
def test_compiled_matches_numpy_on_a_random_network(case):
    prm, state, rng = _random_network(B=3, seed=2)
    N = prm.n_nodes
    if case == "all_random":
        adj = np.array(-prm.laplacian)
        np.fill_diagonal(adj, 0.0)
        f = Faults(oo_period=0.002, oo_loss=0.25, oo_delay=2, measurement_noise=0.02,
                   switching={"graphs": [adj, np.zeros((N, N))], "rate": 5.0})
    else:
        f = Faults.from_value(CASES[case])
    u = 0.3 * rng.normal(size=(3, prm.n_inputs))
    r = rng.normal(size=(3, prm.n_inputs))
    _compare(prm, state, f, 5, [1, 2, 3], u, r)


def test_compiled_matches_numpy_in_split_steps():
    """Large gains and states split the Euler steps: the continuous exchange refreshes the held copies in
    the shortened steps, a sampled one (``oo_period = dt``) does not -- both as the reference."""
    rng = np.random.default_rng(2)
    d = _random_design(rng)
    prm = SimParams.from_design(d, dt=1e-3, substeps=20, phi=0.3, phi_s=0.7)
    s = prm.initial_state(300.0 * rng.normal(size=(3, 5)), z0=rng.normal(size=(3, 4, 5)), gamma0=400.0)
    assert np.any(2 * np.diagonal(prm.laplacian) * prm.dt * s.gamma > 1.0), "the case must split Euler steps"
    u = rng.normal(size=(3, 3))
    r = np.zeros((3, 3))
    state = (s.x, s.z, s.gamma, s.gamma_s, s.v, s.x_r)
    for f in (Faults(), Faults(oo_period=prm.dt), Faults(oo_loss=0.5, measurement_noise=0.1)):
        _compare(prm, state, f, 3, [4, 5, 6], u, r)
    # in a tile (8 copies, half of them splitting: flagged lanes are recomputed copy by copy)
    s8 = prm.initial_state(np.concatenate([300.0 * rng.normal(size=(4, 5)), rng.normal(size=(4, 5))]),
                           z0=rng.normal(size=(8, 4, 5)), gamma0=np.repeat([400.0, 0.1], 4)[:, None])
    u8 = rng.normal(size=(8, 3))
    state8 = (s8.x, s8.z, s8.gamma, s8.gamma_s, s8.v, s8.x_r)
    for f in (Faults(oo_loss=0.5, measurement_noise=0.1), Faults(oo_period=0.002, oo_delay=1)):
        _compare(prm, state8, f, 3, np.arange(8), u8, np.zeros((8, 3)))


def test_batch_independence_bitwise():
    """Copy ``c`` of a batch equals the same copy advanced alone with its seed, bit for bit."""
    prm, state, rng = _ne2(B=4, seed=3)
    u = 0.3 * rng.normal(size=(4, prm.n_inputs))
    r = rng.normal(size=(4, prm.n_inputs))
    fa = fault_args(Faults.from_value(CASES["all"]), prm)
    seeds = [11, 12, 13, 14]
    fs = init_fault_state(prm, fa, state[0], state[1], seeds)
    full = state
    for _ in range(4):
        *full, fs = control_period_faulted_compiled(*full, u, r, prm, fa, fs)
    c = 2
    one = tuple(a[c:c + 1] for a in state)
    fs1 = init_fault_state(prm, fa, one[0], one[1], seeds[c:c + 1])
    for _ in range(4):
        *one, fs1 = control_period_faulted_compiled(*one, u[c:c + 1], r[c:c + 1], prm, fa, fs1)
    for a, b in zip(tuple(one) + tuple(fs1), tuple(full) + tuple(fs)):
        np.testing.assert_array_equal(a[0], b[c])


def test_inputs_are_not_modified():
    prm, state, rng = _ne2(B=2)
    fa = fault_args(Faults(oo_loss=0.5, measurement_noise=0.1), prm)
    fs = init_fault_state(prm, fa, state[0], state[1], [1, 2])
    before = [a.copy() for a in state] + [a.copy() for a in fs]
    u = np.zeros((2, prm.n_inputs))
    control_period_faulted_compiled(*state, u, u, prm, fa, fs)
    for a, b in zip(before, list(state) + list(fs)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("faults", [dict(co_delay=3), dict(co_loss=0.4), dict(co_loss=0.3, co_delay=2,
                                                                                    measurement_noise=0.1)])
def test_co_link_matches_numpy(faults):
    """The compiled C-O link is bitwise the reference (it only copies and draws): over 12 boundaries with
    identifiable sent values, and through the receiver mask."""
    prm, state, rng = _ne2(B=3)
    fa = fault_args(Faults(**faults), prm)
    co_nodes = np.array([0, 1, 2, 3, 4])
    fs_a = fs_b = init_fault_state(prm, fa, state[0], state[1], [3, 4, 5], co_nodes=co_nodes)
    n_lost = 0
    for k in range(12):
        xhat = rng.normal(size=(3, prm.n_nodes, prm.n_states))
        held_a, fs_a = co_link_numpy(xhat[:, co_nodes], fs_a, fa)
        held_b, fs_b, received = co_link_compiled(xhat, co_nodes, fs_b, fa)
        np.testing.assert_array_equal(held_b, held_a)
        np.testing.assert_array_equal(fs_b.co_sent, fs_a.co_sent)
        lost = fault_rng.uniform(np.array([3, 4, 5])[:, None], fault_rng.STREAM_CO_LOSS, k,
                                 np.arange(5)[None, :]) < fa.co_loss
        np.testing.assert_array_equal(received, ~lost)
        n_lost += int(lost.sum())
        fs_a = fs_a.replace(period=fs_a.period + 1)
        fs_b = fs_b.replace(period=fs_b.period + 1)
    assert (n_lost > 0) == (fa.co_loss > 0)


@pytest.mark.parametrize("case", ["all", "burst", "switching", "noise", "ideal"])
def test_period_draws_compiled_match_numpy(case):
    """The compiled period draws (the environments' resets; the kernels' next-period draws) are bitwise
    :func:`~dobs_envs.sim.fault_state.period_draws`: the first period (initial graph, stationary burst
    states) and later ones (chain steps from given graphs and burst states), noise included."""
    from dobs_envs.sim.fault_kernel import period_draws_compiled

    prm, state, rng = _ne2(B=2)
    fa = fault_args(Faults.from_value(CASES[case]), prm)
    B, E, G = 200, fa.sender.shape[0], fa.weight.shape[0]
    seeds = np.concatenate([np.arange(100, dtype=np.uint64), rng.integers(0, 2**64, 100, dtype=np.uint64)])
    for period in (np.zeros(B, dtype=np.int64), rng.integers(1, 1000, B)):
        graph_prev = rng.integers(0, G, B)
        bad_prev = rng.random((B, E)) < 0.5
        want = fstate.period_draws(fa, seeds, period, graph_prev, bad_prev)
        got = period_draws_compiled(fa, seeds, period, graph_prev, bad_prev)
        for name, w, g in zip(("graph", "bad", "noise"), want, got):
            assert g.dtype == np.asarray(w).dtype and g.shape == np.shape(w), name
            np.testing.assert_array_equal(g, w, err_msg=name)
    st = init_fault_state(prm, fa, state[0], state[1], [3, 2**63 + 1], draws=period_draws_compiled)
    for a, b in zip(st, init_fault_state(prm, fa, state[0], state[1], [3, 2**63 + 1])):
        np.testing.assert_array_equal(a, b)


def test_fault_state_tuple_order():
    """Compiled code receives the fault state as a plain tuple in declaration order and names it
    (``FaultState(*fs)``): the order the Python side passes (``tuple(fs)``) is the declaration's."""
    from dobs_envs.sim.fault_kernel import FAULT_STATE_FIELDS

    assert FAULT_STATE_FIELDS == ("seed", "period", "received", "snapshots", "bad", "graph", "noise", "co_sent",
                                  "co_held") == FaultState._fields


@pytest.mark.parametrize("case", ["all", "delay", "burst", "switching"])
def test_tiles_are_bitwise_the_per_copy_path(case):
    """Tiles (140 copies: one of 128 and a remainder of 12, both SIMD) give every copy bitwise what it gets
    advanced alone (the per-copy path), and match the numpy reference (8 copies: one tile of 8)."""
    prm, state, rng = _ne2(B=140, seed=4)
    u = 0.3 * rng.normal(size=(140, prm.n_inputs))
    r = rng.normal(size=(140, prm.n_inputs))
    fa = fault_args(Faults.from_value(CASES[case]), prm)
    seeds = np.arange(1000, 1140)
    fs = init_fault_state(prm, fa, state[0], state[1], seeds)
    full = state
    for _ in range(3):
        *full, fs = control_period_faulted_compiled(*full, u, r, prm, fa, fs)
    for c in (0, 77, 127, 128, 139):
        one = tuple(a[c:c + 1] for a in state)
        fs1 = init_fault_state(prm, fa, one[0], one[1], seeds[c:c + 1])
        for _ in range(3):
            *one, fs1 = control_period_faulted_compiled(*one, u[c:c + 1], r[c:c + 1], prm, fa, fs1)
        for name, a, b in zip(("x", "z", "gamma", "gamma_s", "v", "x_r") + FaultState._fields,
                              tuple(one) + tuple(fs1), tuple(full) + tuple(fs)):
            np.testing.assert_array_equal(a[0], b[c], err_msg=f"{name}, copy {c}")
    sub = tuple(a[:8] for a in state)
    _compare(prm, sub, Faults.from_value(CASES[case]), 3, seeds[:8], u[:8], r[:8])
