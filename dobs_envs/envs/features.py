"""Compiled feature/observation/cost kernel of the environments (batched over copies).

For every copy ``b`` of a batch, :func:`write_features` computes from the
simulation arrays, in one compiled call,

- eq. (localmeasure): ``y_i = C_i x`` (node ``i`` keeps its first ``p_i`` rows),
- eq. (hatxieq): ``xhat_i = z_i + Gbar_i y_i`` and the estimation errors ``||xhat_i - x||``,
- the reference command of eq. (refxdy): ``r_j(t) = a_j sin(w_j t + phi_j)`` (tracking only),
- the task error ``e = x - x_r`` (tracking) or ``e = x``,
- the stage cost ``e'Qe + u'Ru`` (``u`` the applied input), ``||e||``, ``||x||``,
- whether the whole simulated state (``x``, ``x_r``, ``z``, ``gamma``, ``gamma_s``, ``v``) is finite,

writes them into the copy's *work row* ``W[b] = [f (F) | est (N) | u (m)]`` (``f`` the
feature vector of :mod:`dobs_envs.envs.observation`) and gathers all agents' padded
observations ``obs[b] = f[padded_index]`` (shape ``(K, D)``). The readable numpy
reference with the same signature is :func:`dobs_envs.envs.numpy_features.write_features_reference`
(parity-tested over a closed-loop run). No fast-math: the finiteness test must see NaN/inf.
"""
from __future__ import annotations

import numpy as np

from typing import NamedTuple

from ..numba_cache import ensure_fresh
from ..packing import compiled_unpack, f64, i64, pack
from ..sim.fault_kernel import co_link_rows, delivers, loss_key, unpack_fault_args
from ..sim.fault_state import FaultArgs, FaultState
from ..sim.kernel_args import StateArrays

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

try:
    import numba as _numba

    _njit = _numba.njit(cache=True, fastmath=False, nogil=True)
    _njit_inline = _numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
except ImportError:  # pragma: no cover
    def _njit(f):
        return f

    _njit_inline = _njit

__all__ = ["FeatureArgs", "Offsets", "P_SIZES", "offsets", "EnvFault", "env_fault", "pack_static", "unpack_static", "features_row", "write_features",
           "fault_rows", "fault_features", "flops_per_row"]


class FeatureArgs(NamedTuple):
    """The constants of the feature kernel (declaration: :mod:`dobs_envs.packing`), passed packed
    as ``(SF, SI)`` (:func:`pack_static`) and read by name in compiled code (:func:`unpack_static`)."""

    F: i64()  # feature-vector length
    C: f64("N p n")  # padded output matrices, eq. (localmeasure)
    G: f64("N n p")  # Gbar, eq. (hatxieq)
    ref: f64("3 m")  # amplitude, frequency, phase of r(t), eq. (refxdy)
    Q: f64("n n")  # cost weights
    R: f64("m m")
    off: i64("o")  # offsets of FeatureLayout.offsets: (y, xhat, x, x_r, gamma, gamma_s, v, r, time, e), then p_i
    idx: i64("k")  # the flattened (K, D) padded gather


class Offsets(NamedTuple):
    """Where each block of the feature vector starts (the first entries of ``FeatureArgs.off``, in the order
    of :meth:`~dobs_envs.envs.observation.FeatureLayout.offsets`), read by name (:func:`offsets`)."""

    y: int
    xhat: int
    x: int
    x_r: int
    gamma: int
    gamma_s: int
    v: int
    r: int
    time: int
    e: int


#: where the output sizes ``p_i`` start in ``FeatureArgs.off`` (after the :class:`Offsets`)
P_SIZES = len(Offsets._fields)


@_njit_inline
def offsets(off):
    """The :class:`Offsets` of ``FeatureArgs.off`` (its first :data:`P_SIZES` entries)."""
    return Offsets(off[0], off[1], off[2], off[3], off[4], off[5], off[6], off[7], off[8], off[9])


