"""numba-compiled control period: the hot path of every environment.

Same operations as :func:`.numpy_step.control_period_numpy` (see its docstring for
the equations); the two are tested against each other.

Two layouts of the same arithmetic
----------------------------------
- :func:`period_copy` advances one copy ``b`` of a batch-first state
  (``x (B, n)``, ``z (B, N, n)``, ...): scalar code, the outputs of each
  matrix-vector product computed four at a time (independent FMA chains).
- :func:`period_tile` advances a *tile* of ``W`` copies stored with the copy axis
  **innermost** (``X (n, W)``, ``Z (N, n, W)``, ...): every statement is a loop over
  the ``W`` copies, which the compiler turns into SIMD instructions across copies.

:func:`advance_rows` cuts a range of copies into tiles of :data:`TILE` copies
(gathered from / scattered back to the batch-first arrays), a last tile of the
remaining copies if there are at least :data:`MIN_TILE` of them, and runs the rest
copy by copy. Every copy's arithmetic is identical in both layouts -- each sum is
accumulated in the same order, term by term, and :data:`FASTMATH` excludes
reassociation -- so a copy's trajectory does not depend on the batch size or on its
position in the batch (tested bit for bit).

The constants arrive as one :class:`~dobs_envs.sim.state.KernelArgs` tuple
(``SimParams.kernel_tuple``, built once per parameter set).
"""
from __future__ import annotations

import numpy as np

#: LLVM fast-math flags of the kernel: FMA contraction (``contract``) and ``nsz``, but
#: neither ``reassoc`` (a copy's sums must not be reordered differently in the scalar and
#: the tiled layout) nor ``nnan``/``ninf`` (NaN and inf propagate as IEEE arithmetic says:
#: an overflowing observer yields a non-finite state the environment detects and
#: terminates on, instead of undefined behaviour).
FASTMATH = {"nsz", "contract"}
#: Copies per SIMD tile of :func:`advance_rows` (measured on 2 cores, NE2: 128 beats 64 and 256).
TILE = 128
#: Fewest copies run as a (narrower) tile; fewer remaining copies run one by one.
MIN_TILE = 8

try:  # numba is a hard dependency, but keep the package importable without it
    import numba

    _njit = numba.njit(cache=True, fastmath=FASTMATH, nogil=True, error_model="numpy")
    _njit_inline = numba.njit(cache=True, fastmath=FASTMATH, nogil=True, error_model="numpy", inline="always")
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

    def _njit(f):
        return f

    _njit_inline = _njit


__all__ = ["HAVE_NUMBA", "FASTMATH", "TILE", "MIN_TILE", "period_copy", "period_tile", "advance_rows",
           "control_period_compiled", "flops_per_period"]


@_njit
def _scratch_copy(ka):
    """Work arrays of :func:`period_copy` (allocated once per batch call)."""
    C, E_bar, Q_proj, B_v = ka[3], ka[4], ka[8], ka[2]
    N, n, p, rq, mv = E_bar.shape[0], E_bar.shape[1], C.shape[1], Q_proj.shape[2], B_v.shape[1]
    return (np.empty((N, p)), np.empty((N, n)), np.empty((N, n)), np.empty(rq), np.empty(n), np.empty((N, n)),
            np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(mv))


