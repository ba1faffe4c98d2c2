"""Observer design: eqs. (barEFGB), (TidTiu), (obidynamicMAS), Assumptions 5/6 at the boundary."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dobs_envs.assumptions import (
    CollectiveDetectabilityError,
    DetectabilityError,
    GraphNotConnectedError,
)
from dobs_envs.design import (
    ObserverDesign,
    design_distributed_observer,
    design_mas_observer,
    observer_residuals,
    strong_detectability,
)
from dobs_envs.design.subspaces import projector_distance
from dobs_envs.graphs import Graph, path_graph, random_connected_graph, ring_graph

import paper_ne2 as NE2  # the tests' transcription of NE2 (tests/paper_ne2.py)

# Round-off bound for identities built from O(n) products of O(1) orthonormal /
# well-scaled factors (n <= 12 here): ~n * eps * (norms ~ 10) -> 1e-12 is safe.
ATOL = 1e-10


# ------------------------------------------------------------------ paper systems
def ne2():
    """NE2 (tests/paper_ne2.py): A, channels, outputs, the channel each node knows (as lists)."""
    return NE2.A(), NE2.channels(), NE2.outputs(), [[k] for k in NE2.KNOWN]


def ne1_agents():
    dint = np.array([[0.0, 1.0], [0.0, 0.0]])
    tint = np.diag([1.0, 1.0], 1)
    return [
        (np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1))),
        (np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1))),
        (dint, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])),
        (dint, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])),
        (tint, np.array([[0.0], [0.0], [1.0]]), np.array([[1.0, 0.0, 0.0]])),
    ]


# ------------------------------------------------------------------ generic checks
def check_structure(d: ObserverDesign):
    N, n, m = d.n_nodes, d.n_states, d.n_inputs
    p = int(d.p_i.max())
    assert d.A.shape == (n, n) and d.B.shape == (n, m)
    assert d.C.shape == (N, p, n)
    for name, shape in [
        ("E_bar", (N, n, n)), ("F_bar", (N, n, p)), ("G_bar", (N, n, p)),
        ("B_bar", (N, n, m)), ("P_u", (N, n, n)), ("P_d", (N, n, n)), ("known", (N, m)),
    ]:
        arr = getattr(d, name)
        assert arr.shape == shape, name
        assert not arr.flags.writeable, name
    assert d.adjacency.shape == (N, N)
    assert sum(sl.stop - sl.start for sl in d.channel_slices) == m
    I = np.eye(n)
    for i in range(N):
        Td, Tu = d.T_d[i], d.T_u[i]
        delta = Td.shape[1]
        assert Tu.shape == (n, n - delta)
        # eq. (TidTiu)
        np.testing.assert_allclose(Td.T @ Td, np.eye(delta), atol=ATOL)
        np.testing.assert_allclose(Td.T @ Tu, 0.0, atol=ATOL)
        np.testing.assert_allclose(Tu.T @ Tu, np.eye(n - delta), atol=ATOL)
        np.testing.assert_allclose(Tu @ Tu.T, I - Td @ Td.T, atol=ATOL)
        np.testing.assert_allclose(d.P_u[i], Tu @ Tu.T, atol=ATOL)
        np.testing.assert_allclose(d.P_u[i] + d.P_d[i], I, atol=ATOL)
        # padding rows / columns are zero
        pi = d.p_i[i]
        assert np.all(d.C[i, pi:] == 0) and np.all(d.F_bar[i, :, pi:] == 0)
        assert np.all(d.G_bar[i, :, pi:] == 0)
        # Bbar zero on unknown columns, (I - Gbar C) B on known ones (eq. barB_i)
        unk = ~d.known[i]
        assert np.all(d.B_bar[i][:, unk] == 0)
        Ci = d.C_node(i)
        Gb = d.G_bar[i, :, :pi]
        np.testing.assert_allclose(
            d.B_bar[i][:, d.known[i]], (I - Gb @ Ci) @ d.B[:, d.known[i]], atol=ATOL
        )
        # eq. (barEFGB), recomputed naively from the local quadruplet
        E, F, G = d.E[i], d.F[i], d.G[i]
        np.testing.assert_allclose(Gb, Td @ G, atol=ATOL)
        np.testing.assert_allclose(d.E_bar[i], Td @ E @ Td.T + Tu @ Tu.T @ d.A, atol=ATOL)
        np.testing.assert_allclose(d.F_bar[i, :, :pi], Td @ F + Tu @ Tu.T @ d.A @ Gb, atol=ATOL)
    # Lemma 2 equations hold per node
    assert observer_residuals(d).max() < 1e-10


def check_error_dynamics(d: ObserverDesign, seed=0):
    """Uncoupled node error ``e = xhat - x`` of eq. (obidynamic) with the gains of (barEFGB):

    ``T_id^T e' = E_i T_id^T e``  (whatever u_{-i}) and
    ``T_iu^T e' = T_iu^T (A e - B_{-i} u_{-i})``  (proof of Theorem 1).
    """
    rng = np.random.default_rng(seed)
    n, m = d.n_states, d.n_inputs
    for i in range(d.n_nodes):
        x, xhat = rng.standard_normal(n), rng.standard_normal(n)
        u = rng.standard_normal(m)
        v = rng.standard_normal(d.B_v.shape[1])
        pi = d.p_i[i]
        Ci = d.C_node(i)
        Gb, Fb = d.G_bar[i, :, :pi], d.F_bar[i, :, :pi]
        y = Ci @ x
        xdot = d.A @ x + d.B @ u + d.B_v @ v
        z = xhat - Gb @ y
        zdot = d.E_bar[i] @ z + Fb @ y + d.B_bar[i] @ u
        edot = zdot + Gb @ (Ci @ xdot) - xdot
        e = xhat - x
        Td, Tu = d.T_d[i], d.T_u[i]
        u_unknown = np.concatenate([u[~d.known[i]], v])
        scale = 1.0 + np.abs(edot).max()
        np.testing.assert_allclose(Td.T @ edot, d.E[i] @ (Td.T @ e), atol=1e-10 * scale)
        np.testing.assert_allclose(
            Tu.T @ edot, Tu.T @ (d.A @ e - d.B_unknown(i) @ u_unknown), atol=1e-10 * scale
        )


# ------------------------------------------------------------------ NE2 / NE3
def test_ne2_design_matches_paper():
    A, chans, C, known = ne2()
    d = design_distributed_observer(A, chans, C, known, ring_graph(6))
    assert d.n_nodes == 6 and d.n_states == 9 and d.n_inputs == 5
    assert d.delta.tolist() == [1, 3, 2, 3, 1, 1]
    for i in range(NE2.N_NODES):
        T = NE2.t_d(i)
        assert projector_distance(d.T_d[i], T) < 1e-8, f"node {i}"
    assert len(d.lemma2) == 6
    check_structure(d)
    check_error_dynamics(d)
    # known channels: node 5 (paper's 6) knows channel 4 (paper's B^5)
    assert d.known[5].tolist() == [False, False, False, False, True]


def test_ne3_design_with_unknown_input():
    A, chans, C, known = ne2()
    B_v = NE2.b_v()  # B_v = [B^1 B^2]
    d = design_distributed_observer(A, chans, C, known, ring_graph(6), B_v=B_v)
    assert d.B_v.shape == (9, 2)
    for i in range(NE2.N_NODES):  # printed T_2d = e_3 of NE3, the others as NE2
        assert projector_distance(d.T_d[i], NE2.t_d(i, ne3=True)) < 1e-8, f"node {i}"
    check_structure(d)
    check_error_dynamics(d, seed=1)
    for i in range(6):
        assert d.B_unknown(i).shape[1] == 4 + 2  # 4 unknown channels + B_v


def test_assumption6_failure_through_design():
    A, chans, C, known = ne2()
    # drop the paper's node 5 (measures x_2): nobody reconstructs x_2 any more
    keep = [0, 1, 2, 3, 5]
    with pytest.raises(CollectiveDetectabilityError, match="Assumption 6") as ei:
        design_distributed_observer(
            A, chans, [C[k] for k in keep], [known[k] for k in keep], ring_graph(5)
        )
    e = ei.value
    assert e.dimension == 8 and e.n == 9
    assert e.missing_directions.shape == (9, 1)
    assert projector_distance(e.missing_directions, np.eye(9)[:, [1]]) < 1e-8


def test_assumption6_failure_unobservable_unstable_mode():
    A = np.diag([0.0, 1.0])
    with pytest.raises(CollectiveDetectabilityError) as ei:
        design_distributed_observer(A, [], [[1.0, 0.0], [1.0, 0.0]], [[], []], path_graph(2))
    assert projector_distance(ei.value.missing_directions, np.array([[0.0], [1.0]])) < 1e-12


def test_unconnected_graph_raises():
    A, chans, C, known = ne2()
    g = Graph.from_edges(6, [(0, 1), (1, 2), (3, 4), (4, 5)])
    with pytest.raises(GraphNotConnectedError, match="Assumption 5") as ei:
        design_distributed_observer(A, chans, C, known, g)
    assert ei.value.components == [[0, 1, 2], [3, 4, 5]]
    with pytest.raises(GraphNotConnectedError):
        design_distributed_observer(A, chans, C, known, np.asarray(g.adjacency))


def test_inputs_not_mutated_and_copied():
    A, chans, C, known = ne2()
    A0 = A.copy()
    chans0 = [c.copy() for c in chans]
    d = design_distributed_observer(A, chans, C, known, ring_graph(6))
    np.testing.assert_array_equal(A, A0)
    for c, c0 in zip(chans, chans0):
        np.testing.assert_array_equal(c, c0)
    A[0, 0] = 99.0
    assert d.A[0, 0] == 0.0
    with pytest.raises(ValueError):
        d.E_bar[0, 0, 0] = 1.0


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(A=np.zeros((9, 8))), "A must be a non-empty square"),
        (dict(channels=[np.zeros((8, 1))]), r"channels\[0\] must have shape \(9, \*\)"),
        (dict(C=[np.eye(9)[[0]], np.zeros((1, 8))]), r"C\[1\] \(node 1\) must have shape"),
        (dict(C=[np.eye(9)[[0, 0]]]), r"C\[0\] \(node 0\) must have full row rank"),
        (dict(known=[[0], [7], [2], [3], [4], [4]]), r"known\[1\] contains channel 7"),
        (dict(known=[[0]] * 5), "one entry per node"),
        (dict(graph=ring_graph(5)), "graph has 5 nodes but 6"),
        (dict(B_v=np.zeros((3, 1))), "B_v must have shape"),
        (dict(graph=np.array([[0.0, 1.0], [0.0, 0.0]])), "graph: .*symmetric"),
    ],
)
def test_boundary_validation(kwargs, match):
    A, chans, C, known = ne2()
    args = dict(A=A, channels=chans, C=C, known=known, graph=ring_graph(6))
    if "C" in kwargs and "known" not in kwargs:
        args["known"] = known[: len(kwargs["C"])]
        args["graph"] = path_graph(len(kwargs["C"]))
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        design_distributed_observer(
            args["A"], args["channels"], args["C"], args["known"], args["graph"], B_v=args.get("B_v")
        )


# ------------------------------------------------------------------ random systems
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), N=st.integers(2, 5), n=st.integers(2, 8))
def test_random_design_identities(seed, N, n):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) * (rng.random((n, n)) < 0.5)
    K = N
    chans = [rng.standard_normal((n, 1)) for _ in range(K)]
    C = []
    for _ in range(N):
        p = int(rng.integers(1, min(3, n) + 1))
        C.append(rng.standard_normal((p, n)))
    # node 0 measures everything so Assumption 6 surely holds
    C[0] = np.eye(n)
    known = [[i] for i in range(N)]
    d = design_distributed_observer(A, chans, C, known, random_connected_graph(N, 0.3, seed))
    check_structure(d)
    check_error_dynamics(d, seed=seed % 1000)


# ------------------------------------------------------------------ NE1 (MAS)
def test_ne1_mas_design_block_selectors():
    agents = ne1_agents()
    d = design_mas_observer(agents, ring_graph(5))
    assert d.n_states == 9 and d.n_inputs == 5 and d.lemma2 is None
    offs = [0, 1, 2, 4, 6, 9]
    I = np.eye(9)
    for i, (Ai, Bi, Ci) in enumerate(agents):
        sel = I[:, offs[i]:offs[i + 1]]
        np.testing.assert_array_equal(d.T_d[i], sel)  # exactly the block selector
        np.testing.assert_array_equal(d.P_d[i], sel @ sel.T)
        Li = -d.F[i]
        # eq. (obidynamicMAS)
        np.testing.assert_allclose(
            d.E_bar[i], sel @ (Ai + Li @ Ci) @ sel.T + d.P_u[i] @ d.A, atol=ATOL
        )
        np.testing.assert_allclose(d.F_bar[i, :, :1], -sel @ Li, atol=ATOL)
        assert np.all(d.G_bar[i] == 0)
        Bfull = np.zeros((9, 5))
        Bfull[offs[i]:offs[i + 1], i] = Bi[:, 0]
        np.testing.assert_array_equal(d.B_bar[i], Bfull)
        np.testing.assert_array_equal(d.B[:, i], Bfull[:, i])
        # NE1 gain: A_i + L_i C_i decays faster than e^{-0.2 t}
        assert np.linalg.eigvals(Ai + Li @ Ci).real.max() < -0.2
    check_structure(d)
    check_error_dynamics(d)


def test_ne1_lemma2_on_mas_gives_own_block():
    """strong_detectability with B_{-i} = other agents' inputs, C_i = block row
    yields exactly agent i's block (Section AIHMAS)."""
    d = design_mas_observer(ne1_agents(), path_graph(5))
    for i in range(5):
        res = strong_detectability(d.A, d.B_unknown(i), d.C_node(i))
        assert res.delta == d.T_d[i].shape[1]
        assert projector_distance(res.T_d, d.T_d[i]) < 1e-8, f"agent {i}"
    # and the general design on the MAS data reproduces the same subspaces
    g = design_distributed_observer(
        d.A, [d.B[:, [k]] for k in range(5)], [d.C_node(i) for i in range(5)],
        [[i] for i in range(5)], path_graph(5),
    )
    for i in range(5):
        assert projector_distance(g.T_d[i], d.T_d[i]) < 1e-8


def test_mas_undetectable_agent_named():
    agents = ne1_agents()
    agents[3] = (agents[3][0], agents[3][1], np.array([[0.0, 1.0]]))  # measures velocity only
    with pytest.raises(DetectabilityError, match="agent 3"):
        design_mas_observer(agents, ring_graph(5))


def test_mas_given_L_and_errors():
    agents = ne1_agents()
    L = [np.array([[-1.0]]), np.array([[-2.0]]), np.array([[-2.0], [-1.0]]),
         np.array([[-3.0], [-2.0]]), np.array([[-3.0], [-3.0], [-1.0]])]
    d = design_mas_observer(agents, ring_graph(5), L=L)
    np.testing.assert_array_equal(d.F[4], -L[4])
    bad = list(L)
    bad[2] = np.array([[1.0], [1.0]])
    with pytest.raises(ValueError, match=r"L\[2\].*not Hurwitz"):
        design_mas_observer(agents, ring_graph(5), L=bad)
    with pytest.raises(GraphNotConnectedError):
        design_mas_observer(agents, Graph.from_edges(5, [(0, 1), (2, 3)]))
    with pytest.raises(ValueError, match="graph has 4 nodes"):
        design_mas_observer(agents, path_graph(4))
