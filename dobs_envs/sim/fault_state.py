"""The fault model's constants and per-copy state (batch first), their initialisation at reset,
the per-period draws and the C-O link (:mod:`.faults` for the semantics of every key).

- :class:`FaultArgs`: the constants resolved from a :class:`~dobs_envs.sim.faults.Faults` and a
  :class:`~dobs_envs.sim.state.SimParams` (where ``dt`` and the control period are known:
  :func:`fault_args`), declared like :class:`~dobs_envs.sim.kernel_args.KernelArgs` (one line per
  field with kind and shape symbols, :mod:`dobs_envs.packing`) so that they can be packed for a
  compiled kernel.
- :class:`FaultState`: the per-copy state, every array batch first (``B`` copies): the held
  received copies ``r_e`` of the directed O-O links, the ring of broadcast snapshots per sender
  (``oo_delay``), the Gilbert-Elliott states, the active graph, the period's measurement noise,
  the C-O buffers, the period counter and the seed. :func:`init_fault_state` builds it at reset.
- :func:`period_draws`, :func:`oo_losses`: the draws made once per control period (graph chain,
  burst chains, noise; losses), from the counter-based generator :mod:`.fault_rng`.
- :func:`co_link_numpy`: the C-O link at a control-period boundary (loss and delay of the
  estimates the controllers read).

Links. The directed O-O links are the ordered pairs ``(j -> i)`` with ``a_ij > 0`` in some graph
(the union of the switching graphs, or the scenario's graph), sorted by receiver ``i`` then sender
``j`` (the order of the Laplacian's rows): ``sender (E,)``, ``receiver (E,)``; ``weight (G, E)``
holds ``a_ij`` of link ``e`` in graph ``g`` (0: absent from that graph).

Timeline of period ``k`` of a copy (``k`` = periods since its reset, :attr:`FaultState.period`):
the state holds the period's graph, burst states and noise (drawn at the end of period ``k - 1``,
or at reset for ``k = 0``, so that the estimates read at the boundary ``k T`` already carry the
period's noise); :func:`oo_losses` draws the period's O-O losses; the period runs
(:func:`~dobs_envs.sim.numpy_step.control_period_faulted_numpy`); the draws of period ``k + 1``
are made and ``period`` becomes ``k + 1``.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..packing import b1, f64, i64
from . import fault_rng as rng
from .faults import Faults

__all__ = ["NO_FAULT", "FaultArgs", "FaultState", "fault_args", "init_fault_state", "period_draws", "oo_losses",
           "faulted_outputs", "faulted_estimates", "co_link_numpy"]

#: the ``fault`` argument of the compiled kernels on the ideal network: an empty tuple, not ``None``. The
#: kernels branch on ``len(fault) == 0``, which numba turns into a constant before typing for any tuple
#: argument (its ``RewriteSemanticConstants`` pass) and then prunes: each specialisation compiles only its
#: own network's code. ``if fault is None:`` is pruned only where the argument *is* None: a specialisation
#: for a fault tuple kept the ideal branches, compiled the whole ideal engine beside the faulted one (a
#: faulted environment's cold compile 2x longer) and typed the work arrays ``ft``/``fsc`` as optionals.
NO_FAULT = ()


class FaultArgs(NamedTuple):
    """Constants of the fault model for one :class:`~dobs_envs.sim.state.SimParams` (module doc).

    Shape symbols: ``E`` directed O-O links, ``G`` graphs, ``N`` nodes, ``P`` output rows (``p``).
    """

    sender: i64("E")  # link e carries xhat_{sender[e]} ...
    receiver: i64("E")  # ... to node receiver[e]
    weight: f64("G E")  # a_ij of link e in graph g (0: absent)
    degree: f64("G N")  # sum_j a_ij of graph g (the Laplacian's diagonal)
    cum_transition: f64("G G")  # row-wise cumulative transition probabilities of the graph chain
    last_state: i64("G")  # last column with a positive probability in each row (rounding guard)
    initial_graph: i64()
    switching: b1()  # a Markov chain over graphs (else the single graph 0)
    exchange_steps: i64()  # Euler steps between O-O broadcasts, oo_period / dt (1 if continuous)
    continuous: b1()  # oo_period None: r_e refreshed at every evaluation (also in split steps)
    oo_loss: f64()
    burst: b1()  # Gilbert-Elliott losses (then oo_loss is 0)
    p_good_bad: f64()
    p_bad_good: f64()
    loss_good: f64()
    loss_bad: f64()
    stationary_bad: f64()  # P(bad) of the first period
    oo_delay: i64()  # control periods
    lag: i64()  # broadcasts between a snapshot and its arrival, ceil(oo_delay substeps / exchange_steps)
    ring: i64()  # snapshots kept per node, lag + 1
    co_loss: f64()
    co_delay: i64()  # control periods
    noise_std: f64()
    noise_mask: f64("N P")  # 1 for the real rows of C_i, 0 for zero padding rows
    substeps: i64()  # Euler steps per control period


class FaultState(NamedTuple):
    """Per-copy state of the fault model, batch first (module doc). ``K`` C-O links, ``R = ring``.

    Attributes
    ----------
    seed : (B,) uint64
        The copy's fault seed (all its draws, :mod:`.fault_rng`).
    period : (B,) int64
        Control periods since the copy's reset (Euler step ``s = period * substeps + j``).
    received : (B, E, n)
        ``r_e``: the last estimate of ``sender[e]`` received by ``receiver[e]``.
    snapshots : (B, R, N, n)
        Ring of broadcast snapshots per sender: broadcast ``q`` (``s = q * exchange_steps``) in slot
        ``q % R`` (used when ``oo_delay > 0``; filled with the ``t = 0`` estimates at reset).
    bad : (B, E) bool
        Gilbert-Elliott state of each link in the current period (True: bad).
    graph : (B,) int64
        Active graph in the current period.
    noise : (B, N, P)
        Measurement noise held over the current period (zeros when ``measurement_noise = 0``).
    co_sent : (B, co_delay + 1, K, n)
        Ring of the estimates sent over the C-O links: boundary ``k`` in slot ``k % (co_delay + 1)``.
    co_held : (B, K, n)
        The estimate each controller holds (last received).
    """

    seed: np.ndarray
    period: np.ndarray
    received: np.ndarray
    snapshots: np.ndarray
    bad: np.ndarray
    graph: np.ndarray
    noise: np.ndarray
    co_sent: np.ndarray
    co_held: np.ndarray

    def replace(self, **changes) -> "FaultState":
        return self._replace(**changes)


def _adjacency_of(params) -> np.ndarray:
    """The scenario's adjacency ``a_ij`` from the Laplacian of ``params`` (exact: ``-(-a_ij)``)."""
    adj = -np.array(params.laplacian, dtype=np.float64)
    np.fill_diagonal(adj, 0.0)
    return adj