@_njit
def period_copy(b, x, z, gamma, gamma_s, v, x_r, u, r, ka, sc):
    """One control period of copy ``b`` in place (batch-first arrays, see module doc).

    ``x (B, n)``, ``z (B, N, n)``, ``gamma``/``gamma_s (B, N)``, ``v (B, m_v)``, ``x_r (B, n)``;
    held ``u``/``r (B, m)``; ``ka`` the :class:`~dobs_envs.sim.state.KernelArgs` fields in
    order; ``sc`` the work arrays of :func:`_scratch_copy`.
    """
    (A, B, B_v, C, E_bar, F_bar, G_bar, B_bar, Q_proj, proj_range, nbr_idx, nbr_w, deg, A_r,
     phi, phi_s, sigma, sigma_s, Phi_v, dt, substeps, has_reference) = ka  # = KernelArgs._fields
    y, xhat, d, cq, w, bu, Bu, Br, znew, xdot, xrdot, vnew = sc
    N, n = z.shape[1], z.shape[2]
    p, m, mv = C.shape[1], B.shape[1], B_v.shape[1]
    rq, maxdeg = Q_proj.shape[2], nbr_idx.shape[1]
    # held inputs (ZOH over the control period): Bbar_i u, B u, B r
    for i in range(N):
        for k in range(n):
            s = 0.0
            for j in range(m):
                s = s + B_bar[i, k, j] * u[b, j]
            bu[i, k] = s
    for k in range(n):
        s = 0.0
        s2 = 0.0
        for j in range(m):
            s = s + B[k, j] * u[b, j]
            s2 = s2 + B[k, j] * r[b, j]
        Bu[k] = s
        Br[k] = s2
    for _ in range(substeps):
        # eq. (localmeasure) y_i = C_i x ; eq. (hatxieq) xhat_i = z_i + Gbar_i y_i
        for i in range(N):
            for q in range(p):
                s = 0.0
                for k in range(n):
                    s = s + C[i, q, k] * x[b, k]
                y[i, q] = s
            for k in range(n):
                s = z[b, i, k]
                for q in range(p):
                    s = s + G_bar[i, k, q] * y[i, q]
                xhat[i, k] = s
        # d_i = sum_j a_ij (xhat_i - xhat_j) over the neighbour lists (sparse L xhat)
        for i in range(N):
            for k in range(n):
                d[i, k] = deg[i] * xhat[i, k]
            for q in range(maxdeg):
                a = nbr_w[i, q]
                if a != 0.0:
                    j = nbr_idx[i, q]
                    for k in range(n):
                        d[i, k] = d[i, k] - a * xhat[j, k]
        for i in range(N):
            # w = P_u,i d_i through the thinner of the two bases:
            # Q spans Im T_iu (w = Q Q^T d) or Im T_id (w = d - Q Q^T d)
            for c in range(rq):
                s = 0.0
                for l in range(n):
                    s = s + Q_proj[i, l, c] * d[i, l]
                cq[c] = s
            nw2 = 0.0
            for k in range(n):
                s = 0.0
                for c in range(rq):
                    s = s + Q_proj[i, k, c] * cq[c]
                if not proj_range[i]:
                    s = d[i, k] - s
                w[k] = s
                nw2 = nw2 + s * s
            nw = np.sqrt(nw2)
            g = gamma[b, i]
            gs = gamma_s[b, i]
            coef = g + (gs / nw if nw > 0.0 else 0.0)  # eq. (H_idefine), h(0) = 0
            # eq. (zidynamic): four outputs at a time (independent chains, same order per output)
            k = 0
            while k + 4 <= n:
                s0 = bu[i, k] - coef * w[k]
                s1 = bu[i, k + 1] - coef * w[k + 1]
                s2 = bu[i, k + 2] - coef * w[k + 2]
                s3 = bu[i, k + 3] - coef * w[k + 3]
                for l in range(n):
                    zl = z[b, i, l]
                    s0 = s0 + E_bar[i, k, l] * zl
                    s1 = s1 + E_bar[i, k + 1, l] * zl
                    s2 = s2 + E_bar[i, k + 2, l] * zl
                    s3 = s3 + E_bar[i, k + 3, l] * zl
                for q in range(p):
                    yq = y[i, q]
                    s0 = s0 + F_bar[i, k, q] * yq
                    s1 = s1 + F_bar[i, k + 1, q] * yq
                    s2 = s2 + F_bar[i, k + 2, q] * yq
                    s3 = s3 + F_bar[i, k + 3, q] * yq
                znew[k] = z[b, i, k] + dt * s0
                znew[k + 1] = z[b, i, k + 1] + dt * s1
                znew[k + 2] = z[b, i, k + 2] + dt * s2
                znew[k + 3] = z[b, i, k + 3] + dt * s3
                k += 4
            while k < n:
                s = bu[i, k] - coef * w[k]
                for l in range(n):
                    s = s + E_bar[i, k, l] * z[b, i, l]
                for q in range(p):
                    s = s + F_bar[i, k, q] * y[i, q]
                znew[k] = z[b, i, k] + dt * s
                k += 1
            for k in range(n):
                z[b, i, k] = znew[k]
            # eqs. (gammaiis)/(gagasbeta)
            gamma[b, i] = g + dt * (-sigma[i] * g + phi[i] * nw2)
            gamma_s[b, i] = gs + dt * (-sigma_s[i] * gs + phi_s[i] * nw)
        # eq. (LTIsys) plant and eq. (refxdy) reference model
        _matvec4(xdot, Bu, A, x, b)
        for k in range(n):
            s = xdot[k]
            for j in range(mv):
                s = s + B_v[k, j] * v[b, j]
            xdot[k] = s
        if has_reference:
            _matvec4(xrdot, Br, A_r, x_r, b)
            for k in range(n):
                x_r[b, k] = x_r[b, k] + dt * xrdot[k]
        for k in range(n):
            x[b, k] = x[b, k] + dt * xdot[k]
        # exosystem v <- expm(S dt) v
        for j in range(mv):
            s = 0.0
            for l in range(mv):
                s = s + Phi_v[j, l] * v[b, l]
            vnew[j] = s
        for j in range(mv):
            v[b, j] = vnew[j]


