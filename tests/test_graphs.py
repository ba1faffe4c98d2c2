"""Graph / Laplacian (Section commugraph) and Assumption 5 connectivity."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dobs_envs.graphs import (
    Graph,
    complete_graph,
    path_graph,
    random_connected_graph,
    ring_graph,
    star_graph,
)

TOPOLOGIES = [
    ("path", lambda N: path_graph(N)),
    ("ring", lambda N: ring_graph(N)),
    ("star", lambda N: star_graph(N)),
    ("star_c2", lambda N: star_graph(N, center=2)),
    ("complete", lambda N: complete_graph(N)),
    ("random", lambda N: random_connected_graph(N, 0.05, seed=7)),
]


@pytest.mark.parametrize("name,make", TOPOLOGIES)
@pytest.mark.parametrize("N", [3, 6, 17])
def test_topology_laplacian_and_connectivity(name, make, N):
    g = make(N)
    L = g.laplacian
    assert L.shape == (N, N)
    np.testing.assert_allclose(L.sum(axis=1), 0.0, atol=1e-12)
    np.testing.assert_array_equal(L, L.T)
    ev = np.linalg.eigvalsh(L)
    assert ev.min() > -1e-10  # PSD
    # connected <=> eigenvalue 0 is simple (algebraic connectivity > 0)
    assert ev[1] > 1e-8
    assert g.is_connected()
    assert g.components() == [list(range(N))]
    np.testing.assert_array_equal(np.diag(L), g.degree)
    assert g.max_degree == g.degree.max()


def test_specific_degrees():
    assert star_graph(5).degree.tolist() == [4, 1, 1, 1, 1]
    assert ring_graph(5).degree.tolist() == [2] * 5
    assert path_graph(4).degree.tolist() == [1, 2, 2, 1]
    assert complete_graph(4).max_degree == 3
    assert path_graph(4).neighbors(1).tolist() == [0, 2]
    assert star_graph(4, center=3).neighbors(3).tolist() == [0, 1, 2]
    assert len(complete_graph(6).edges) == 15


def test_from_edges_weights_and_laplacian_definition():
    g = Graph.from_edges(3, [(0, 1), (2, 1)], weights=[2.0, 0.5])
    expected = np.array([[2.0, -2.0, 0.0], [-2.0, 2.5, -0.5], [0.0, -0.5, 0.5]])
    np.testing.assert_array_equal(g.laplacian, expected)
    assert g.edges == [(0, 1), (1, 2)]


def test_disconnected_components():
    g = Graph.from_edges(5, [(0, 3), (1, 4)])
    assert not g.is_connected()
    assert g.components() == [[0, 3], [1, 4], [2]]
    ev = np.linalg.eigvalsh(g.laplacian)
    assert np.sum(np.abs(ev) < 1e-10) == 3  # multiplicity of 0 = number of components


def test_single_node_is_connected():
    g = Graph(np.zeros((1, 1)))
    assert g.is_connected()
    np.testing.assert_array_equal(g.laplacian, [[0.0]])


def test_random_graph_seeded_determinism():
    a = random_connected_graph(30, 0.1, seed=123)
    b = random_connected_graph(30, 0.1, seed=123)
    c = random_connected_graph(30, 0.1, seed=124)
    assert a == b
    np.testing.assert_array_equal(a.adjacency, b.adjacency)
    assert a != c


@settings(max_examples=40, deadline=None)
@given(N=st.integers(1, 40), p=st.floats(0.0, 1.0), seed=st.integers(0, 2**31 - 1))
def test_random_graph_always_connected(N, p, seed):
    g = random_connected_graph(N, p, seed)
    assert g.is_connected()
    assert len(g.edges) >= N - 1
    if p == 0.0:
        assert len(g.edges) == N - 1  # exactly the spanning tree


def test_arrays_are_read_only_and_input_copied():
    a = np.array([[0.0, 1.0], [1.0, 0.0]])
    g = Graph(a)
    a[0, 1] = 5.0
    assert g.adjacency[0, 1] == 1.0
    with pytest.raises(ValueError):
        g.adjacency[0, 1] = 3.0


@pytest.mark.parametrize(
    "adj,match",
    [
        ([[0, 1], [2, 0]], "symmetric"),
        ([[0, -1], [-1, 0]], "nonnegative"),
        ([[1, 1], [1, 0]], "diagonal"),
        ([[0, 1, 0], [1, 0, 1]], "square"),
        ([[0, np.nan], [np.nan, 0]], "NaN"),
        (np.zeros((0, 0)), "at least one"),
    ],
)
def test_invalid_adjacency(adj, match):
    with pytest.raises(ValueError, match=match):
        Graph(np.asarray(adj, dtype=float))


def test_invalid_edges():
    with pytest.raises(ValueError, match="0-based"):
        Graph.from_edges(3, [(1, 3)])
    with pytest.raises(ValueError, match="self-loop"):
        Graph.from_edges(3, [(1, 1)])
    with pytest.raises(ValueError, match="duplicate"):
        Graph.from_edges(3, [(0, 1), (1, 0)])
    with pytest.raises(ValueError, match="positive"):
        Graph.from_edges(3, [(0, 1)], weights=[0.0])
    with pytest.raises(ValueError, match="weights"):
        Graph.from_edges(3, [(0, 1)], weights=[1.0, 2.0])
    with pytest.raises(ValueError):
        ring_graph(2)
    with pytest.raises(ValueError):
        random_connected_graph(5, 1.5, 0)