def pack_static(C, G, ref, Q, R, off, idx, F):
    """The kernel's constant arrays (:class:`FeatureArgs`) packed into one float and one int buffer
    ``(SF, SI)`` (fewer arguments = cheaper compiled-call dispatch on the per-step path).

    ``C (N, p, n)``/``G (N, n, p)`` padded design arrays; ``ref (3, m)`` amplitude,
    frequency, phase of ``r(t)``; ``Q (n, n)``, ``R (m, m)``; ``off`` the offsets of
    :meth:`FeatureLayout.offsets`; ``idx`` the flattened ``(K, D)`` padded gather; ``F``
    the feature-vector length.
    """
    return pack(FeatureArgs(F=int(F), C=C, G=G, ref=ref, Q=Q, R=R, off=np.asarray(off, dtype=np.int64),
                            idx=np.asarray(idx, dtype=np.int64).ravel()))


#: ``unpack_static(SF, SI)``: the :class:`FeatureArgs` packed by :func:`pack_static` (views), compiled
#: from source generated from the declaration (:func:`dobs_envs.packing.compiled_unpack`).
unpack_static = compiled_unpack(FeatureArgs, _njit, "unpack_static")


@_njit_inline
def features_row(b, st, W, fa, has_ref, obs2, y, noise):
    """Copy ``b`` of the state ``st`` (:class:`~dobs_envs.sim.kernel_args.StateArrays`): fill ``W[b]``
    and ``obs2[b] (K * D)`` with the constants ``fa`` (:class:`FeatureArgs`); return
    ``(cost, ||e||, ||x||, finite)`` (``y (p,)`` is scratch).

    Same arithmetic order as :func:`dobs_envs.sim.estimates`: ``y_i = C_i x``,
    ``xhat_i = z_i + G_i y_i``; with communication faults and measurement noise, ``noise (B, N, p)`` the
    held noise of the period, ``y_i = C_i x + n_i`` (the draw the observer node uses; ``None``: no noise). ``finite`` is accumulated as ``sum(value * 0)``, which is 0
    exactly when every state entry is finite (``inf * 0`` and ``NaN * 0`` are NaN).
    """
    x, z, x_r, gamma, gamma_s, v, t = st.x, st.z, st.x_r, st.gamma, st.gamma_s, st.v, st.t
    F, C, G, ref, Q, R, off, idx = fa.F, fa.C, fa.G, fa.ref, fa.Q, fa.R, fa.off, fa.idx
    N, n = z.shape[1], z.shape[2]
    p = C.shape[1]
    m = R.shape[0]
    nonfin = 0.0
    o = offsets(off)
    oy = o.y
    oxh = o.xhat
    for i in range(N):
        for q in range(p):
            s = 0.0
            for l in range(n):
                s += C[i, q, l] * x[b, l]
            if noise is None:
                y[q] = s
            else:
                y[q] = s + noise[b, i, q]
        pi = off[P_SIZES + i]
        for q in range(pi):
            W[b, oy + q] = y[q]
        oy += pi
        ss = 0.0
        for k in range(n):
            s = 0.0
            for q in range(p):
                s += G[i, k, q] * y[q]
            zk = z[b, i, k]
            nonfin += zk * 0.0
            xh = zk + s
            W[b, oxh + i * n + k] = xh
            d = xh - x[b, k]
            ss += d * d
        W[b, F + i] = np.sqrt(ss)
    xx = 0.0
    ee = 0.0
    for k in range(n):
        xk = x[b, k]
        xrk = x_r[b, k]
        W[b, o.x + k] = xk
        W[b, o.x_r + k] = xrk
        xx += xk * xk
        nonfin += xk * 0.0 + xrk * 0.0
        e = xk - xrk if has_ref else xk
        W[b, o.e + k] = e
        ee += e * e
    for i in range(N):
        W[b, o.gamma + i] = gamma[b, i]
        W[b, o.gamma_s + i] = gamma_s[b, i]
        nonfin += gamma[b, i] * 0.0 + gamma_s[b, i] * 0.0
    for j in range(v.shape[1]):
        W[b, o.v + j] = v[b, j]
        nonfin += v[b, j] * 0.0
    tb = t[b]
    if has_ref:
        for j in range(ref.shape[1]):
            W[b, o.r + j] = ref[0, j] * np.sin(ref[1, j] * tb + ref[2, j])
    W[b, o.time] = tb
    oe = o.e
    cost = 0.0
    for k in range(n):
        s = 0.0
        for l in range(n):
            s += Q[k, l] * W[b, oe + l]
        cost += W[b, oe + k] * s
    ou = F + N
    for k in range(m):
        s = 0.0
        for l in range(m):
            s += R[k, l] * W[b, ou + l]
        cost += W[b, ou + k] * s
    for j in range(idx.shape[0]):
        obs2[b, j] = W[b, idx[j]]
    return cost, np.sqrt(ee), np.sqrt(xx), nonfin == 0.0