@_njit
def _matvec4(out, init, M, X, b):
    """``out[k] = init[k] + sum_l M[k, l] X[b, l]`` (terms in order of ``l``), four rows at a time."""
    K, L = M.shape[0], M.shape[1]
    k = 0
    while k + 4 <= K:
        s0 = init[k]
        s1 = init[k + 1]
        s2 = init[k + 2]
        s3 = init[k + 3]
        for l in range(L):
            xl = X[b, l]
            s0 = s0 + M[k, l] * xl
            s1 = s1 + M[k + 1, l] * xl
            s2 = s2 + M[k + 2, l] * xl
            s3 = s3 + M[k + 3, l] * xl
        out[k] = s0
        out[k + 1] = s1
        out[k + 2] = s2
        out[k + 3] = s3
        k += 4
    while k < K:
        s = init[k]
        for l in range(L):
            s = s + M[k, l] * X[b, l]
        out[k] = s
        k += 1


@_njit
def _scratch_tile(ka, W):
    """Tile state (X, Z, G, GS, V, XR, U, R) and work arrays of :func:`period_tile` for ``W`` copies."""
    B, C, E_bar, Q_proj, B_v = ka[1], ka[3], ka[4], ka[8], ka[2]
    N, n, p, rq, mv, m = E_bar.shape[0], E_bar.shape[1], C.shape[1], Q_proj.shape[2], B_v.shape[1], B.shape[1]
    state = (np.empty((n, W)), np.empty((N, n, W)), np.empty((N, W)), np.empty((N, W)), np.empty((mv, W)),
             np.empty((n, W)), np.empty((m, W)), np.empty((m, W)))
    work = (np.empty((N, p, W)), np.empty((N, n, W)), np.empty((N, n, W)), np.empty((rq, W)), np.empty((n, W)),
            np.empty((N, n, W)), np.empty((n, W)), np.empty((n, W)), np.empty((n, W)), np.empty((n, W)),
            np.empty((n, W)), np.empty((mv, W)), np.empty(W), np.empty(W), np.empty(W))
    return state, work


