"""numba-compiled control period: the hot path of every environment.

Same arithmetic, in the same order of terms, as :func:`.numpy_step.control_period_numpy`
(see its docstring for the equations); the two are tested against each other.
Arrays are updated in place on copies made by :func:`control_period_compiled`.
The constants arrive as one :class:`~dobs_envs.sim.state.KernelArgs` tuple
(``SimParams.kernel_tuple``, built once per parameter set).
"""
from __future__ import annotations

import numpy as np

#: LLVM fast-math flags of the kernel: reassociation and contraction (FMA) but *not*
#: ``nnan``/``ninf``, so NaN and inf propagate as IEEE arithmetic says (an overflowing
#: observer yields a non-finite state the environment detects and terminates on,
#: instead of undefined behaviour). Measured on NE2 (50 substeps, 1 env): ~36-38 us per
#: control period with these flags, ~41 us with ``fastmath=True``, ~43 us without fastmath.
FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

try:  # numba is a hard dependency, but keep the package importable without it
    import numba

    _njit = numba.njit(cache=True, fastmath=FASTMATH, nogil=True, error_model="numpy")
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

    def _njit(f):
        return f


__all__ = ["HAVE_NUMBA", "FASTMATH", "control_period_compiled"]


@_njit
def _control_period(x, z, gamma, gamma_s, v, x_r, u, r, ka):
    """One control period in place. State ``x (B, n)``, ``z (B, N, n)``, ``gamma``/``gamma_s (B, N)``,
    ``v (B, m_v)``, ``x_r (B, n)``; held ``u``/``r (B, m)``; ``ka``: the fields of
    :class:`~dobs_envs.sim.state.KernelArgs`, in its order (``SimParams.kernel_tuple``)."""
    (A, B, B_v, C, E_bar, F_bar, G_bar, B_bar, Q_proj, proj_range, nbr_idx, nbr_w, deg, A_r,
     phi, phi_s, sigma, sigma_s, Phi_v, dt, substeps, has_reference) = ka  # = KernelArgs._fields
    nb, N, n = z.shape
    p = C.shape[1]
    m = B.shape[1]
    mv = B_v.shape[1]
    y = np.empty((N, p))
    rq = Q_proj.shape[2]
    maxdeg = nbr_idx.shape[1]
    xhat = np.empty((N, n))
    d = np.empty((N, n))
    w = np.empty(n)
    cq = np.empty(rq)
    bu = np.empty((N, n))
    Bu = np.empty(n)
    Br = np.empty(n)
    znew = np.empty(n)
    xdot = np.empty(n)
    xrdot = np.empty(n)
    vnew = np.empty(mv)
    for b in range(nb):
        # held inputs (ZOH over the control period)
        for i in range(N):
            for k in range(n):
                s = 0.0
                for j in range(m):
                    s += B_bar[i, k, j] * u[b, j]
                bu[i, k] = s
        for k in range(n):
            s = 0.0
            s2 = 0.0
            for j in range(m):
                s += B[k, j] * u[b, j]
                s2 += B[k, j] * r[b, j]
            Bu[k] = s
            Br[k] = s2
        for _ in range(substeps):
            # y_i = C_i x ; xhat_i = z_i + Gbar_i y_i
            for i in range(N):
                for q in range(p):
                    s = 0.0
                    for k in range(n):
                        s += C[i, q, k] * x[b, k]
                    y[i, q] = s
                for k in range(n):
                    s = z[b, i, k]
                    for q in range(p):
                        s += G_bar[i, k, q] * y[i, q]
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
                            d[i, k] -= a * xhat[j, k]
            for i in range(N):
                # w = P_u,i d_i through the thinner of the two bases:
                # Q spans Im T_iu (w = Q Q^T d) or Im T_id (w = d - Q Q^T d)
                for c in range(rq):
                    s = 0.0
                    for l in range(n):
                        s += Q_proj[i, l, c] * d[i, l]
                    cq[c] = s
                rng_ = proj_range[i]
                nw2 = 0.0
                for k in range(n):
                    s = 0.0
                    for c in range(rq):
                        s += Q_proj[i, k, c] * cq[c]
                    if not rng_:
                        s = d[i, k] - s
                    w[k] = s
                    nw2 += s * s
                nw = np.sqrt(nw2)
                g = gamma[b, i]
                gs = gamma_s[b, i]
                coef = g + (gs / nw if nw > 0.0 else 0.0)
                for k in range(n):
                    s = bu[i, k] - coef * w[k]
                    for l in range(n):
                        s += E_bar[i, k, l] * z[b, i, l]
                    for q in range(p):
                        s += F_bar[i, k, q] * y[i, q]
                    znew[k] = z[b, i, k] + dt * s
                for k in range(n):
                    z[b, i, k] = znew[k]
                gamma[b, i] = g + dt * (-sigma[i] * g + phi[i] * nw2)
                gamma_s[b, i] = gs + dt * (-sigma_s[i] * gs + phi_s[i] * nw)
            # plant and reference model
            for k in range(n):
                s = Bu[k]
                for l in range(n):
                    s += A[k, l] * x[b, l]
                for j in range(mv):
                    s += B_v[k, j] * v[b, j]
                xdot[k] = s
            if has_reference:
                for k in range(n):
                    s = Br[k]
                    for l in range(n):
                        s += A_r[k, l] * x_r[b, l]
                    xrdot[k] = s
                for k in range(n):
                    x_r[b, k] += dt * xrdot[k]
            for k in range(n):
                x[b, k] += dt * xdot[k]
            for j in range(mv):
                s = 0.0
                for l in range(mv):
                    s += Phi_v[j, l] * v[b, l]
                vnew[j] = s
            for j in range(mv):
                v[b, j] = vnew[j]


@_njit
def _control_period_copy(x, z, gamma, gamma_s, v, x_r, u, r, ka):
    # copies made inside compiled code: ~4 us cheaper per call than numpy .copy() x 6
    x = x.copy()
    z = z.copy()
    gamma = gamma.copy()
    gamma_s = gamma_s.copy()
    v = v.copy()
    x_r = x_r.copy()
    _control_period(x, z, gamma, gamma_s, v, x_r, u, r, ka)
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
