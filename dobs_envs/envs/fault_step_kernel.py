"""One environment step of every copy with communication faults (issue 23): the compiled step of
:class:`~dobs_envs.envs.env_core.EnvCore` when its ``faults`` option is not None.

:func:`advance_batch_faulted` / :func:`advance_range_faulted` are
:func:`~dobs_envs.envs.step_kernel.advance_batch` / ``advance_range`` with the faulted control
period (:func:`dobs_envs.sim.fault_kernel.advance_rows_faulted`) and, after the features of the copies
(:func:`~dobs_envs.envs.features.features_row`), :func:`fault_rows`: what the agents observe at the
control-period boundary (``faults=None`` runs ``step_kernel`` unchanged):

- measured outputs and estimates with the period's held measurement noise:
  ``y_i = C_i x + n_i``, ``xhat_i = z_i + Gbar_i y_i`` (the feature vector's ``y`` and ``xhat``
  entries and the estimation errors ``||xhat_i - x||`` are those of the noisy measurement, the
  draw the observer node uses);
- the C-O link (:func:`~dobs_envs.sim.fault_kernel.co_link_rows`): controller ``k`` reads the
  estimate it holds, ``xhat_rx[k]`` (delayed, or the last received when this boundary's packet is
  lost); ``co_rx[k]`` is 1 when this boundary's packet arrived;
- the O-O copies node ``i`` holds at the boundary instant, ``nbr_rx[e]`` for each link
  ``e = (j -> i)``: the value received at the boundary's own broadcast when one is due (the
  boundary is an exchange instant and the link delivers in the starting period: its graph, its
  loss draw) -- ``oo_rx[e] = 1`` -- else the value held from an earlier broadcast,
  ``oo_rx[e] = 0`` (stale). Nothing in the fault state is changed by this read (the period's
  kernel makes the same broadcast at its first Euler step).

The observation gathers are then redone for the copy. The readable numpy reference is
:func:`dobs_envs.envs.numpy_advance.advance_reference_faulted`.
"""
from __future__ import annotations

import numpy as np

from ..numba_cache import ensure_fresh
from ..sim.fault_kernel import _fields, advance_rows_faulted, co_link_rows, delivers, loss_key, unpack_fault_args
from ..sim.kernel_args import StateArrays
from ..sim.period_kernel import unpack_kernel_args
from .features import features_row, unpack_static
from .step_kernel import StepConsts, apply_inputs, finish_row, first_non_finite

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

import numba as _numba  # noqa: E402

_njit = _numba.njit(cache=True, fastmath=False, nogil=True)
_njit_inline = _numba.njit(cache=True, fastmath=False, nogil=True, inline="always")

__all__ = ["advance_batch_faulted", "advance_range_faulted", "fault_rows", "fault_features", "ROWS_CHUNK"]


#: copies whose features, faulted observations and step results are written together by
#: :func:`advance_range_faulted` (their rows stay in the cache between the three passes)
ROWS_CHUNK = 64


