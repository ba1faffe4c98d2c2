"""Per-agent observation layouts: one flat vector gathered from a per-step feature vector.

Every control step the environment writes, once, a flat *feature vector* ``f``
holding everything any agent may observe::

    f = [ y (sum_i p_i) | xhat_0..xhat_{N-1} (N n) | x (n) | x_r (n) | gamma (N) | gamma_s (N)
          | v (m_v) | r (m) | t (1) | e (n) | 0 (1) | 1 (1) ]

(written by one compiled call, :func:`write_features`; readable numpy reference in
:mod:`dobs_envs.envs.numpy_features`) and the observation of agent ``k`` is ``f[index_k]`` (one fancy-indexing
gather, which also copies). Padding entries point at the constant 0, mask
entries at the constant 1 (or 0 for padding). This keeps the per-step cost at
one gather per agent whatever components are selected.

Components an agent ``k`` (linked observer node ``i = links[k]``) can observe:

=============  ===============  ================================================================
name           size             content
=============  ===============  ================================================================
``y``          ``p_i``          local measured output ``y_i = C_i x`` (eq. localmeasure)
``xhat``       ``n``            the estimate ``xhat_i`` it receives over its C-O link (eq. hatxieq)
``neighbors``  ``D n``          estimates ``xhat_j`` of node ``i``'s O-O neighbours ``j`` (sorted
                                by index), zero-padded to ``D`` = the largest number of neighbours
                                of any node
``mask``       ``D``            1 for a real neighbour slot, 0 for padding
``r``          ``m_k``          its reference command ``r^k(t)`` (eq. refxdy; tracking only)
``x``          ``n``            true plant state (privileged, debugging)
``x_r``        ``n``            reference-model state (privileged; tracking only)
``estimates``  ``N n``          all observer nodes' estimates (privileged)
``gamma``      ``N``            adaptive gains ``gamma_i`` of eq. (gammaiis)
``gamma_s``    ``N``            adaptive gains ``gamma_is`` of eq. (gammaiis)
``v``          ``m_v``          unknown input ``v`` (privileged; only when ``B_v != 0``)
``time``       ``1``            simulated time ``t`` (s)
=============  ===============  ================================================================

Presets: ``"local"`` = ``(y, xhat, neighbors, mask, r)`` (``r`` only with a
reference), ``"full"`` = local + ``(x, x_r, estimates, gamma, gamma_s, v, time)``
(each only where it exists).
"""
from __future__ import annotations

import numpy as np

__all__ = ["COMPONENTS", "LOCAL", "FULL", "FeatureLayout", "resolve_components", "write_features", "clip_inplace",
           "pack_static", "unpack_static", "write_features_packed"]

COMPONENTS = ("y", "xhat", "neighbors", "mask", "r", "x", "x_r", "estimates", "gamma", "gamma_s", "v", "time")
LOCAL = ("y", "xhat", "neighbors", "mask", "r")
FULL = LOCAL + ("x", "x_r", "estimates", "gamma", "gamma_s", "v", "time")
#: components that exist only in some systems (silently dropped from the presets)
_OPTIONAL = {"r": "has_reference", "x_r": "has_reference", "v": "has_unknown_input"}


def resolve_components(spec, *, has_reference: bool, has_unknown_input: bool) -> tuple:
    """The tuple of component names selected by ``spec`` ("local", "full" or a sequence of names)."""
    avail = {"has_reference": has_reference, "has_unknown_input": has_unknown_input}
    if isinstance(spec, str):
        if spec not in ("local", "full"):
            raise ValueError(f"observation must be 'local', 'full' or a sequence of component names from {COMPONENTS}, got {spec!r}")
        names = LOCAL if spec == "local" else FULL
        return tuple(c for c in names if c not in _OPTIONAL or avail[_OPTIONAL[c]])
    try:
        names = tuple(spec)
    except TypeError:
        raise ValueError(f"observation must be 'local', 'full' or a sequence of component names, got {spec!r}") from None
    if not names:
        raise ValueError("observation must select at least one component")
    for c in names:
        if c not in COMPONENTS:
            raise ValueError(f"unknown observation component {c!r}; valid components are {COMPONENTS}")
        if c in _OPTIONAL and not avail[_OPTIONAL[c]]:
            what = "a reference signal" if _OPTIONAL[c] == "has_reference" else "an unknown input (B_v)"
            raise ValueError(f"observation component {c!r} needs {what}, which this system does not have")
    if len(set(names)) != len(names):
        raise ValueError(f"observation components must not repeat, got {names}")
    return names