@_njit
def write_features(rows, state, W, obs, SF, SI, has_ref, out):
    """Features, observations and cost of the copies ``rows`` (see module docstring).

    Parameters
    ----------
    rows : (k,) int copies to process.
    state : the plain tuple of :class:`~dobs_envs.sim.kernel_args.StateArrays`' fields
        ``(t (B,), x (B, n), z (B, N, n), gamma (B, N), gamma_s (B, N), v (B, m_v), x_r (B, n))`` (read).
    W : (B, F + N + m) work rows ``[f | est | u]``, written (``u`` is read; the constant
        0/1 entries of ``f`` are left as they are).
    obs : (B, K, D) padded observations (float32 or float64), written.
    SF, SI : static arrays of :func:`pack_static`.
    has_ref : bool, tracking task (reference command and ``e = x - x_r``).
    out : ``(cost, err, xnorm, finite)``, (B,) float64 x 3 and (B,) bool, written at ``rows``:
        ``e'Qe + u'Ru``, ``||e||``, ``||x||`` and the finiteness flag.
    """
    fa = unpack_static(SF, SI)
    st = StateArrays(*state)
    cost, err, xnorm, finite = out
    obs2 = obs.reshape((obs.shape[0], obs.shape[1] * obs.shape[2]))
    y = np.empty(fa.C.shape[1])
    for r in range(rows.shape[0]):
        b = rows[r]
        c, e, xn, fin = features_row(b, st, W, fa, has_ref, obs2, y, None)
        cost[b] = c
        err[b] = e
        xnorm[b] = xn
        finite[b] = fin


class EnvFault(NamedTuple):
    """The communication faults of an environment step in compiled code (:func:`env_fault`)."""

    args: FaultArgs  # unpacked constants
    state: FaultState  # the copies' fault state (updated)
    co_rx: np.ndarray  # (B, K) bool: the C-O packet of each controller arrived at the boundary (written)
    oo_rx: np.ndarray  # (B, E) bool: link e's copy at the boundary is this boundary's broadcast (written)
    co_nodes: np.ndarray  # (K,) the node each controller reads over its C-O link
    offsets: np.ndarray  # (4,) offsets of xhat_rx, nbr_rx, co_rx, oo_rx in the feature vector


@_njit
def env_fault(fault):
    """:class:`EnvFault` of the plain tuple ``(fp, fs, rx, fconsts)`` an environment passes: ``fp = (FF, FI)``
    the packed :class:`~dobs_envs.sim.fault_state.FaultArgs`, ``fs`` the fault-state tuple (FaultState
    order), ``rx = (co_rx, oo_rx)``, ``fconsts = (co_nodes, offsets)`` (plain tuples: cheaper to dispatch)."""
    fp, fs, rx, fconsts = fault
    FF, FI = fp
    co_rx, oo_rx = rx
    co_nodes, offsets = fconsts
    return EnvFault(unpack_fault_args(FF, FI), FaultState(*fs), co_rx, oo_rx, co_nodes, offsets)


