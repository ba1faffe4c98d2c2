"""The fault-specific parts of the compiled engine (issue 23; :mod:`.faults` for the semantics): the draws,
the delivery gather and the C-O link.

The faulted control period itself is :func:`dobs_envs.sim.period_kernel.advance_rows` with a
:class:`FaultPeriod` instead of :data:`NO_FAULT` (one engine: the same Euler steps, stable-step test and split
steps, the O-O exchange the only difference, as in :mod:`.numpy_step`'s ``_IdealExchange`` /
``_FaultedExchange``). What is here:

- the period's deliveries (the delivery gather): link ``e`` of the copy's active graph ``g`` delivers
  unless its packet is lost (probability ``oo_loss``, or ``loss_bad``/``loss_good`` by its
  Gilbert-Elliott state), drawn from :mod:`.fault_rng` by (seed, stream, period, link)
  (:func:`delivers`; per copy :func:`deliveries_copy`, per tile :func:`gather_tile` with the copies'
  degrees, weights, held noise, received copies and period counters, written back by
  :func:`scatter_lane`);
- the next period's draws (:func:`draws_rows`: graph chain, burst chains, noise; the period counter),
  as :func:`~dobs_envs.sim.fault_state.period_draws` (:func:`period_draws_compiled`: the same draws for
  any periods, e.g. the first at a reset);
- :func:`co_link_rows`: the C-O link of a range of copies at their control-period boundaries
  (:func:`co_link_row` of one copy; :func:`co_link_compiled` for tests), as
  :func:`~dobs_envs.sim.fault_state.co_link_numpy`.

Every draw, the graph and burst states, the noise, the period counter and the C-O buffers' bookkeeping
are bitwise those of the numpy reference. The fault state is read by name: compiled code receives the
plain tuple of :class:`~dobs_envs.sim.fault_state.FaultState`'s fields (``tuple(fs)``: a named tuple
costs more to dispatch) and names it once (``FaultState(*fs)``); the constants as
:class:`~dobs_envs.sim.fault_state.FaultArgs` packed by :func:`dobs_envs.packing.pack` and read by name
(:func:`unpack_fault_args`, generated from the declaration).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..numba_cache import ensure_fresh
from ..packing import compiled_unpack, pack
from . import fault_rng as frng
from .fault_state import NO_FAULT, FaultArgs, FaultState
from .jit import njit as _njit
from .jit import njit_inline as _njit_inline

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

__all__ = ["FaultPeriod", "FaultCopyScratch", "FaultTile", "unpack_fault_args", "loss_key", "delivers",
           "deliveries_copy", "scratch_copy", "scratch_tile", "gather_tile", "scatter_lane", "draws_rows",
           "co_link_row", "co_link_rows", "period_draws_compiled", "co_link_compiled", "FAULT_STATE_FIELDS"]

#: the order of the fault-state tuple the kernels receive (``tuple(FaultState)``)
FAULT_STATE_FIELDS = FaultState._fields
_OO_LOSS = np.uint64(frng.STREAM_OO_LOSS)
_OO_BURST = np.uint64(frng.STREAM_OO_BURST)
_CO_LOSS = np.uint64(frng.STREAM_CO_LOSS)
_SWITCHING = np.uint64(frng.STREAM_SWITCHING)
_NOISE = np.uint64(frng.STREAM_NOISE)
_U0 = np.uint64(0)

#: ``unpack_fault_args(FF, FI)``: the :class:`~dobs_envs.sim.fault_state.FaultArgs` packed by
#: :func:`dobs_envs.packing.pack` (views; bool scalars as bool), compiled from the declaration.
unpack_fault_args = compiled_unpack(FaultArgs, _njit, "unpack_fault_args")


class FaultPeriod(NamedTuple):
    """The fault arguments of one control period of the engine (``None`` there: the ideal network)."""

    args: FaultArgs  # unpacked constants (unpack_fault_args)
    state: FaultState  # the copies' fault state (received copies and snapshot ring updated, draws read)
    delivered: np.ndarray  # (B, E) bool: the period's deliveries (written)


class FaultCopyScratch(NamedTuple):
    """Work arrays of one copy's faulted period (:func:`scratch_copy`)."""

    degree: np.ndarray  # (N,) the active graph's degrees
    weight: np.ndarray  # (E,) the active graph's link weights
    deliver: np.ndarray  # (E,) bool: the period's deliveries