class FeatureLayout:
    """Positions of the quantities in the feature vector ``f`` and the per-agent gathers.

    Parameters
    ----------
    p : (N,) output sizes ``p_i``; n : state size; m : input size; m_v : unknown-input size.
    neighbors : list of sorted neighbour arrays per node.
    links : (K,) linked observer node per controller node.
    channel_slices : per controller node, its columns of ``u`` (and ``r``).
    components : tuple of selected component names.
    """

    def __init__(self, p, n, m, m_v, neighbors, links, channel_slices, components):
        N = len(p)
        self.N, self.n, self.m, self.m_v = N, n, m, m_v
        pos = 0

        def take(size):
            nonlocal pos
            s = slice(pos, pos + size)
            pos += size
            return s

        y_off = np.concatenate([[0], np.cumsum(p)]).astype(int)
        self.y = take(int(y_off[-1]))
        self.y_nodes = [slice(self.y.start + y_off[i], self.y.start + y_off[i + 1]) for i in range(N)]
        self.xhat = take(N * n)
        self.x = take(n)
        self.x_r = take(n)
        self.gamma = take(N)
        self.gamma_s = take(N)
        self.v = take(m_v)
        self.r = take(m)
        self.time = take(1)
        self.e = take(n)  # task error x - x_r (or x); not observable, used for the reward
        self.zero = take(1).start
        self.one = take(1).start
        self.size = pos
        self.max_neighbors = max((len(nb) for nb in neighbors), default=0)
        self.components = tuple(components)
        D = self.max_neighbors
        self.agent_index = []
        self.agent_layout = []
        for k, i in enumerate(links):
            parts, layout, start = [], {}, 0
            nb = list(neighbors[i])
            for c in components:
                if c == "y":
                    idx = np.arange(self.y_nodes[i].start, self.y_nodes[i].stop)
                elif c == "xhat":
                    idx = self.xhat.start + i * n + np.arange(n)
                elif c == "neighbors":
                    idx = np.full(D * n, self.zero)
                    for s, j in enumerate(nb):
                        idx[s * n:(s + 1) * n] = self.xhat.start + j * n + np.arange(n)
                elif c == "mask":
                    idx = np.array([self.one if s < len(nb) else self.zero for s in range(D)], dtype=int)
                elif c == "r":
                    sl = channel_slices[k]
                    idx = self.r.start + np.arange(sl.start, sl.stop)
                elif c == "estimates":
                    idx = np.arange(self.xhat.start, self.xhat.stop)
                else:  # x, x_r, gamma, gamma_s, v, time
                    s_ = getattr(self, c)
                    idx = np.arange(s_.start, s_.stop)
                idx = np.asarray(idx, dtype=np.intp)
                layout[c] = slice(start, start + idx.size)
                start += idx.size
                parts.append(idx)
            self.agent_index.append(np.concatenate(parts) if parts else np.zeros(0, dtype=np.intp))
            self.agent_layout.append(layout)
        self.all_index = np.concatenate(self.agent_index)

    def bounds(self, k: int, dtype):
        """``(low, high)`` of agent ``k``'s observation (mask entries in [0, 1], the rest unbounded)."""
        L = self.agent_index[k].size
        low = np.full(L, -np.inf, dtype=dtype)
        high = np.full(L, np.inf, dtype=dtype)
        lay = self.agent_layout[k]
        if "mask" in lay:
            low[lay["mask"]] = 0.0
            high[lay["mask"]] = 1.0
        if "time" in lay:
            low[lay["time"]] = 0.0
        return low, high


try:
    import numba as _numba

    _njit = _numba.njit(cache=True, fastmath=False, nogil=True)  # no fast-math: the finiteness test must see NaN/inf
except ImportError:  # pragma: no cover
    def _njit(f):
        return f