@_njit
def period_tile(X, Z, G, GS, V, XR, U, R, ka, work):
    """One control period of a tile of ``W`` copies, copy axis last, in place.

    ``X (n, W)``, ``Z (N, n, W)``, ``G``/``GS (N, W)``, ``V (m_v, W)``, ``XR (n, W)``,
    ``U``/``R (m, W)``. Per copy the same operations in the same order as
    :func:`period_copy`; the innermost loops run over the copies (SIMD).
    """
    (A, B, B_v, C, E_bar, F_bar, G_bar, B_bar, Q_proj, proj_range, nbr_idx, nbr_w, deg, A_r,
     phi, phi_s, sigma, sigma_s, Phi_v, dt, substeps, has_reference) = ka
    Y, XH, D, CQ, Wv, BU, Bu, Br, ZN, XD, XRD, VN, nw2, coef, nw = work
    N, n, W = Z.shape[0], Z.shape[1], Z.shape[2]
    p, m, mv = C.shape[1], B.shape[1], B_v.shape[1]
    rq, maxdeg = Q_proj.shape[2], nbr_idx.shape[1]
    for i in range(N):
        for k in range(n):
            _tile_dot(BU[i, k], None, B_bar[i, k], U, W)
    for k in range(n):
        _tile_dot(Bu[k], None, B[k], U, W)
        _tile_dot(Br[k], None, B[k], R, W)
    for _ in range(substeps):
        for i in range(N):
            for q in range(p):
                _tile_dot(Y[i, q], None, C[i, q], X, W)
            for k in range(n):
                _tile_dot(XH[i, k], Z[i, k], G_bar[i, k], Y[i], W)
        for i in range(N):
            dg = deg[i]
            for k in range(n):
                for c in range(W):
                    D[i, k, c] = dg * XH[i, k, c]
            for q in range(maxdeg):
                a = nbr_w[i, q]
                if a != 0.0:
                    j = nbr_idx[i, q]
                    for k in range(n):
                        for c in range(W):
                            D[i, k, c] = D[i, k, c] - a * XH[j, k, c]
        for i in range(N):
            for c_ in range(rq):
                for c in range(W):
                    CQ[c_, c] = 0.0
                for l in range(n):
                    e = Q_proj[i, l, c_]
                    for c in range(W):
                        CQ[c_, c] = CQ[c_, c] + e * D[i, l, c]
            for c in range(W):
                nw2[c] = 0.0
            rng_ = proj_range[i]
            for k in range(n):
                _tile_dot(Wv[k], None, Q_proj[i, k], CQ, W)
                if not rng_:
                    for c in range(W):
                        Wv[k, c] = D[i, k, c] - Wv[k, c]
                for c in range(W):
                    nw2[c] = nw2[c] + Wv[k, c] * Wv[k, c]
            for c in range(W):
                nw[c] = np.sqrt(nw2[c])
                coef[c] = G[i, c] + (GS[i, c] / nw[c] if nw[c] > 0.0 else 0.0)
            for k in range(n):
                for c in range(W):
                    ZN[k, c] = BU[i, k, c] - coef[c] * Wv[k, c]
                _tile_dot(ZN[k], ZN[k], E_bar[i, k], Z[i], W)
                _tile_dot(ZN[k], ZN[k], F_bar[i, k], Y[i], W)
                for c in range(W):
                    ZN[k, c] = Z[i, k, c] + dt * ZN[k, c]
            for k in range(n):
                for c in range(W):
                    Z[i, k, c] = ZN[k, c]
            sg, ph, sgs, phs = sigma[i], phi[i], sigma_s[i], phi_s[i]
            for c in range(W):
                g = G[i, c]
                gs = GS[i, c]
                G[i, c] = g + dt * (-sg * g + ph * nw2[c])
                GS[i, c] = gs + dt * (-sgs * gs + phs * nw[c])
        for k in range(n):
            _tile_dot(XD[k], Bu[k], A[k], X, W)
            _tile_dot(XD[k], XD[k], B_v[k], V, W)
        if has_reference:
            for k in range(n):
                _tile_dot(XRD[k], Br[k], A_r[k], XR, W)
            for k in range(n):
                for c in range(W):
                    XR[k, c] = XR[k, c] + dt * XRD[k, c]
        for k in range(n):
            for c in range(W):
                X[k, c] = X[k, c] + dt * XD[k, c]
        for j in range(mv):
            _tile_dot(VN[j], None, Phi_v[j], V, W)
        for j in range(mv):
            for c in range(W):
                V[j, c] = VN[j, c]


@_njit_inline
def _tile_dot(out, init, row, X, W):
    """``out[c] = init[c] + sum_l row[l] X[l, c]`` (``init`` None: 0) for the ``W`` copies ``c``;
    terms added in order of ``l``, four per pass over the copies."""
    if init is None:
        for c in range(W):
            out[c] = 0.0
    else:
        for c in range(W):
            out[c] = init[c]
    L = row.shape[0]
    l = 0
    while l + 4 <= L:
        e0, e1, e2, e3 = row[l], row[l + 1], row[l + 2], row[l + 3]
        for c in range(W):
            out[c] = out[c] + e0 * X[l, c] + e1 * X[l + 1, c] + e2 * X[l + 2, c] + e3 * X[l + 3, c]
        l += 4
    while l < L:
        e = row[l]
        for c in range(W):
            out[c] = out[c] + e * X[l, c]
        l += 1


@_njit
def _gather(state, lo, nl, x, z, gamma, gamma_s, v, x_r, u, r):
    """Copies ``lo .. lo+nl-1`` into the tile (lanes past ``nl`` repeat the last copy)."""
    X, Z, G, GS, V, XR, U, R = state
    W = X.shape[1]
    N, n = Z.shape[0], Z.shape[1]
    for c in range(W):
        b = lo + (c if c < nl else nl - 1)
        for k in range(n):
            X[k, c] = x[b, k]
            XR[k, c] = x_r[b, k]
        for i in range(N):
            G[i, c] = gamma[b, i]
            GS[i, c] = gamma_s[b, i]
            for k in range(n):
                Z[i, k, c] = z[b, i, k]
        for j in range(V.shape[0]):
            V[j, c] = v[b, j]
        for j in range(U.shape[0]):
            U[j, c] = u[b, j]
            R[j, c] = r[b, j]