class FaultTile(NamedTuple):
    """Per-lane fault arrays of a tile of ``W`` copies (:func:`scratch_tile`, :func:`gather_tile`)."""

    received: np.ndarray  # (E, n, W) held copies r_e
    noise: np.ndarray  # (N, p, W) held measurement noise
    degree: np.ndarray  # (N, W) the active graph's degrees
    weight: np.ndarray  # (E, W) the active graph's link weights
    deliver: np.ndarray  # (E, W) bool: the period's deliveries
    period: np.ndarray  # (W,) int: control periods since the reset
    phase: np.ndarray  # (W,) int: the Euler step count of the period's start modulo exchange_steps
    broadcast: np.ndarray  # (W,) bool: a broadcast at this Euler step
    snap: np.ndarray  # (nb, N, n, W): the period's snapshots (oo_delay > 0; nb the most broadcasts per period)
    snap_slot: np.ndarray  # (nb, W) int: their ring slots
    snap_count: np.ndarray  # (W,) int: how many
    mask: np.ndarray  # (W,) bool: a lane mask
    links: np.ndarray  # (E,) int: the links into each node, links[link_ptr[i]:link_ptr[i + 1]] increasing
    link_ptr: np.ndarray  # (N + 1,) int


@_njit
def scratch_copy(fa, N):
    """:class:`FaultCopyScratch` of ``N`` nodes and the ``E`` links of ``fa``."""
    E = fa.sender.shape[0]
    return FaultCopyScratch(np.empty(N), np.empty(E), np.zeros(E, dtype=np.bool_))


@_njit_inline
def loss_key(seed_a, b, k):
    """The :func:`~dobs_envs.sim.fault_rng.period_key` of copy ``b``'s O-O losses in period ``k``."""
    return frng.period_key(seed_a[b], _OO_LOSS, np.uint64(k))


@_njit_inline
def delivers(b, e, fa, key, bad_a, g):
    """Whether link ``e`` of copy ``b`` delivers in the period of the loss key ``key`` (:func:`loss_key`)
    with active graph ``g``: it is in ``g`` and does not lose the period's packets (probability
    ``oo_loss``, or ``loss_bad``/``loss_good`` by its burst state ``bad_a[b, e]``;
    :func:`~dobs_envs.sim.fault_state.oo_losses`)."""
    if not fa.weight[g, e] > 0.0:
        return False
    if fa.burst:
        pl = fa.loss_bad if bad_a[b, e] else fa.loss_good
    else:
        pl = fa.oo_loss
    if pl > 0.0:
        return not frng.uniform_at(key, np.uint64(e)) < pl
    return True


@_njit_inline
def deliveries_copy(b, fault, fsc):
    """The period's active graph (degrees, weights into ``fsc``) and deliveries of copy ``b`` (into
    ``fsc.deliver`` and ``fault.delivered[b]``)."""
    fa, fs = fault.args, fault.state
    g = fs.graph[b]
    deg, wl, deliver = fsc.degree, fsc.weight, fsc.deliver
    for i in range(deg.shape[0]):
        deg[i] = fa.degree[g, i]
    key = loss_key(fs.seed, b, fs.period[b])
    for e in range(wl.shape[0]):
        wl[e] = fa.weight[g, e]
        dl = delivers(b, e, fa, key, fs.bad, g)
        deliver[e] = dl
        fault.delivered[b, e] = dl


@_njit
def scratch_tile(fa, N, n, p, W):
    """:class:`FaultTile` of ``W`` lanes; the links into each node, ``links[link_ptr[i]:link_ptr[i+1]]`` in
    increasing order (without graph switching: only those of nonzero weight)."""
    E = fa.sender.shape[0]
    nb = fa.substeps // fa.exchange_steps + 1 if fa.lag > 0 else 0
    LK = np.empty(E, dtype=np.int64)
    LP = np.zeros(N + 1, dtype=np.int64)
    t = 0
    for i in range(N):
        LP[i] = t
        for e in range(E):
            if fa.receiver[e] == i and (fa.switching or fa.weight[0, e] != 0.0):
                LK[t] = e
                t += 1
    LP[N] = t
    return FaultTile(np.empty((E, n, W)), np.zeros((N, p, W)), np.empty((N, W)), np.empty((E, W)),
                     np.zeros((E, W), dtype=np.bool_), np.zeros(W, dtype=np.int64), np.zeros(W, dtype=np.int64),
                     np.zeros(W, dtype=np.bool_),
                     np.empty((nb, N, n, W)), np.zeros((nb, W), dtype=np.int64), np.zeros(W, dtype=np.int64),
                     np.zeros(W, dtype=np.bool_), LK, LP)


