r"""Distributed observer design: eqs. (barEFGB), (TidTiu), (obidynamicMAS).

Section "Fully Distributed State Estimation" (``SFDOWUGI``): observer node
``i`` runs (eq. ``obidynamic``)::

    z_i'   = Ebar_i z_i + Fbar_i y_i + Bbar_i u_i - H_i( sum_j a_ij (xhat_i - xhat_j) )
    xhat_i = z_i + Gbar_i y_i

with the gains of eq. (``barEFGB``)::

    Ebar_i = T_id E_i T_id^T + T_iu T_iu^T A
    Fbar_i = T_id F_i + T_iu T_iu^T A Gbar_i
    Gbar_i = T_id G_i
    Bbar_i = (I - Gbar_i C_i) B_i

where ``(T_id, E_i, F_i, G_i)`` is the Lemma 2 (FUIO) quadruplet of the triplet
``(A, B_{-i}, C_i)`` and ``T_iu`` completes ``T_id`` (eq. ``TidTiu``:
``T_id^T T_iu = 0``, ``T_iu^T T_iu = I``, ``T_iu T_iu^T = I - T_id T_id^T``).
``B_{-i}`` collects the columns of the input channels node ``i`` does not know
plus ``B_v`` (eq. ``splitinput``); the channels themselves are the ``B^k`` of
eq. (``Busplit``).

:func:`design_distributed_observer` computes all of this for ``N`` nodes and
checks Assumptions 5 and 6. :func:`design_mas_observer` builds the reduced
form (``obidynamicMAS``) of Section ``AIHMAS`` for a heterogeneous
multi-agent system. Both return an :class:`ObserverDesign` with the node axis
first (see ARCHITECTURE.md); node, channel and agent indices are **0-based**.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from .. import assumptions as _asm
from ..graphs import Graph, as_graph
from ..linalg.subspaces import is_hurwitz, scaled_rank
from ..linalg.validation import as_matrix, as_square, check_tol
from .gains import observer_are_gain
from .lemma2 import StrongDetectability, lemma2_residuals
from .mas_composition import agent_offsets, compose_mas
from .node_tasks import DESIGN_BACKENDS, run_node_designs

__all__ = [
    "ObserverDesign",
    "design_distributed_observer",
    "design_mas_observer",
    "observer_residuals",
]


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class ObserverDesign:
    """All gains of the ``N`` observer nodes, node axis first.

    ``N`` nodes, ``n`` states, ``m`` control inputs (all channels stacked),
    ``m_v`` unknown inputs, ``p = max_i p_i``. Node and channel indices are 0-based.

    Attributes
    ----------
    A : ndarray (n, n)
    B : ndarray (n, m)
        ``[B^1 ... B^K]`` (eq. ``Busplit``).
    channel_slices : tuple of slice
        Columns of channel ``k`` in ``B``.
    B_v : ndarray (n, m_v)
        Unknown-input matrix (``m_v = 0`` allowed).
    C : ndarray (N, p, n)
        ``C_i`` of eq. (``localmeasure``); rows ``p_i..p-1`` are zero padding.
    p_i : ndarray (N,) int
        Number of outputs of node ``i``.
    known : ndarray (N, m) bool
        Columns of ``B`` whose input node ``i`` receives (``B_i`` of eq. ``splitinput``).
    E_bar, F_bar, G_bar, B_bar : ndarray (N, n, n), (N, n, p), (N, n, p), (N, n, m)
        Eq. (``barEFGB``). ``F_bar``/``G_bar`` have zero columns beyond
        ``p_i``; ``B_bar[i]`` has zero columns for the inputs node ``i`` does
        not know, so the node term is ``B_bar[i] @ u`` with the full ``u (m,)``.
        For the MAS form (``obidynamicMAS``): ``G_bar = 0``, ``B_bar[i] = B_i``.
    P_u, P_d : ndarray (N, n, n)
        ``T_iu T_iu^T`` and ``T_id T_id^T`` (eq. ``TidTiu``), ``P_u + P_d = I``.
    adjacency : ndarray (N, N)
    graph : Graph
    lemma2 : tuple of StrongDetectability or None
        Per-node Lemma 2 results; ``None`` for the MAS form (whose quadruplet
        is given in closed form, see :func:`design_mas_observer`).
    T_d : tuple of ndarray (n, delta_i)
        Orthonormal bases of the strongly detectable subspaces ``Im T_id``.
    T_u : tuple of ndarray (n, n - delta_i)
        ``T_iu`` of eq. (``TidTiu``).
    E, F, G : tuple of ndarray (delta_i, delta_i), (delta_i, p_i), (delta_i, p_i)
        The local quadruplet ``(E_i, F_i, G_i)`` used in eq. (``barEFGB``).

    All arrays are read-only copies.
    """

    A: np.ndarray
    B: np.ndarray
    channel_slices: tuple
    B_v: np.ndarray
    C: np.ndarray
    p_i: np.ndarray
    known: np.ndarray
    E_bar: np.ndarray
    F_bar: np.ndarray
    G_bar: np.ndarray
    B_bar: np.ndarray
    P_u: np.ndarray
    P_d: np.ndarray
    adjacency: np.ndarray
    graph: Graph
    lemma2: tuple | None
    T_d: tuple
    T_u: tuple
    E: tuple
    F: tuple
    G: tuple

    @property
    def n_nodes(self) -> int:
        """``N``."""
        return int(self.E_bar.shape[0])

    @property
    def n_states(self) -> int:
        """``n``."""
        return int(self.A.shape[0])

    @property
    def n_inputs(self) -> int:
        """``m`` (all channels)."""
        return int(self.B.shape[1])

    @property
    def delta(self) -> np.ndarray:
        """``delta_i = dim Im T_id`` per node, shape ``(N,)``."""
        return np.array([T.shape[1] for T in self.T_d], dtype=int)

    @property
    def laplacian(self) -> np.ndarray:
        """Graph Laplacian ``(N, N)`` (Section ``commugraph``)."""
        return self.graph.laplacian

    def C_node(self, i: int) -> np.ndarray:
        """Unpadded ``C_i`` of shape ``(p_i, n)``."""
        return self.C[i, : self.p_i[i]]

    def B_known(self, i: int) -> np.ndarray:
        """``B_i`` (columns of the inputs node ``i`` knows), shape ``(n, #known)``."""
        return self.B[:, self.known[i]]

    def B_unknown(self, i: int) -> np.ndarray:
        """``B_{-i}`` of eq. (``splitinput``): unknown channel columns, then ``B_v``."""
        return np.hstack([self.B[:, ~self.known[i]], self.B_v])

    def residuals(self) -> np.ndarray:
        """See :func:`observer_residuals`."""
        return observer_residuals(self)


def observer_residuals(design: ObserverDesign) -> np.ndarray:
    """Per-node relative residuals of the two equations of Lemma 2 (FUIO).

    For node ``i`` with ``B_{-i}`` = :meth:`ObserverDesign.B_unknown`:

    * ``rB_i``: ``G_i C_i B_{-i} = T_id^T B_{-i}``,
    * ``rA_i``: ``E_i T_id^T + (G_i C_i - T_id^T) A + (F_i - E_i G_i) C_i = 0``,

    each relative to the size of its terms (as in
    :func:`~dobs_envs.design.lemma2.lemma2_residuals`).

    Returns
    -------
    ndarray, shape (N, 2)
        Columns ``(rB, rA)``; ~1e-15 for a correct design.
    """
    out = np.zeros((design.n_nodes, 2))
    for i in range(design.n_nodes):
        q = StrongDetectability(
            T_d=design.T_d[i], T_u=design.T_u[i], E=design.E[i], F=design.F[i], G=design.G[i]
        )
        out[i] = lemma2_residuals(design.A, design.B_unknown(i), design.C_node(i), q)
    return out


# ---------------------------------------------------------------------------
# boundary validation
# ---------------------------------------------------------------------------
def _check_full_row_rank(C: np.ndarray, name: str) -> None:
    if C.shape[0] == 0:
        raise ValueError(f"{name} has no rows: every observer node needs a measurement y_i = C_i x")
    r = scaled_rank(C)  # the rule strong_detectability applies (units of C do not matter)
    if r < C.shape[0]:
        raise ValueError(
            f"{name} must have full row rank (eq. localmeasure), got shape {C.shape} with "
            f"numerical rank {r}; remove the redundant rows"
        )


def _graph_for(graph, N: int) -> Graph:
    try:
        g = as_graph(graph)
    except ValueError as exc:
        raise ValueError(f"graph: {exc}") from None
    if g.n_nodes != N:
        raise ValueError(f"graph has {g.n_nodes} nodes but {N} observer nodes were given (len(C))")
    return g


def _known_indices(known, N: int, K: int) -> list[list[int]]:
    try:
        known = list(known)
    except TypeError:
        raise ValueError("known must be a sequence with, per node, an iterable of channel indices") from None
    if len(known) != N:
        raise ValueError(f"known must have one entry per node (N = {N} from len(C)), got {len(known)}")
    out = []
    for i, ks in enumerate(known):
        if isinstance(ks, (int, np.integer)):
            ks = [ks]
        try:
            ks = list(ks)
        except TypeError:
            raise ValueError(f"known[{i}] must be an iterable of channel indices, got {ks!r}") from None
        idx = []
        for k in ks:
            if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
                raise ValueError(f"known[{i}] contains {k!r}; channel indices must be integers (0-based)")
            if not 0 <= int(k) < K:
                raise ValueError(
                    f"known[{i}] contains channel {int(k)} but there are {K} channels "
                    f"(0-based indices 0..{K - 1})"
                )
            if int(k) in idx:
                raise ValueError(f"known[{i}] lists channel {int(k)} twice")
            idx.append(int(k))
        out.append(sorted(idx))
    return out


def _channel_slices(chans) -> list[slice]:
    """Columns of each channel ``B^k (n, m_k)`` in ``B = [B^0 ... B^{K-1}]`` (eq. Busplit)."""
    slices, start = [], 0
    for b in chans:
        slices.append(slice(start, start + b.shape[1]))
        start += b.shape[1]
    return slices


def _known_mask(known_idx, slices, N: int, m: int) -> np.ndarray:
    """``(N, m)`` bool: the columns of ``B`` whose input node ``i`` receives (its ``B_i``, eq. splitinput)."""
    known_mask = np.zeros((N, m), dtype=bool)
    for i, ks in enumerate(known_idx):
        for k in ks:
            known_mask[i, slices[k]] = True
    return known_mask


def _assemble(A, B, slices, B_v, C_list, known_mask, g, T_d, T_u, E, F, G, lemma2) -> ObserverDesign:
    """Eq. (barEFGB)/(TidTiu) for every node, node axis first."""
    n = A.shape[0]
    m = B.shape[1]
    N = len(C_list)
    p_i = np.array([Ci.shape[0] for Ci in C_list], dtype=int)
    p = int(p_i.max())
    I = np.eye(n)
    C = np.zeros((N, p, n))
    E_bar = np.empty((N, n, n))
    F_bar = np.zeros((N, n, p))
    G_bar = np.zeros((N, n, p))
    B_bar = np.zeros((N, n, m))
    P_u = np.empty((N, n, n))
    P_d = np.empty((N, n, n))
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is checked below
        for i in range(N):
            Ci, Td, Tu = C_list[i], T_d[i], T_u[i]
            pi = Ci.shape[0]
            C[i, :pi] = Ci
            P_d[i] = Td @ Td.T
            P_u[i] = Tu @ Tu.T  # eq. (TidTiu): = I - T_id T_id^T
            PuA = A - Td @ (Td.T @ A)  # T_iu T_iu^T A without forming P_u @ A (O(n^2 delta))
            Gb = Td @ G[i]  # eq. (barG_i)
            E_bar[i] = (Td @ E[i]) @ Td.T + PuA  # eq. (barE_i)
            F_bar[i, :, :pi] = Td @ F[i] + PuA @ Gb  # eq. (barF_i)
            G_bar[i, :, :pi] = Gb
            cols = known_mask[i]
            if cols.any():
                B_bar[i][:, cols] = (I - Gb @ Ci) @ B[:, cols]  # eq. (barB_i)
    del I
    for name, M in (("E_bar", E_bar), ("F_bar", F_bar), ("G_bar", G_bar), ("B_bar", B_bar)):
        bad = ~np.all(np.isfinite(M.reshape(N, -1)), axis=1)
        if bad.any():
            raise ValueError(
                f"{name} of node {int(np.argmax(bad))} overflows double precision (eq. barEFGB): "
                "A, the input channels or C_i are too large for this design; rescale them"
            )
    return ObserverDesign(
        A=_ro(A), B=_ro(B), channel_slices=tuple(slices), B_v=_ro(B_v), C=_ro(C), p_i=_ro(p_i),
        known=_ro(known_mask), E_bar=_ro(E_bar), F_bar=_ro(F_bar), G_bar=_ro(G_bar),
        B_bar=_ro(B_bar), P_u=_ro(P_u), P_d=_ro(P_d), adjacency=g.adjacency, graph=g,
        lemma2=lemma2, T_d=tuple(_ro(t) for t in T_d), T_u=tuple(_ro(t) for t in T_u),
        E=tuple(_ro(e) for e in E), F=tuple(_ro(f) for f in F), G=tuple(_ro(x) for x in G),
    )


# ---------------------------------------------------------------------------
# general design (Section SFDOWUGI)
# ---------------------------------------------------------------------------
def design_distributed_observer(
    A,
    channels: Sequence,
    C: Sequence,
    known: Sequence[Iterable[int]],
    graph,
    B_v=None,
    *,
    tol: float | None = None,
    poles=None,
    backend: str = "serial",
) -> ObserverDesign:
    """Design the ``N`` observer nodes of eq. (``obidynamic``) with gains (``barEFGB``).

    Parameters
    ----------
    A : array_like, shape (n, n)
        System matrix of eq. (``LTIsys``).
    channels : sequence of array_like, each shape (n, m_k)
        Input channels ``B^k`` of eq. (``Busplit``) (a 1-D vector of length
        ``n`` is one column); ``B = [B^0 ... B^{K-1}]``.
    C : sequence of array_like, each shape (p_i, n)
        Output matrices of eq. (``localmeasure``), full row rank, ``p_i >= 1``
        (a 1-D vector is one row). ``N = len(C)``.
    known : sequence of length N of iterables of int
        ``known[i]`` = 0-based indices of the channels whose input node ``i``
        receives (its ``B_i`` of eq. ``splitinput``).
    graph : Graph or array_like (N, N)
        O-O communication graph (Assumption 5: connected).
    B_v : array_like, shape (n, m_v), optional
        Unknown-input matrix; always part of every ``B_{-i}``.
    tol : float, optional
        Absolute SVD threshold passed to
        :func:`~dobs_envs.design.lemma2.strong_detectability`.
    poles : mapping int -> array_like, optional
        ``{i: eigenvalues}``: pin the assignable eigenvalues of node ``i``'s ``E_i``
        (0-based node index; see ``poles`` of
        :func:`~dobs_envs.design.lemma2.strong_detectability`); the other nodes keep
        the default choice (shifted ARE). The paper leaves ``E_i`` free beyond Hurwitz.
    backend : {"serial", "ray"}, default "serial"
        Where the ``N`` independent per-node Lemma 2 designs run: in this process, or as one
        Ray task each on the Ray runtime of this process (``pip install 'dobs-envs[distributed]'``;
        see :mod:`dobs_envs.design.node_tasks`). The result is the same.

    Returns
    -------
    ObserverDesign

    Raises
    ------
    ValueError
        Malformed arguments (message names the argument, node and expected shape).
    IllConditionedError
        A node's Lemma 2 design cannot be computed reliably in double
        precision (a ``ValueError``; the message names the node and why).
    GraphNotConnectedError
        Assumption 5 fails.
    CollectiveDetectabilityError
        Assumption 6 fails (``sum_i Im T_id != R^n``).
    """
    A = as_square(A, "A", nonempty=True)
    tol = check_tol(tol)
    n = A.shape[0]
    if isinstance(channels, np.ndarray) and channels.ndim == 2:
        raise ValueError(
            "channels must be a sequence of (n, m_k) blocks B^k, not one matrix; "
            "pass e.g. [B[:, [k]] for k in range(m)]"
        )
    chans = [as_matrix(b, f"channels[{k}]", rows=n, vector_as="col") for k, b in enumerate(channels)]
    K = len(chans)
    slices = _channel_slices(chans)
    B = np.hstack(chans) if chans else np.zeros((n, 0))
    m = B.shape[1]
    B_v = np.zeros((n, 0)) if B_v is None else as_matrix(B_v, "B_v", rows=n, vector_as="col")

    if isinstance(C, np.ndarray) and C.ndim == 2:
        raise ValueError("C must be a sequence of per-node (p_i, n) matrices, not one matrix")
    C_list = [as_matrix(Ci, f"C[{i}] (node {i})", cols=n, vector_as="row") for i, Ci in enumerate(C)]
    N = len(C_list)
    if N == 0:
        raise ValueError("C must contain at least one node's output matrix")
    for i, Ci in enumerate(C_list):
        _check_full_row_rank(Ci, f"C[{i}] (node {i})")
    known_idx = _known_indices(known, N, K)
    g = _graph_for(graph, N)

    known_mask = _known_mask(known_idx, slices, N, m)

    # Assumption 5 first: cheap and independent of the Lemma 2 computations
    _asm.check_connected(g)

    poles = {} if poles is None else dict(poles)
    bad = [k for k in poles if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer))
           or not 0 <= k < N]
    if bad:
        raise ValueError(f"poles: keys must be node indices 0..{N - 1}, got {bad}")
    if backend not in DESIGN_BACKENDS:
        raise ValueError(f"backend must be one of {DESIGN_BACKENDS}, got {backend!r}")
    B_minus = [np.hstack([B[:, ~known_mask[i]], B_v]) for i in range(N)]  # eq. (splitinput)
    results = run_node_designs(backend, A, B_minus, C_list, tol, poles)

    T_d = [r.T_d for r in results]
    _asm.check_collective_detectability(T_d, n, tol=tol)  # Assumption 6

    return _assemble(
        A, B, slices, B_v, C_list, known_mask, g, T_d,
        [r.T_u for r in results], [r.E for r in results], [r.F for r in results],
        [r.G for r in results], tuple(results),
    )