@_njit
def fault_rows(lo, hi, st, W, fa, ff, fs, rx, fconsts, obs2, link):
    """The faulted observations of copies ``lo .. hi-1`` at a boundary (module doc), after ``features_row``.

    ``fa`` :class:`~dobs_envs.envs.features.FeatureArgs`; ``ff`` the unpacked
    :class:`~dobs_envs.sim.fault_state.FaultArgs`; ``fs`` the fault-state tuple; ``rx = (co_rx (B, K),
    oo_rx (B, E))`` bool, written; ``fconsts = (co_nodes (K,), foff (4,))`` with ``foff`` the offsets
    of ``xhat_rx``, ``nbr_rx``, ``co_rx``, ``oo_rx`` in the feature vector; ``link``: run the C-O link
    (False at reset: every controller holds the ``t = 0`` estimate, received).

    One call for a range of copies, in three passes over it (noisy estimates; the C-O links,
    :func:`~dobs_envs.sim.fault_kernel.co_link_rows`; held copies, masks and the gathers): the arrays
    are taken out of the tuples once per call (per copy, each unpacked array cost an atomic reference
    count update on entry and exit). Each copy's values are those of its own row only.
    """
    x, z = st.x, st.z
    C, G, off, idx, F = fa.C, fa.G, fa.off, fa.idx, fa.F
    co_nodes, foff = fconsts
    co_rx, oo_rx = rx
    seed_a, period_a, received_a, snapshots_a, bad_a, graph_a, noise_a, co_sent_a, co_held_a = _fields(fs)
    N, n = z.shape[1], z.shape[2]
    p = C.shape[1]
    K = co_nodes.shape[0]
    sender = ff.sender
    E = sender.shape[0]
    oxh = off[1]
    if ff.noise_std > 0.0:  # y_i = C_i x + n_i, xhat_i = z_i + Gbar_i y_i (features_row's order, plus n_i)
        y = np.empty(p)
        for b in range(lo, hi):
            oy = off[0]
            for i in range(N):
                for q in range(p):
                    s = 0.0
                    for l in range(n):
                        s += C[i, q, l] * x[b, l]
                    y[q] = s + noise_a[b, i, q]
                pi = off[10 + i]
                for q in range(pi):
                    W[b, oy + q] = y[q]
                oy += pi
                ss = 0.0
                for k in range(n):
                    s = 0.0
                    for q in range(p):
                        s += G[i, k, q] * y[q]
                    xh = z[b, i, k] + s
                    W[b, oxh + i * n + k] = xh
                    dd = xh - x[b, k]
                    ss += dd * dd
                W[b, F + i] = np.sqrt(ss)
    # the C-O links (the estimates xhat_i of the feature vector: W[b, oxh + i n ...])
    if link:
        co_link_rows(lo, hi, W, 0, oxh, co_nodes, ff, fs, co_rx)
    else:
        for b in range(lo, hi):
            for l in range(K):
                co_rx[b, l] = True
    # the O-O copies held at the boundary instant (a broadcast due now delivers on the starting period's links)
    S, M, lag, ring, continuous = ff.substeps, ff.exchange_steps, ff.lag, ff.ring, ff.continuous
    for b in range(lo, hi):
        o = foff[0]
        for l in range(K):
            for c in range(n):
                W[b, o + l * n + c] = co_held_a[b, l, c]
            W[b, foff[2] + l] = 1.0 if co_rx[b, l] else 0.0
        k = period_a[b]
        s_ = k * S
        due = continuous or s_ % M == 0
        old = (s_ // M - lag) % ring
        o = foff[1]
        key = loss_key(seed_a, b, k)
        g = graph_a[b]
        for e in range(E):
            fresh = due and delivers(b, e, ff, key, bad_a, g)
            oo_rx[b, e] = fresh
            W[b, foff[3] + e] = 1.0 if fresh else 0.0
            js = sender[e]
            for c in range(n):
                if not fresh:
                    val = received_a[b, e, c]
                elif lag > 0:
                    val = snapshots_a[b, old, js, c]
                else:
                    val = W[b, oxh + js * n + c]
                W[b, o + e * n + c] = val
        for j in range(idx.shape[0]):
            obs2[b, j] = W[b, idx[j]]


@_njit
def fault_features(rows, state, W, obs, SF, SI, FF, FI, fs, rx, fconsts):
    """:func:`fault_rows` (without the C-O link) of the copies ``rows``, after
    :func:`~dobs_envs.envs.features.write_features` (reset and ``set_sim_state``)."""
    fa = unpack_static(SF, SI)
    ff = unpack_fault_args(FF, FI)
    st = StateArrays(*state)
    obs2 = obs.reshape((obs.shape[0], obs.shape[1] * obs.shape[2]))
    for r in range(rows.shape[0]):
        fault_rows(rows[r], rows[r] + 1, st, W, fa, ff, fs, rx, fconsts, obs2, False)


@_njit
def advance_range_faulted(lo, hi, state, W, obs, outs, u, sig, ka, SF, SI, consts, fp, fs, rx, fconsts):
    """:func:`~dobs_envs.envs.step_kernel.advance_range` with faults (module doc): ``fp = (FF, FI)`` the
    packed :class:`~dobs_envs.sim.fault_state.FaultArgs`, ``fs`` the fault-state tuple (updated),
    ``rx = (co_rx (B, K), oo_rx (B, E))`` the received masks (written), ``fconsts = (co_nodes, foff)``.

    After the period, per chunk of :data:`ROWS_CHUNK` copies: their features (``features_row``), their
    faulted observations (:func:`fault_rows`), then reward and termination (``finish_row``, from the
    stored cost, ``||x||`` and finiteness): per copy the order of the unfaulted step with ``fault_rows``
    between ``features_row`` and ``finish_row``."""
    KF, KI = ka
    ka = unpack_kernel_args(KF, KI)
    ff = unpack_fault_args(fp[0], fp[1])
    fa = unpack_static(SF, SI)
    c = StepConsts(*consts)
    st = StateArrays(*state)
    t, x, z, gamma, gamma_s, v, x_r = st.t, st.x, st.z, st.gamma, st.gamma_s, st.v, st.x_r
    outf, outb, reason, cycles = outs
    cost, err, xnorm = outf[1], outf[2], outf[3]
    finite = outb[0]
    F = fa.F
    N = z.shape[1]
    m = u.shape[1]
    ou = F + N
    o_r = fa.off[7]
    apply_inputs(lo, hi, t, v, W, u, sig, ou, c)
    delivered = np.empty((x.shape[0], ff.sender.shape[0]), dtype=np.bool_)  # the period's (not observed)
    advance_rows_faulted(x, z, gamma, gamma_s, v, x_r, W[:, ou:ou + m], W[:, o_r:o_r + m], ka, ff, fs, delivered,
                         lo, hi)
    obs2 = obs.reshape((obs.shape[0], obs.shape[1] * obs.shape[2]))
    y = np.empty(fa.C.shape[1])
    for b0 in range(lo, hi, ROWS_CHUNK):
        b1 = min(b0 + ROWS_CHUNK, hi)
        for b in range(b0, b1):
            t[b] = t[b] + c.period
            cycles[b] += 1
            cb, e, xn, fin = features_row(b, st, W, fa, c.has_ref, obs2, y)
            cost[b] = cb
            err[b] = e
            xnorm[b] = xn
            finite[b] = fin
        fault_rows(b0, b1, st, W, fa, ff, fs, rx, fconsts, obs2, True)
        for b in range(b0, b1):
            finish_row(b, cost[b], xnorm[b], finite[b], x, W, F, obs2, outs, c)


@_njit
def advance_batch_faulted(state, W, obs, outs, u, sig, ka, SF, SI, consts, fp, fs, rx, fconsts):
    """:func:`~dobs_envs.envs.step_kernel.advance_batch` with faults (arguments of
    :func:`advance_range_faulted`); -1 or the first copy whose input is not finite (nothing modified)."""
    bad = first_non_finite(u)
    if bad >= 0:
        return bad
    # np.int64(0), not 0: a literal would compile a second advance_range_faulted besides the threads' one
    advance_range_faulted(np.int64(0), u.shape[0], state, W, obs, outs, u, sig, ka, SF, SI, consts, fp, fs, rx,
                          fconsts)
    return -1