@_njit
def gather_tile(ft, lo, nl, fault):
    """The fault state of copies ``lo .. lo+nl-1`` into the tile ``ft`` (lanes past ``nl`` repeat the last
    copy), with each lane's deliveries of the period (:func:`delivers`)."""
    fa, fs = fault.args, fault.state
    seed_a, period_a, received_a, bad_a, graph_a, noise_a = fs.seed, fs.period, fs.received, fs.bad, fs.graph, fs.noise
    REC, NZ, DEG, WL, DL, KP = ft.received, ft.noise, ft.degree, ft.weight, ft.deliver, ft.period
    TCNT = ft.snap_count
    W = KP.shape[0]
    E, n = REC.shape[0], REC.shape[1]
    N, p = NZ.shape[0], NZ.shape[1]
    for c in range(W):
        b = lo + (c if c < nl else nl - 1)
        g = graph_a[b]
        KP[c] = period_a[b]
        TCNT[c] = 0
        key = loss_key(seed_a, b, period_a[b])
        for i in range(N):
            DEG[i, c] = fa.degree[g, i]
            for q in range(p):
                NZ[i, q, c] = noise_a[b, i, q]
        for e in range(E):
            WL[e, c] = fa.weight[g, e]
            DL[e, c] = delivers(b, e, fa, key, bad_a, g)
            for k in range(n):
                REC[e, k, c] = received_a[b, e, k]


@_njit_inline
def scatter_lane(ft, c, b, fault):
    """Lane ``c`` of the tile back into copy ``b``: its deliveries, received copies and the snapshots its
    period wrote into the ring."""
    fs = fault.state
    received_a, snapshots_a, delivered = fs.received, fs.snapshots, fault.delivered
    REC, DL, TSN, TSLOT = ft.received, ft.deliver, ft.snap, ft.snap_slot
    E, n = REC.shape[0], REC.shape[1]
    N = TSN.shape[1]
    for e in range(E):
        delivered[b, e] = DL[e, c]
        for k in range(n):
            received_a[b, e, k] = REC[e, k, c]
    for t in range(ft.snap_count[c]):
        sl = TSLOT[t, c]
        for i in range(N):
            for k in range(n):
                snapshots_a[b, sl, i, k] = TSN[t, i, k, c]


@_njit
def _period_draws_rows(lo, hi, fa, seed_a, period_a, graph_a, bad_a, noise_a):
    """The draws of period ``period_a[b]`` of copies ``lo .. hi-1``, in place (as
    :func:`~dobs_envs.sim.fault_state.period_draws`): period 0 the graph ``initial_graph`` and burst states
    from the stationary distribution, a later period one step of the graph chain from ``graph_a[b]`` and of
    each link's burst chain from ``bad_a[b]``; the measurement noise (``noise_a`` untouched without it). The
    arrays are taken out of their tuples by the caller, once for the range (per copy, each unpacked array
    cost an atomic reference count update on entry and exit)."""
    cum_transition, last_state = fa.cum_transition, fa.last_state
    noise_mask = fa.noise_mask
    switching, burst, initial_graph = fa.switching, fa.burst, fa.initial_graph
    p_bad_good, p_good_bad, stationary_bad, noise_std = fa.p_bad_good, fa.p_good_bad, fa.stationary_bad, fa.noise_std
    E = fa.sender.shape[0]
    N, P = noise_mask.shape
    G = cum_transition.shape[1]
    for b in range(lo, hi):
        seed = seed_a[b]
        k = period_a[b]
        first = k == 0
        ku = np.uint64(k)
        if not switching:
            graph_a[b] = 0
        elif first:
            graph_a[b] = initial_graph
        else:
            g = graph_a[b]
            thr = frng.uniform_at(frng.period_key(seed, _SWITCHING, ku), _U0) * cum_transition[g, G - 1]
            nxt = 0
            for c in range(G):
                if cum_transition[g, c] <= thr:
                    nxt += 1
            last = last_state[g]
            graph_a[b] = nxt if nxt < last else last
        if burst:
            key = frng.period_key(seed, _OO_BURST, ku)
            for e in range(E):
                uu = frng.uniform_at(key, np.uint64(e))
                if first:
                    bad_a[b, e] = uu < stationary_bad
                elif bad_a[b, e]:
                    bad_a[b, e] = uu >= p_bad_good  # stays bad unless it recovers
                else:
                    bad_a[b, e] = uu < p_good_bad
        else:
            for e in range(E):
                bad_a[b, e] = False
        if noise_std > 0.0:
            key = frng.period_key(seed, _NOISE, ku)
            for i in range(N):
                for q in range(P):
                    zq = frng.normal_at(key, np.uint64(i * P + q))
                    noise_a[b, i, q] = noise_std * zq * noise_mask[i, q]


@_njit
def _period_draws(FF, FI, seed, period, graph, bad, noise):
    _period_draws_rows(0, seed.shape[0], unpack_fault_args(FF, FI), seed, period, graph, bad, noise)