def fault_args(faults: Faults, params) -> FaultArgs:
    """Resolve ``faults`` against ``params`` (:class:`~dobs_envs.sim.state.SimParams`): the links of the
    union of the graphs, the exchange period in Euler steps (``ValueError`` naming ``oo_period`` unless
    it is a positive integer multiple of ``params.dt``), the ring lengths, the graph chain's transition
    matrix per control period. ``ValueError`` naming ``switching`` when its graphs do not have the
    scenario's ``N`` nodes."""
    if not isinstance(faults, Faults):
        raise TypeError(f"fault_args: faults must be a Faults (Faults.from_value), got {type(faults).__name__}")
    N, P = params.n_nodes, params.C.shape[1]
    S = params.substeps
    M = faults.exchange_steps(params.dt)
    sw = faults.switching
    if sw is not None:
        if sw.n_nodes != N:
            raise ValueError(f"faults: switching graphs have {sw.n_nodes} nodes, the scenario's observer network {N}")
        adjs = np.stack(sw.graphs)
        T = sw.transition_matrix(params.control_period)
        initial = sw.initial
        degree = adjs.sum(axis=2)
    else:
        adjs = _adjacency_of(params)[None]
        T = np.ones((1, 1))
        initial = 0
        degree = np.array(np.diagonal(params.laplacian))[None]  # the exact diagonal control_period_numpy uses
    union = np.any(adjs > 0, axis=0)
    receiver, sender = np.nonzero(union)  # row-major: by receiver, then sender
    weight = adjs[:, receiver, sender]
    cum = np.cumsum(T, axis=1)
    last = np.array([int(np.flatnonzero(row > 0)[-1]) for row in T], dtype=np.int64)
    burst = faults.oo_burst
    D = faults.oo_delay
    lag = -(-D * S // M) if D > 0 else 0
    mask = np.array(np.any(params.C != 0, axis=2), dtype=np.float64)  # (N, P): real rows of C_i
    return FaultArgs(
        sender=np.ascontiguousarray(sender, dtype=np.int64), receiver=np.ascontiguousarray(receiver, dtype=np.int64),
        weight=np.ascontiguousarray(weight, dtype=np.float64), degree=np.ascontiguousarray(degree, dtype=np.float64),
        cum_transition=np.ascontiguousarray(cum), last_state=last, initial_graph=int(initial),
        switching=sw is not None, exchange_steps=int(M), continuous=faults.oo_period is None,
        oo_loss=float(faults.oo_loss), burst=burst is not None,
        p_good_bad=burst.p_good_bad if burst else 0.0, p_bad_good=burst.p_bad_good if burst else 0.0,
        loss_good=burst.loss_good if burst else 0.0, loss_bad=burst.loss_bad if burst else 0.0,
        stationary_bad=burst.stationary_bad if burst else 0.0,
        oo_delay=int(D), lag=int(lag), ring=int(lag + 1), co_loss=float(faults.co_loss), co_delay=int(faults.co_delay),
        noise_std=float(faults.measurement_noise), noise_mask=mask, substeps=int(S),
    )


def period_draws(fa: FaultArgs, seed, period, graph_prev, bad_prev):
    """The draws of control period ``period`` (per copy, ``(B,)``): the active graph, the burst states and
    the measurement noise.

    Period 0: graph ``initial_graph``, burst states from the stationary distribution, noise. Later
    periods: one step of the graph chain from ``graph_prev (B,)`` and of each link's burst chain from
    ``bad_prev (B, E)``, noise. Returns ``graph (B,) int64``, ``bad (B, E) bool``, ``noise (B, N, P)``.
    """
    seed = np.asarray(seed, dtype=np.uint64)
    period = np.asarray(period, dtype=np.int64)
    B = seed.shape[0]
    first = period == 0
    E = fa.sender.shape[0]
    N, P = fa.noise_mask.shape
    graph = np.asarray(graph_prev, dtype=np.int64).copy()
    if fa.switching:
        u = rng.uniform(seed, rng.STREAM_SWITCHING, period, 0)
        cum = fa.cum_transition[graph]  # (B, G) rows of the current graphs
        nxt = np.sum(cum <= (u * cum[:, -1])[:, None], axis=1)
        nxt = np.minimum(nxt, fa.last_state[graph])
        graph = np.where(first, fa.initial_graph, nxt)
    else:
        graph[:] = 0
    bad = np.asarray(bad_prev, dtype=bool).copy()
    if fa.burst:
        u = rng.uniform(seed[:, None], rng.STREAM_OO_BURST, period[:, None], np.arange(E)[None, :])
        stay = np.where(bad, u >= fa.p_bad_good, u < fa.p_good_bad)  # bad: stays unless it recovers
        bad = np.where(first[:, None], u < fa.stationary_bad, stay)
    else:
        bad[:] = False
    if fa.noise_std > 0:
        z = rng.normal(seed[:, None], rng.STREAM_NOISE, period[:, None], np.arange(N * P)[None, :])
        noise = fa.noise_std * z.reshape(B, N, P) * fa.noise_mask
    else:
        noise = np.zeros((B, N, P))
    return graph, bad, noise


def oo_losses(fa: FaultArgs, fs: FaultState) -> np.ndarray:
    """``(B, E)`` bool: the directed O-O links losing their packets in the current period of each copy
    (probability ``oo_loss``, or ``loss_bad`` / ``loss_good`` by burst state)."""
    B, E = fs.seed.shape[0], fa.sender.shape[0]
    if fa.burst:
        p = np.where(fs.bad, fa.loss_bad, fa.loss_good)
    else:
        p = np.full((B, E), fa.oo_loss)
    if not np.any(p > 0):
        return np.zeros((B, E), dtype=bool)
    u = rng.uniform(fs.seed[:, None], rng.STREAM_OO_LOSS, fs.period[:, None], np.arange(E)[None, :])
    return u < p


def faulted_outputs(x, params, noise) -> np.ndarray:
    """Measured outputs ``y_i = C_i x + n_i`` (eq. (localmeasure) plus the held noise), ``(B, N, P)``."""
    y = np.einsum("ipn,bn->bip", params.C, x)
    return y if noise is None else y + noise


def faulted_estimates(x, z, params, fs: FaultState | None = None) -> np.ndarray:
    """Estimates ``xhat_i = z_i + Gbar_i (C_i x + n_i)`` (eq. (hatxieq) with the period's measurement noise
    of ``fs``; ``fs`` None: no noise), ``(B, N, n)``: what the nodes broadcast and send to the controllers."""
    noise = None if fs is None or not np.any(fs.noise) else fs.noise
    return z + np.einsum("inp,bip->bin", params.G_bar, faulted_outputs(x, params, noise))


def init_fault_state(params, fa: FaultArgs, x, z, seeds, co_nodes=None, *, draws=None) -> FaultState:
    """The fault state of ``B`` copies at reset (period 0).

    Parameters
    ----------
    params : SimParams
    fa : FaultArgs of ``params`` (:func:`fault_args`).
    x : (B, n) initial plant states.  z : (B, N, n) initial observer states.
    seeds : (B,) non-negative integers below ``2**64`` (or one for every copy): each copy's fault seed.
    co_nodes : (K,) int, optional
        The observer node whose estimate each C-O link carries (default: every node, ``K = N``).
    draws : callable, optional
        :func:`period_draws` (the default) or a function with its arguments and bitwise its results
        (:func:`dobs_envs.sim.fault_kernel.period_draws_compiled`: the environments' resets).

    The period-0 draws are made (:func:`period_draws`), then every link holds the sender's ``t = 0``
    estimate (with the period's noise), every snapshot slot holds it, and so do the C-O buffers.
    """
    x = np.asarray(x, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    B = x.shape[0]
    N, n = params.n_nodes, params.n_states
    if z.shape != (B, N, n):
        raise ValueError(f"z must have shape ({B}, {N}, {n}), got {z.shape}")
    seed = rng.as_seeds(seeds, B)
    co_nodes = np.arange(N) if co_nodes is None else np.asarray(co_nodes)
    if co_nodes.ndim != 1 or co_nodes.dtype.kind not in "iu" or np.any(co_nodes < 0) or np.any(co_nodes >= N):
        raise ValueError(f"co_nodes must be a 1-D array of observer node indices in [0, {N}), got {co_nodes!r}")
    E = fa.sender.shape[0]
    period = np.zeros(B, dtype=np.int64)
    graph, bad, noise = (period_draws if draws is None else draws)(fa, seed, period, np.zeros(B, dtype=np.int64),
                                                                  np.zeros((B, E), dtype=bool))
    xhat0 = z + np.einsum("inp,bip->bin", params.G_bar, faulted_outputs(x, params, noise if fa.noise_std > 0 else None))
    K, Lc = co_nodes.shape[0], fa.co_delay + 1
    return FaultState(
        seed=seed, period=period,
        received=np.ascontiguousarray(xhat0[:, fa.sender]),
        snapshots=np.ascontiguousarray(np.broadcast_to(xhat0[:, None], (B, fa.ring, N, n))),
        bad=bad, graph=graph, noise=noise,
        co_sent=np.ascontiguousarray(np.broadcast_to(xhat0[:, None, co_nodes], (B, Lc, K, n))),
        co_held=np.ascontiguousarray(xhat0[:, co_nodes]),
    )


def co_link_numpy(sent, fs: FaultState, fa: FaultArgs):
    """The C-O links at the boundary of period ``fs.period`` (module doc of :mod:`.faults`).

    Parameters
    ----------
    sent : (B, K, n)
        The estimates the observer nodes send now (link ``l`` carries its node's estimate,
        :func:`faulted_estimates` at this boundary).
    fs : FaultState (its ``period`` is the boundary's index ``k``).  fa : FaultArgs.

    Returns
    -------
    held : (B, K, n)
        What each controller reads: the estimate sent at boundary ``k - co_delay`` (the ``t = 0``
        one before), or, if the link loses this period's packet (probability ``co_loss``), the
        estimate it held before.
    fs : FaultState with the C-O buffers updated (call once per boundary; the period counter is
        advanced by the control period).
    """
    sent = np.asarray(sent, dtype=np.float64)
    B, K = fs.co_held.shape[:2]
    if sent.shape != fs.co_held.shape:
        raise ValueError(f"sent must have shape {fs.co_held.shape} (copies, C-O links, n), got {sent.shape}")
    Lc = fa.co_delay + 1
    k = fs.period
    rows = np.arange(B)
    co_sent = fs.co_sent.copy()
    co_sent[rows, k % Lc] = sent
    arrived = co_sent[rows, (k - fa.co_delay) % Lc]  # not yet written before co_delay boundaries: t = 0
    if fa.co_loss > 0:
        lost = rng.uniform(fs.seed[:, None], rng.STREAM_CO_LOSS, k[:, None], np.arange(K)[None, :]) < fa.co_loss
        held = np.where(lost[..., None], fs.co_held, arrived)
    else:
        held = arrived.copy()
    return held, fs.replace(co_sent=co_sent, co_held=held)