# ---------------------------------------------------------------------------
# heterogeneous MAS (Section AIHMAS)
# ---------------------------------------------------------------------------
def design_mas_observer(agents: Sequence, graph, *, shift: float = 0.2, L: Sequence | None = None) -> ObserverDesign:
    """Observer of eq. (``obidynamicMAS``) for a heterogeneous multi-agent system (``HMAS``).

    Agent ``i`` has ``breve x_i' = A_i breve x_i + B_i u_i``, ``y_i = C_i breve x_i``
    and knows only ``u_i`` and ``y_i``. The overall system
    (:func:`~dobs_envs.design.mas_composition.compose_mas`, the composition the MAS
    scenarios use) has ``A = diag(A_i)``, ``B = diag(B_i)`` (channel ``i`` = agent ``i``),
    ``C_i`` padded to the block row of agent ``i``, and
    ``T_id = [0 I_{n_i} 0]^T`` (block selector). The gains are::

        Ebar_i = T_id (A_i + L_i C_i) T_id^T + T_iu T_iu^T A,
        Fbar_i = -T_id L_i,   Gbar_i = 0,   Bbar_i = B_i (block column),

    so the node state ``z_i`` *is* ``xhat_i``. This is eq. (``barEFGB``) with
    the Lemma 2 quadruplet ``(T_id, A_i + L_i C_i, -L_i, 0)``, stored in
    ``design.E/F/G`` (``design.lemma2`` is ``None``).

    Parameters
    ----------
    agents : sequence of (A_i, B_i, C_i)
        Shapes ``(n_i, n_i)``, ``(n_i, m_i)``, ``(p_i, n_i)``; ``C_i`` full row
        rank; ``(A_i, C_i)`` detectable. Agent indices are 0-based.
    graph : Graph or array_like (N, N)
        Assumption 5: connected.
    shift : float, default 0.2
        ``L_i = observer_are_gain(A_i, C_i, shift)`` (Section NE1).
    L : sequence of array_like (n_i, p_i), optional
        Given observer gains instead; ``A_i + L_i C_i`` must be Hurwitz.

    Raises
    ------
    DetectabilityError
        ``(A_i, C_i)`` not detectable with margin ``shift`` (names the agent).
    GraphNotConnectedError
    ValueError
        Malformed arguments or a given ``L_i`` that does not stabilise ``A_i + L_i C_i``.
    """
    try:
        agents = list(agents)
    except TypeError:
        raise ValueError("agents must be a sequence of (A_i, B_i, C_i) triples") from None
    N = len(agents)
    if N == 0:
        raise ValueError("agents must contain at least one (A_i, B_i, C_i) triple")
    if L is not None:
        L = list(L)
        if len(L) != N:
            raise ValueError(f"L must have one gain per agent ({N}), got {len(L)}")
    Ai, Bi, Ci = [], [], []
    for i, ag in enumerate(agents):
        try:
            a, b, c = ag
        except (TypeError, ValueError):
            raise ValueError(f"agents[{i}] must be a triple (A_i, B_i, C_i)") from None
        a = as_square(a, f"agents[{i}] A_i", nonempty=True, vector_as="row")
        ni = a.shape[0]
        b = as_matrix(b, f"agents[{i}] B_i", rows=ni, vector_as="col")
        c = as_matrix(c, f"agents[{i}] C_i", cols=ni, vector_as="row")
        _check_full_row_rank(c, f"agents[{i}] C_i")
        Ai.append(a), Bi.append(b), Ci.append(c)
    g = _graph_for(graph, N)

    # eq. (HMAS) as one plant (Section AIHMAS): A = diag(A_i), B^i = [0 B_i^T 0]^T, C_i = [0 C_i 0], known[i] = (i,)
    mas = compose_mas(zip(Ai, Bi, Ci))
    A = mas.A
    chans = mas.channels
    slices = _channel_slices(chans)
    B = np.hstack(chans)  # diag(B_i)
    n = A.shape[0]
    n_i = [a.shape[0] for a in Ai]
    offs = agent_offsets(n_i)
    C_list, T_d, T_u, E, F, G = list(mas.C), [], [], [], [], []
    I = np.eye(n)
    for i in range(N):
        T_d.append(I[:, offs[i]:offs[i + 1]].copy())  # block selector [0 I_{n_i} 0]^T
        T_u.append(np.delete(I, np.arange(offs[i], offs[i + 1]), axis=1))
        name = f"agent {i} (0-based)"
        if L is None:
            Li = observer_are_gain(Ai[i], Ci[i], shift, name=name)  # NE1
        else:
            Li = as_matrix(L[i], f"L[{i}]", rows=n_i[i], cols=Ci[i].shape[0], vector_as="col")
            if not is_hurwitz(Ai[i] + Li @ Ci[i]):
                raise ValueError(f"L[{i}]: A_i + L_i C_i of {name} is not Hurwitz")
        E.append(Ai[i] + Li @ Ci[i])
        F.append(-Li)
        G.append(np.zeros((n_i[i], Ci[i].shape[0])))
    del I

    _asm.check_connected(g)  # Assumption 5
    _asm.check_collective_detectability(T_d, n)  # Assumption 6 (holds by construction)

    known_mask = _known_mask(mas.known, slices, N, B.shape[1])
    return _assemble(A, B, slices, np.zeros((n, 0)), C_list, known_mask, g, T_d, T_u, E, F, G, None)