def period_draws_compiled(fa: FaultArgs, seed, period, graph_prev, bad_prev, *, packed=None):
    """Compiled counterpart of :func:`~dobs_envs.sim.fault_state.period_draws` (same arguments and returns,
    bitwise the same draws: :mod:`.fault_rng`), e.g. as ``init_fault_state(..., draws=...)`` at the resets of
    an environment. ``packed``: ``fa`` already packed (:func:`dobs_envs.packing.pack`), to skip packing."""
    FF, FI = pack(fa) if packed is None else packed
    seed = np.ascontiguousarray(seed, dtype=np.uint64).reshape(-1)
    B = seed.shape[0]
    E = fa.sender.shape[0]
    period = np.ascontiguousarray(np.broadcast_to(np.asarray(period, dtype=np.int64), (B,)))
    graph = np.array(np.broadcast_to(np.asarray(graph_prev, dtype=np.int64), (B,)), order="C")
    bad = np.array(np.broadcast_to(np.asarray(bad_prev, dtype=np.bool_), (B, E)), order="C")
    noise = np.zeros((B,) + fa.noise_mask.shape)
    _period_draws(FF, FI, seed, period, graph, bad, noise)
    return graph, bad, noise


@_njit
def draws_rows(lo, hi, fa, fs):
    """The period counters of copies ``lo .. hi-1`` ``+ 1`` and the draws of their new period
    (:func:`_period_draws_rows`)."""
    period_a = fs.period
    for b in range(lo, hi):
        period_a[b] = period_a[b] + 1
    _period_draws_rows(lo, hi, fa, fs.seed, period_a, fs.graph, fs.bad, fs.noise)


@_njit
def co_link_rows(lo, hi, X, xoff, o, co_nodes, fa, fs, received):
    """The C-O links of copies ``lo .. hi-1``, each at the boundary of its period ``fs.period[b]`` (as
    :func:`~dobs_envs.sim.fault_state.co_link_numpy`): link ``l`` of copy ``b`` sends node
    ``co_nodes[l]``'s estimate, ``X[b - xoff, o + co_nodes[l] n : ... + n]`` (``X`` 2-D, the estimates
    flat from column ``o``, node ``i`` at ``o + i n``), into the ring ``co_sent``; unless lost
    (probability ``co_loss``; ``received[b, l]`` = not lost), ``co_held[b, l]`` becomes what was sent
    ``co_delay`` boundaries before. One call for the range (the arrays are taken out of the tuples once)."""
    seed_a, period_a, co_sent, co_held = fs.seed, fs.period, fs.co_sent, fs.co_held
    co_delay, co_loss = fa.co_delay, fa.co_loss
    Lc = co_delay + 1
    n = co_held.shape[2]
    for b in range(lo, hi):
        k = period_a[b]
        slot = k % Lc
        src = (k - co_delay) % Lc
        xr = b - xoff
        key = frng.period_key(seed_a[b], _CO_LOSS, np.uint64(k))
        for l in range(co_nodes.shape[0]):
            i = o + co_nodes[l] * n
            for c in range(n):
                co_sent[b, slot, l, c] = X[xr, i + c]
            lost = False
            if co_loss > 0.0:
                lost = frng.uniform_at(key, np.uint64(l)) < co_loss
            received[b, l] = not lost
            if not lost:
                for c in range(n):
                    co_held[b, l, c] = co_sent[b, src, l, c]


@_njit
def co_link_row(b, xhat, co_nodes, fa, fs, received):
    """The C-O links of copy ``b`` at the boundary of its period (:func:`co_link_rows`; ``xhat`` flat
    ``(N n,)``, node ``i`` at ``i n``)."""
    co_link_rows(b, b + 1, xhat.reshape((1, xhat.shape[0])), b, 0, co_nodes, fa, fs, received)


def _copy_state(fs: FaultState) -> tuple:
    return tuple(np.array(a, copy=True, order="C") for a in fs)


@_njit
def _co_link(sent, co_nodes, FF, FI, fs, received):
    co_link_rows(0, sent.shape[0], sent, 0, 0, co_nodes, unpack_fault_args(FF, FI), FaultState(*fs), received)


def co_link_compiled(xhat, co_nodes, fs: FaultState, fa, received=None):
    """Compiled C-O link of every copy (tests): ``xhat (B, N, n)`` the nodes' estimates at the boundary,
    ``co_nodes (K,)``; returns ``(held (B, K, n), new FaultState, received (B, K) bool)``."""
    FF, FI = pack(fa) if isinstance(fa, FaultArgs) else fa
    st = _copy_state(fs)
    B = fs.seed.shape[0]
    received = np.zeros((B, np.asarray(co_nodes).shape[0]), dtype=np.bool_) if received is None else received
    sent = np.ascontiguousarray(np.asarray(xhat, dtype=np.float64).reshape(B, -1))
    _co_link(sent, np.ascontiguousarray(co_nodes, dtype=np.int64), FF, FI, st, received)
    new = FaultState(*st)
    return new.co_held.copy(), new, received