@_njit
def _scatter(state, lo, nl, x, z, gamma, gamma_s, v, x_r):
    X, Z, G, GS, V, XR, U, R = state
    N, n = Z.shape[0], Z.shape[1]
    for c in range(nl):
        b = lo + c
        for k in range(n):
            x[b, k] = X[k, c]
            x_r[b, k] = XR[k, c]
        for i in range(N):
            gamma[b, i] = G[i, c]
            gamma_s[b, i] = GS[i, c]
            for k in range(n):
                z[b, i, k] = Z[i, k, c]
        for j in range(V.shape[0]):
            v[b, j] = V[j, c]


@_njit
def advance_rows(x, z, gamma, gamma_s, v, x_r, u, r, ka, lo, hi):
    """One control period of copies ``lo .. hi-1`` in place: tiles of :data:`TILE` copies,
    one narrower tile for a remainder of at least :data:`MIN_TILE`, the rest copy by copy."""
    b = lo
    if hi - b >= TILE:
        st, wk = _scratch_tile(ka, TILE)
        while hi - b >= TILE:
            _gather(st, b, TILE, x, z, gamma, gamma_s, v, x_r, u, r)
            period_tile(st[0], st[1], st[2], st[3], st[4], st[5], st[6], st[7], ka, wk)
            _scatter(st, b, TILE, x, z, gamma, gamma_s, v, x_r)
            b += TILE
    rest = hi - b
    if rest >= MIN_TILE:
        Wt = (rest + 7) // 8 * 8  # lanes past the remainder repeat its last copy and are not written back
        st, wk = _scratch_tile(ka, Wt)
        _gather(st, b, rest, x, z, gamma, gamma_s, v, x_r, u, r)
        period_tile(st[0], st[1], st[2], st[3], st[4], st[5], st[6], st[7], ka, wk)
        _scatter(st, b, rest, x, z, gamma, gamma_s, v, x_r)
    elif rest > 0:
        sc = _scratch_copy(ka)
        for c in range(b, hi):
            period_copy(c, x, z, gamma, gamma_s, v, x_r, u, r, ka, sc)


@_njit
def _control_period_copy(x, z, gamma, gamma_s, v, x_r, u, r, ka):
    # copies made inside compiled code: ~4 us cheaper per call than numpy .copy() x 6
    x = x.copy()
    z = z.copy()
    gamma = gamma.copy()
    gamma_s = gamma_s.copy()
    v = v.copy()
    x_r = x_r.copy()
    advance_rows(x, z, gamma, gamma_s, v, x_r, u, r, ka, 0, x.shape[0])
    return x, z, gamma, gamma_s, v, x_r


def control_period_compiled(x, z, gamma, gamma_s, v, x_r, u, r, p):
    """Compiled counterpart of :func:`control_period_numpy` (same signature).

    State inputs must be C-contiguous float64 arrays (those of :class:`SimState`
    are); they are copied, never modified.
    """
    if u.dtype != np.float64 or not u.flags.c_contiguous:
        u = np.ascontiguousarray(u, dtype=np.float64)
    if r.dtype != np.float64 or not r.flags.c_contiguous:
        r = np.ascontiguousarray(r, dtype=np.float64)
    return _control_period_copy(x, z, gamma, gamma_s, v, x_r, u, r, p.kernel_tuple)


def flops_per_period(p) -> int:
    """Floating-point operations of one control period of one copy (an FMA counts 2).

    Counted from the loops of :func:`period_copy` with the parameters ``p``
    (:class:`~dobs_envs.sim.state.SimParams`): padded output rows and the sparse
    neighbour lists as the kernel runs them; square roots and divisions count 1.
    """
    N, n, m, mv = p.n_nodes, p.n_states, p.n_inputs, p.n_unknown
    P, rq = p.C.shape[1], p.Q_proj.shape[2]
    nnz = int(np.count_nonzero(p.nbr_w))
    held = 2 * (N * n * m + 2 * n * m)
    sub = (2 * N * P * n  # y
           + 2 * N * n * P  # xhat
           + N * n + 2 * nnz * n  # d
           + 2 * N * rq * n + 2 * N * n * rq + N * n * (0 if np.all(p.proj_range) else 1) + 2 * N * n  # w, ||w||^2
           + 3 * N  # sqrt, division, gain
           + N * n * (2 + 2 * n + 2 * P + 2)  # z update
           + 8 * N  # adaptive gains
           + 2 * n * n + 2 * n * mv + 2 * n  # plant
           + (2 * n * n + 2 * n if p.has_reference else 0)  # reference model
           + 2 * mv * mv)  # exosystem
    return int(held + p.substeps * sub)
