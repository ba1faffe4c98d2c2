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
"""
from __future__ import annotations

import numpy as np

__all__ = ["control_period_numpy"]


def control_period_numpy(x, z, gamma, gamma_s, v, x_r, u, r, p):
    """Advance ``p.substeps`` Euler steps. Returns new arrays (inputs untouched).

    Shapes: x (B,n), z (B,N,n), gamma/gamma_s (B,N), v (B,m_v), x_r (B,n),
    u (B,m), r (B,m).
    """
    x = x.copy(); z = z.copy(); gamma = gamma.copy(); gamma_s = gamma_s.copy()
    v = v.copy(); x_r = x_r.copy()
    dt = p.dt
    bu = np.einsum("inm,bm->bin", p.B_bar, u)  # held local inputs Bbar_i u_i
    Bu = u @ p.B.T
    Br = r @ p.B.T
    for _ in range(p.substeps):
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
        if p.has_reference:
            x_r = x_r + dt * (x_r @ p.A_r.T + Br)
        z = z + dt * zdot
        gamma = gamma + dt * gdot
        gamma_s = gamma_s + dt * gsdot
        x = x + dt * xdot
        v = v @ p.Phi_v.T
    return x, z, gamma, gamma_s, v, x_r