@_njit
def fault_rows(lo, hi, st, W, obs2, fa, fault, link):
    """What the agents observe at a boundary with faults, copies ``lo .. hi-1``, after :func:`features_row`
    (with the held noise: ``y_i = C_i x + n_i``, ``xhat_i = z_i + Gbar_i y_i`` and the estimation errors
    are those of the noisy measurement):

    - the C-O link (:func:`~dobs_envs.sim.fault_kernel.co_link_rows`; ``link`` False at a reset: every
      controller holds the ``t = 0`` estimate, received): controller ``k`` reads the estimate it holds,
      ``xhat_rx[k]``; ``co_rx[k]`` is 1 when this boundary's packet arrived;
    - the O-O copies node ``i`` holds at the boundary instant, ``nbr_rx[e]`` for each link ``e = (j -> i)``:
      the value received at the boundary's own broadcast when one is due (the boundary is an exchange
      instant and the link delivers in the starting period) -- ``oo_rx[e] = 1`` -- else the value held
      from an earlier broadcast (``oo_rx[e] = 0``, stale). Nothing in the fault state is changed by this
      read (the period's kernel makes the same broadcast at its first Euler step);
    - then the observation gathers again.

    ``fa`` :class:`FeatureArgs`; ``fault`` :class:`EnvFault`. One call for a range of copies, in two passes
    (the C-O links, then held copies, masks and the gathers); each copy's values are those of its own row.
    """
    ff, fs = fault.args, fault.state
    co_rx, oo_rx, co_nodes, foff = fault.co_rx, fault.oo_rx, fault.co_nodes, fault.offsets
    o_xhat_rx, o_nbr_rx, o_co_rx, o_oo_rx = foff[0], foff[1], foff[2], foff[3]
    seed_a, period_a, received_a, snapshots_a, bad_a, graph_a = fs.seed, fs.period, fs.received, fs.snapshots, fs.bad, fs.graph
    co_held_a = fs.co_held
    idx = fa.idx
    n = st.z.shape[2]
    K = co_nodes.shape[0]
    sender = ff.sender
    E = sender.shape[0]
    oxh = offsets(fa.off).xhat
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
        for l in range(K):
            for c in range(n):
                W[b, o_xhat_rx + l * n + c] = co_held_a[b, l, c]
            W[b, o_co_rx + l] = 1.0 if co_rx[b, l] else 0.0
        k = period_a[b]
        s_ = k * S
        due = continuous or s_ % M == 0
        old = (s_ // M - lag) % ring
        key = loss_key(seed_a, b, k)
        g = graph_a[b]
        for e in range(E):
            fresh = due and delivers(b, e, ff, key, bad_a, g)
            oo_rx[b, e] = fresh
            W[b, o_oo_rx + e] = 1.0 if fresh else 0.0
            js = sender[e]
            for c in range(n):
                if not fresh:
                    val = received_a[b, e, c]
                elif lag > 0:
                    val = snapshots_a[b, old, js, c]
                else:
                    val = W[b, oxh + js * n + c]
                W[b, o_nbr_rx + e * n + c] = val
        for j in range(idx.shape[0]):
            obs2[b, j] = W[b, idx[j]]


@_njit
def fault_features(rows, state, W, obs, SF, SI, has_ref, fault):
    """The features with the held noise and :func:`fault_rows` (without the C-O link) of the copies ``rows``,
    after :func:`write_features` (reset and ``set_sim_state``); ``fault`` the plain tuple of
    :func:`env_fault`."""
    fa = unpack_static(SF, SI)
    ef = env_fault(fault)
    st = StateArrays(*state)
    obs2 = obs.reshape((obs.shape[0], obs.shape[1] * obs.shape[2]))
    y = np.empty(fa.C.shape[1])
    noisy = ef.args.noise_std > 0.0
    for r in range(rows.shape[0]):
        b = rows[r]
        if noisy:
            features_row(b, st, W, fa, has_ref, obs2, y, ef.state.noise)
        fault_rows(b, b + 1, st, W, obs2, fa, ef, False)


def flops_per_row(core) -> int:
    """Floating-point operations of :func:`features_row` plus the reward of one copy (an FMA counts 2;
    square roots, the sine of each reference component and the log of the log reward count 1)."""
    p, n, N, m = core.params.C.shape[1], core.n_states, core.n_nodes, core.n_inputs
    return int(2 * N * p * n + 2 * N * n * p + N * n + 3 * N * n + N  # y, xhat, ||xhat_i - x||
               + 4 * n + 2 * n + 2  # e, ||x||^2, ||e||^2, square roots
               + (3 * m if core.has_reference else 0)  # r(t)
               + 2 * n * n + 2 * n + 2 * m * m + 2 * m  # e'Qe + u'Ru
               + 3)  # reward
