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

__all__ = ["FeatureArgs", "pack_static", "unpack_static", "features_row", "write_features", "flops_per_row"]


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
def features_row(b, st, W, fa, has_ref, obs2, y):
    """Copy ``b`` of the state ``st`` (:class:`~dobs_envs.sim.kernel_args.StateArrays`): fill ``W[b]``
    and ``obs2[b] (K * D)`` with the constants ``fa`` (:class:`FeatureArgs`); return
    ``(cost, ||e||, ||x||, finite)`` (``y (p,)`` is scratch).

    Same arithmetic order as :func:`dobs_envs.sim.estimates`: ``y_i = C_i x``,
    ``xhat_i = z_i + G_i y_i``. ``finite`` is accumulated as ``sum(value * 0)``, which is 0
    exactly when every state entry is finite (``inf * 0`` and ``NaN * 0`` are NaN).
    """
    x, z, x_r, gamma, gamma_s, v, t = st.x, st.z, st.x_r, st.gamma, st.gamma_s, st.v, st.t
    F, C, G, ref, Q, R, off, idx = fa.F, fa.C, fa.G, fa.ref, fa.Q, fa.R, fa.off, fa.idx
    N, n = z.shape[1], z.shape[2]
    p = C.shape[1]
    m = R.shape[0]
    nonfin = 0.0
    oy = off[0]
    oxh = off[1]
    for i in range(N):
        for q in range(p):
            s = 0.0
            for l in range(n):
                s += C[i, q, l] * x[b, l]
            y[q] = s
        pi = off[10 + i]
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
        W[b, off[2] + k] = xk
        W[b, off[3] + k] = xrk
        xx += xk * xk
        nonfin += xk * 0.0 + xrk * 0.0
        e = xk - xrk if has_ref else xk
        W[b, off[9] + k] = e
        ee += e * e
    for i in range(N):
        W[b, off[4] + i] = gamma[b, i]
        W[b, off[5] + i] = gamma_s[b, i]
        nonfin += gamma[b, i] * 0.0 + gamma_s[b, i] * 0.0
    for j in range(v.shape[1]):
        W[b, off[6] + j] = v[b, j]
        nonfin += v[b, j] * 0.0
    tb = t[b]
    if has_ref:
        for j in range(ref.shape[1]):
            W[b, off[7] + j] = ref[0, j] * np.sin(ref[1, j] * tb + ref[2, j])
    W[b, off[8]] = tb
    oe = off[9]
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
def write_features(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, obs, rows, cost, err, xnorm, finite):
    """Features, observations and cost of the copies ``rows`` (see module docstring).

    Parameters
    ----------
    x : (B, n); z : (B, N, n); x_r : (B, n); gamma, gamma_s : (B, N); v : (B, m_v); t : (B,)
        simulation arrays (read).
    W : (B, F + N + m) work rows ``[f | est | u]``, written (``u`` is read; the constant
        0/1 entries of ``f`` are left as they are).
    SF, SI : static arrays of :func:`pack_static`.
    has_ref : bool, tracking task (reference command and ``e = x - x_r``).
    obs : (B, K, D) padded observations (float32 or float64), written.
    rows : (k,) int copies to process.
    cost, err, xnorm : (B,) float64, finite : (B,) bool, written at ``rows``:
        ``e'Qe + u'Ru``, ``||e||``, ``||x||`` and the finiteness flag.
    """
    fa = unpack_static(SF, SI)
    st = StateArrays(t, x, z, gamma, gamma_s, v, x_r)
    obs2 = obs.reshape((obs.shape[0], obs.shape[1] * obs.shape[2]))
    y = np.empty(fa.C.shape[1])
    for r in range(rows.shape[0]):
        b = rows[r]
        c, e, xn, fin = features_row(b, st, W, fa, has_ref, obs2, y)
        cost[b] = c
        err[b] = e
        xnorm[b] = xn
        finite[b] = fin


def flops_per_row(core) -> int:
    """Floating-point operations of :func:`features_row` plus the reward of one copy (an FMA counts 2;
    square roots, the sine of each reference component and the log of the log reward count 1)."""
    p, n, N, m = core.params.C.shape[1], core.n_states, core.n_nodes, core.n_inputs
    return int(2 * N * p * n + 2 * N * n * p + N * n + 3 * N * n + N  # y, xhat, ||xhat_i - x||
               + 4 * n + 2 * n + 2  # e, ||x||^2, ||e||^2, square roots
               + (3 * m if core.has_reference else 0)  # r(t)
               + 2 * n * n + 2 * n + 2 * m * m + 2 * m  # e'Qe + u'Ru
               + 3)  # reward
