"""Communication graphs among observer nodes (the paper's O-O links).

Section "Communication Links" (label ``commugraph``) of Cao & Yin: the
observer nodes exchange state estimates over an *undirected* weighted graph
with adjacency ``A = [a_ij]`` (``a_ij > 0`` iff nodes ``i`` and ``j`` are
neighbours, ``a_ii = 0``, ``a_ij = a_ji``) and Laplacian ``L = [l_ij]`` with
``l_ii = sum_k a_ik`` and ``l_ij = -a_ij`` (``i != j``). Assumption 5
(``ooconnected``) requires the graph to be connected.

Node indices are **0-based** in code (the paper numbers nodes ``1..N``):
paper node ``i`` is code node ``i - 1``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np
from scipy.sparse import csgraph
from scipy.sparse import csr_matrix

from .linalg.validation import as_array, as_float, as_int, check_seed

__all__ = [
    "Graph",
    "as_graph",
    "path_graph",
    "ring_graph",
    "star_graph",
    "complete_graph",
    "random_connected_graph",
]

#: Absolute tolerance for the symmetry check of a user adjacency matrix
#: (relative to the largest weight). Weights are user data, typically exact
#: small numbers, so anything above round-off is a genuine asymmetry.
_SYM_RTOL = 1e-12


@dataclass(frozen=True)
class Graph:
    """Weighted undirected graph given by its adjacency matrix.

    Parameters
    ----------
    adjacency : array_like, shape (N, N)
        Finite, nonnegative, symmetric weights ``a_ij`` with zero diagonal
        (no self-loops). ``N >= 1``. The array is copied and stored read-only.

    Notes
    -----
    Node indices are 0-based. Construct from an edge list with
    :meth:`Graph.from_edges`. The Laplacian follows the paper's Section
    ``commugraph``: ``l_ii = sum_k a_ik``, ``l_ij = -a_ij``.
    """

    adjacency: np.ndarray

    def __post_init__(self) -> None:
        adj = self.adjacency
        if isinstance(adj, np.ndarray) and adj.dtype == bool:
            adj = adj.astype(float)  # a boolean adjacency: True = an edge of weight 1
        a = as_array(adj, "Graph: adjacency")  # complex, strings, ragged, NaN/inf, too large: named errors
        if a.ndim != 2 or a.shape[0] != a.shape[1]:
            raise ValueError(f"Graph: adjacency must be a square (N, N) array, got shape {a.shape}")
        if a.shape[0] < 1:
            raise ValueError("Graph: adjacency must have at least one node (N >= 1)")
        if np.any(a < 0):
            i, j = np.argwhere(a < 0)[0]
            raise ValueError(
                f"Graph: adjacency weights must be nonnegative, got a[{i},{j}] = {a[i, j]}"
            )
        diag = np.diag(a)
        if np.any(diag != 0):
            i = int(np.flatnonzero(diag)[0])
            raise ValueError(
                f"Graph: adjacency must have zero diagonal (no self-loops), got a[{i},{i}] = {a[i, i]}"
            )
        scale = max(1.0, float(np.max(a)))
        asym = np.abs(a - a.T)
        if np.any(asym > _SYM_RTOL * scale):
            i, j = np.unravel_index(int(np.argmax(asym)), asym.shape)
            raise ValueError(
                "Graph: adjacency must be symmetric (undirected graph, a_ij = a_ji), "
                f"got a[{i},{j}] = {a[i, j]} != a[{j},{i}] = {a[j, i]}"
            )
        a = 0.5 * (a + a.T)  # remove round-off asymmetry
        a.flags.writeable = False
        object.__setattr__(self, "adjacency", a)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_edges(
        cls,
        n_nodes: int,
        edges: Iterable[tuple[int, int]],
        weights: Sequence[float] | None = None,
    ) -> "Graph":
        """Build an undirected graph from a list of 0-based edges ``(i, j)``.

        Parameters
        ----------
        n_nodes : int
            Number of nodes ``N >= 1``.
        edges : iterable of (int, int)
            Undirected edges; ``(i, j)`` and ``(j, i)`` are the same edge.
            Self-loops and duplicate edges are rejected.
        weights : sequence of float, optional
            Positive weight per edge (default 1, as in the paper's examples).
        """
        n = _check_n(n_nodes, "Graph.from_edges")
        try:
            edges = [tuple(e) for e in edges]
        except TypeError:
            raise ValueError(f"Graph.from_edges: edges must be a list of pairs (i, j), got {edges!r}") from None
        if weights is None:
            w = np.ones(len(edges))
        else:
            w = np.atleast_1d(as_array(weights, "Graph.from_edges: weights"))
            if w.ndim != 1:
                raise ValueError(f"Graph.from_edges: weights must be a list of positive numbers, got shape {w.shape}")
            if w.shape[0] != len(edges):
                raise ValueError(
                    f"Graph.from_edges: got {len(edges)} edges but {w.shape[0]} weights"
                )
        a = np.zeros((n, n))
        seen = set()
        for k, e in enumerate(edges):
            if len(e) != 2:
                raise ValueError(f"Graph.from_edges: edge {k} = {e!r} is not a pair (i, j)")
            # fractional, boolean or string node indices are refused, never truncated
            i, j = (as_int(e[0], f"Graph.from_edges: edge {k} = {e!r}: node index"),
                    as_int(e[1], f"Graph.from_edges: edge {k} = {e!r}: node index"))
            if not (0 <= i < n and 0 <= j < n):
                raise ValueError(
                    f"Graph.from_edges: edge {k} = {e!r} has a node outside 0..{n - 1} "
                    "(node indices are 0-based)"
                )
            if i == j:
                raise ValueError(f"Graph.from_edges: edge {k} = {e!r} is a self-loop")
            key = (min(i, j), max(i, j))
            if key in seen:
                raise ValueError(f"Graph.from_edges: duplicate edge {e!r}")
            seen.add(key)
            if not (np.isfinite(w[k]) and w[k] > 0):
                raise ValueError(
                    f"Graph.from_edges: weight of edge {e!r} must be positive and finite, got {w[k]}"
                )
            a[i, j] = a[j, i] = w[k]
        return cls(a)

    # ------------------------------------------------------------------ properties
    @property
    def n_nodes(self) -> int:
        """Number of nodes ``N``."""
        return int(self.adjacency.shape[0])

    @property
    def laplacian(self) -> np.ndarray:
        """Laplacian ``L (N, N)``: ``l_ii = sum_k a_ik``, ``l_ij = -a_ij`` (Section commugraph).

        Rows sum to zero; symmetric positive semidefinite; the multiplicity of
        the eigenvalue 0 equals the number of connected components.
        """
        L = np.diag(self.degree) - self.adjacency
        L.flags.writeable = False
        return L

    @property
    def degree(self) -> np.ndarray:
        """Weighted degrees ``d_i = sum_k a_ik``, shape ``(N,)``."""
        return self.adjacency.sum(axis=1)

    @property
    def max_degree(self) -> float:
        """Largest weighted degree ``max_i d_i``."""
        return float(self.degree.max())

    @property
    def edges(self) -> list[tuple[int, int]]:
        """Undirected edges ``(i, j)`` with ``i < j`` (0-based)."""
        i, j = np.nonzero(np.triu(self.adjacency, 1))
        return [(int(a), int(b)) for a, b in zip(i, j)]

    def neighbors(self, i: int) -> np.ndarray:
        """0-based indices ``j`` with ``a_ij > 0`` (sorted)."""
        i = as_int(i, "Graph.neighbors: node")
        if not 0 <= i < self.n_nodes:
            raise IndexError(f"Graph.neighbors: node {i} outside 0..{self.n_nodes - 1}")
        return np.flatnonzero(self.adjacency[i] > 0)

    def components(self) -> list[list[int]]:
        """Connected components as sorted lists of 0-based node indices,
        ordered by their smallest node."""
        ncomp, labels = csgraph.connected_components(
            csr_matrix(self.adjacency > 0), directed=False
        )
        comps = [sorted(np.flatnonzero(labels == c).tolist()) for c in range(ncomp)]
        return sorted(comps, key=lambda c: c[0])

    def is_connected(self) -> bool:
        """True when the graph has exactly one connected component (Assumption 5)."""
        return len(self.components()) == 1

    def __eq__(self, other: object) -> bool:  # arrays need elementwise comparison
        if not isinstance(other, Graph):
            return NotImplemented
        return self.adjacency.shape == other.adjacency.shape and bool(
            np.array_equal(self.adjacency, other.adjacency)
        )

    def __hash__(self) -> int:
        return hash((self.adjacency.shape, self.adjacency.tobytes()))

    def __repr__(self) -> str:
        return f"Graph(N={self.n_nodes}, edges={len(self.edges)}, connected={self.is_connected()})"


def as_graph(graph: "Graph | np.ndarray | Sequence[Sequence[float]]") -> Graph:
    """Return ``graph`` as a :class:`Graph` (an adjacency array is validated)."""
    if isinstance(graph, Graph):
        return graph
    return Graph(graph)


def _check_n(n: int, who: str, minimum: int = 1) -> int:
    return as_int(n, f"{who}: number of nodes", minimum=minimum)


def path_graph(N: int) -> Graph:
    """Path ``0 - 1 - ... - (N-1)`` with unit weights."""
    N = _check_n(N, "path_graph")
    return Graph.from_edges(N, [(i, i + 1) for i in range(N - 1)])


def ring_graph(N: int) -> Graph:
    """Cycle ``0 - 1 - ... - (N-1) - 0`` with unit weights (``N >= 3``)."""
    N = _check_n(N, "ring_graph", minimum=3)
    return Graph.from_edges(N, [(i, (i + 1) % N) for i in range(N)])


def star_graph(N: int, center: int = 0) -> Graph:
    """Star with hub ``center`` joined to every other node (unit weights)."""
    N = _check_n(N, "star_graph")
    center = as_int(center, "star_graph: center", minimum=0, maximum=N - 1)
    return Graph.from_edges(N, [(center, j) for j in range(N) if j != center])


def complete_graph(N: int) -> Graph:
    """All-to-all graph with unit weights."""
    N = _check_n(N, "complete_graph")
    return Graph.from_edges(N, [(i, j) for i in range(N) for j in range(i + 1, N)])


def random_connected_graph(N: int, edge_prob: float = 0.1, seed: int | None = 0) -> Graph:
    """Random connected graph with unit weights, reproducible from ``seed``.

    A uniformly shuffled random spanning tree (node ``k`` of a random
    permutation attaches to a uniformly chosen earlier node) guarantees
    connectivity; every remaining pair is then added independently with
    probability ``edge_prob`` (Erdos-Renyi). The same ``(N, edge_prob, seed)``
    gives the same graph.
    """
    N = _check_n(N, "random_connected_graph")
    p = as_float(edge_prob, "random_connected_graph: edge_prob", minimum=0.0, maximum=1.0)
    rng = np.random.default_rng(check_seed(seed, "random_connected_graph: seed"))
    a = np.zeros((N, N))
    perm = rng.permutation(N)
    for k in range(1, N):
        j = perm[rng.integers(0, k)]
        a[perm[k], j] = a[j, perm[k]] = 1.0
    extra = np.triu(rng.random((N, N)) < p, 1)
    extra = extra | extra.T
    a[extra] = 1.0
    np.fill_diagonal(a, 0.0)
    return Graph(a)
