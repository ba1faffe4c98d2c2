"""Reference (pure numpy) implementation of one control period.

Vectorised over batch and nodes; a Python loop runs over the ``substeps`` Euler
steps only. It is the specification the compiled kernel (:mod:`.kernel`) is
tested against, and the fallback when numba is unavailable.

One forward-Euler step of length ``dt`` with the held input ``u`` and held
reference command ``r`` (all right-hand sides evaluated at the old state):

- eq. (localmeasure): ``y_i = C_i x``
- eq. (hatxieq): ``xhat_i = z_i + Gbar_i y_i``
- consensus: ``d_i = sum_j a_ij (xhat_i - xhat_j) = (L xhat)_i``;
  ``T_iu eps_iu = P_u,i d_i`` with ``||eps_iu|| = ||P_u,i d_i||`` (T_iu has
  orthonormal columns, eq. (TidTiu))
- eq. (H_idefine): ``H_i = gamma_i P_u,i d_i + gamma_is P_u,i d_i / ||P_u,i d_i||``
  (``h(0) = 0``, eq. (hfunc))
- eq. (zidynamic): ``z_i += dt (Ebar_i z_i + Fbar_i y_i + Bbar_i u - H_i)``
- eqs. (gammaiis)/(gagasbeta): ``gamma_i += dt (-sigma_i gamma_i + phi_i ||eps_iu||^2)``,
  ``gamma_is += dt (-sigma_is gamma_is + phi_is ||eps_iu||)``
- eq. (LTIsys): ``x += dt (A x + B u + B_v v)``
- eq. (refxdy): ``x_r += dt ((A + B K) x_r + B r)``
- exosystem: ``v <- expm(S dt) v``.

The discontinuous term ``h`` makes any fixed-step scheme chatter: once
``eps_iu`` reaches the origin, each step overshoots by ``dt * gamma_is``, so the
disagreement ``||P_u,i d_i||`` stays in a band of order ``dt * gamma_is``
(times the Laplacian gain). This O(dt) chattering band is the floor of the
estimation error in every fixed-step simulation of the paper's observers.

Stable steps (eqs. (zidynamic), (gammaiis); derivation in :mod:`.kernel`, "Stable steps"): an
Euler step is taken as above only when ``max_i 2 deg_i dt (gamma_i + dt phi_i ||eps_iu||^2) <= 1``
at its start (``deg_i`` the weighted degree, the diagonal of the Laplacian); otherwise that copy
integrates the interval ``dt`` by shorter Euler steps ``h = min(tau, min_i h_i)``, ``h_i`` the
largest step passing the same test at node ``i`` (recomputed after each step, at least
``dt / MAX_SPLIT``), with ``v`` held, and ``v <- expm(S dt) v`` once at the end.
"""

from __future__ import annotations

import numpy as np

from .period_kernel import MAX_SPLIT

__all__ = ["control_period_numpy"]


def _rates(x, z, gamma, gamma_s, v, bu, Bu, p):
    """Right-hand sides at the current state: zdot, gdot, gsdot, xdot and ||eps_iu||^2 (B, N)."""
    y = np.einsum("ipn,bn->bip", p.C, x)
    xhat = z + np.einsum("inp,bip->bin", p.G_bar, y)
    d = np.einsum("ij,bjn->bin", p.laplacian, xhat)
    w = np.einsum("ink,bik->bin", p.P_u, d)
    nw = np.linalg.norm(w, axis=-1)
    safe = np.where(nw > 0.0, nw, 1.0)
    unit = np.where((nw > 0.0)[..., None], w / safe[..., None], 0.0)
    H = gamma[..., None] * w + gamma_s[..., None] * unit
    zdot = np.einsum("ink,bik->bin", p.E_bar, z) + np.einsum("inp,bip->bin", p.F_bar, y) + bu - H
    gdot = -p.sigma * gamma + p.phi * nw**2
    gsdot = -p.sigma_s * gamma_s + p.phi_s * nw
    xdot = x @ p.A.T + Bu + v @ p.B_v.T
    return zdot, gdot, gsdot, xdot, nw**2


def _stable_step(deg, gamma, phi, nw2):
    """Largest ``h`` with ``2 deg_i h (gamma_i + h phi_i ||eps_iu||^2) <= 1`` at every node (B,)."""
    a = 2.0 * deg * gamma
    b = 2.0 * deg * phi * nw2
    den = a + np.sqrt(a * a + 4.0 * b)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.where(den > 0.0, 2.0 / np.where(den > 0.0, den, 1.0), np.inf)
    return h.min(axis=-1)


def control_period_numpy(x, z, gamma, gamma_s, v, x_r, u, r, p):
    """Advance ``p.substeps`` Euler steps. Returns new arrays (inputs untouched).

    Shapes: x (B,n), z (B,N,n), gamma/gamma_s (B,N), v (B,m_v), x_r (B,n),
    u (B,m), r (B,m).
    """
    x = x.copy(); z = z.copy(); gamma = gamma.copy(); gamma_s = gamma_s.copy()
    v = v.copy(); x_r = x_r.copy()
    dt = p.dt
    deg = np.diagonal(p.laplacian)
    bu = np.einsum("inm,bm->bin", p.B_bar, u)  # held local inputs Bbar_i u_i
    Bu = u @ p.B.T
    Br = r @ p.B.T
    for _ in range(p.substeps):
        zdot, gdot, gsdot, xdot, nw2 = _rates(x, z, gamma, gamma_s, v, bu, Bu, p)
        # stability test of the Euler step (kernel module doc, "Stable steps"); NaN: not split
        split = np.any(2.0 * deg * dt * (gamma + dt * p.phi * nw2) > 1.0, axis=-1)
        xrdot = x_r @ p.A_r.T + Br
        keep = ~split
        if p.has_reference:
            x_r[keep] = x_r[keep] + dt * xrdot[keep]
        z[keep] = z[keep] + dt * zdot[keep]
        gamma[keep] = gamma[keep] + dt * gdot[keep]
        gamma_s[keep] = gamma_s[keep] + dt * gsdot[keep]
        x[keep] = x[keep] + dt * xdot[keep]
        if split.any():
            s = np.flatnonzero(split)
            xs, zs, gs, gss, vs, xrs = x[s], z[s], gamma[s], gamma_s[s], v[s], x_r[s]
            bus, Bus, Brs = bu[s], Bu[s], Br[s]
            tau = np.full(s.size, dt)
            live = np.ones(s.size, dtype=bool)
            hmin = dt / MAX_SPLIT
            while live.any():
                q = np.flatnonzero(live)
                zd, gd, gsd, xd, n2 = _rates(xs[q], zs[q], gs[q], gss[q], vs[q], bus[q], Bus[q], p)
                hreq = np.minimum(tau[q], _stable_step(deg, gs[q], p.phi, n2))
                h = np.where(np.isnan(hreq), tau[q], np.where(hreq < hmin, hmin, hreq))
                last = h >= tau[q]
                h = np.where(last, tau[q], h)
                if p.has_reference:
                    xrs[q] = xrs[q] + h[:, None] * (xrs[q] @ p.A_r.T + Brs[q])
                zs[q] = zs[q] + h[:, None, None] * zd
                gs[q] = gs[q] + h[:, None] * gd
                gss[q] = gss[q] + h[:, None] * gsd
                xs[q] = xs[q] + h[:, None] * xd
                tau[q] = tau[q] - h
                live[q[last]] = False
            x[s], z[s], gamma[s], gamma_s[s], x_r[s] = xs, zs, gs, gss, xrs
        v = v @ p.Phi_v.T
    return x, z, gamma, gamma_s, v, x_r