@_njit
def write_features(x, z, x_r, gamma, gamma_s, v, t, C, G, ref, has_ref, f, off, est, Q, R, u, idx, out):
    """Fill the feature vector ``f`` from the (batch-1) simulation arrays in one call.

    ``off`` = (y, xhat, x, x_r, gamma, gamma_s, v, r, time, e) start offsets;
    ``C (N, p, n)``/``G (N, n, p)`` padded design arrays (``y`` keeps the first
    ``p_i`` rows of node ``i``: ``off[10:10+N]`` holds ``p_i``); ``ref (3, m)`` =
    amplitude, frequency, phase of ``r(t)``. Writes ``est[i] = ||xhat_i - x||``.
    Then gathers ``out[j] = f[idx[j]]`` (all agents' observations, concatenated; ``out`` is
    a fresh array of the observation dtype).
    Returns ``(e'Qe + u'Ru, ||e||, ||x||, finite)`` with ``e = x - x_r`` (``has_ref``) or ``x``
    and ``finite`` True iff every entry of ``x``, ``x_r``, ``z``, ``gamma``, ``gamma_s`` and ``v``
    is finite (accumulated as ``sum(value * 0)``, which is 0 exactly when all are finite).
    Same arithmetic order as :func:`dobs_envs.sim.estimates`: ``y_i = C_i x``, ``xhat_i = z_i + G_i y_i``.
    """
    N, n = z.shape[1], z.shape[2]
    p = C.shape[1]
    y = np.empty(p)
    nonfin = 0.0  # stays 0.0 iff all state entries are finite (inf * 0 and NaN * 0 are NaN)
    oy = off[0]
    oxh = off[1]
    for i in range(N):
        for q in range(p):
            s = 0.0
            for l in range(n):
                s += C[i, q, l] * x[0, l]
            y[q] = s
        pi = off[10 + i]
        for q in range(pi):
            f[oy + q] = y[q]
        oy += pi
        ss = 0.0
        for k in range(n):
            s = 0.0
            for q in range(p):
                s += G[i, k, q] * y[q]
            zk = z[0, i, k]
            nonfin += zk * 0.0
            xh = zk + s
            f[oxh + i * n + k] = xh
            d = xh - x[0, k]
            ss += d * d
        est[i] = np.sqrt(ss)
    xx = 0.0
    ee = 0.0
    for k in range(n):
        f[off[2] + k] = x[0, k]
        f[off[3] + k] = x_r[0, k]
        xx += x[0, k] * x[0, k]
        nonfin += x[0, k] * 0.0 + x_r[0, k] * 0.0
        e = x[0, k] - x_r[0, k] if has_ref else x[0, k]
        f[off[9] + k] = e
        ee += e * e
    for i in range(N):
        f[off[4] + i] = gamma[0, i]
        f[off[5] + i] = gamma_s[0, i]
        nonfin += gamma[0, i] * 0.0 + gamma_s[0, i] * 0.0
    for j in range(v.shape[1]):
        f[off[6] + j] = v[0, j]
        nonfin += v[0, j] * 0.0
    m = ref.shape[1]
    if has_ref:
        for j in range(m):
            f[off[7] + j] = ref[0, j] * np.sin(ref[1, j] * t + ref[2, j])
    f[off[8]] = t
    oe = off[9]
    cost = 0.0
    for k in range(n):
        s = 0.0
        for l in range(n):
            s += Q[k, l] * f[oe + l]
        cost += f[oe + k] * s
    mu = u.shape[0]
    for k in range(mu):
        s = 0.0
        for l in range(mu):
            s += R[k, l] * u[l]
        cost += u[k] * s
    for j in range(idx.shape[0]):
        out[j] = f[idx[j]]
    return cost, np.sqrt(ee), np.sqrt(xx), nonfin == 0.0


@_njit
def clip_inplace(u, lo, hi):
    """Clip ``u`` to ``[lo, hi]`` in place; False (and ``u`` untouched) if ``u`` has NaN/inf."""
    for j in range(u.shape[0]):
        if not np.isfinite(u[j]):
            return False
    for j in range(u.shape[0]):
        if u[j] < lo[j]:
            u[j] = lo[j]
        elif u[j] > hi[j]:
            u[j] = hi[j]
    return True


def pack_static(C, G, ref, Q, R, off, idx, F):
    """Static arrays of :func:`write_features_packed`: one float and one int buffer (fewer
    arguments = cheaper compiled-call dispatch on the per-step path)."""
    C, G, ref, Q, R = (np.ascontiguousarray(a, dtype=np.float64) for a in (C, G, ref, Q, R))
    N, p, n = C.shape
    m = R.shape[0]
    SF = np.concatenate([C.ravel(), G.ravel(), ref.ravel(), Q.ravel(), R.ravel()])
    head = np.array([F, N, p, n, m, ref.shape[1], len(off), len(idx)], dtype=np.int64)
    SI = np.concatenate([head, np.asarray(off, dtype=np.int64), np.asarray(idx, dtype=np.int64)])
    return SF, SI


@_njit
def unpack_static(SF, SI):
    """Views of the static arrays packed by :func:`pack_static`.

    Returns ``(F, C (N, p, n), G (N, n, p), ref (3, m), Q (n, n), R (m, m), off, idx)``
    with ``F`` the feature-vector length, ``off`` the offsets of
    :func:`write_features` and ``idx`` the concatenated agent gathers.
    """
    F, N, p, n, m, mr, no, ni = SI[0], SI[1], SI[2], SI[3], SI[4], SI[5], SI[6], SI[7]
    a = 0
    C = SF[a:a + N * p * n].reshape((N, p, n)); a += N * p * n
    G = SF[a:a + N * n * p].reshape((N, n, p)); a += N * n * p
    ref = SF[a:a + 3 * mr].reshape((3, mr)); a += 3 * mr
    Q = SF[a:a + n * n].reshape((n, n)); a += n * n
    R = SF[a:a + m * m].reshape((m, m))
    off = SI[8:8 + no]
    idx = SI[8 + no:8 + no + ni]
    return F, C, G, ref, Q, R, off, idx


@_njit
def write_features_packed(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, out):
    """:func:`write_features` with packed arguments: ``W = [f | est (N) | u (m)]`` (work buffer),
    ``SF``/``SI`` from :func:`pack_static`. Readable reference:
    :func:`dobs_envs.envs.numpy_features.write_features_reference` (same signature)."""
    F, C, G, ref, Q, R, off, idx = unpack_static(SF, SI)
    N, m = C.shape[0], R.shape[0]
    return write_features(x, z, x_r, gamma, gamma_s, v, t, C, G, ref, has_ref, W[:F], off, W[F:F + N], Q, R,
                          W[F + N:F + N + m], idx, out)
