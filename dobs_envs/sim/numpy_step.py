"""Reference (pure numpy) implementation of one control period.

Vectorised over batch and nodes; a Python loop runs over the ``substeps`` Euler
steps only. It is the specification the compiled kernel (:mod:`.period_kernel`) is
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

Stable steps (eqs. (zidynamic), (gammaiis); derivation in :mod:`.period_kernel`, "Stable steps"): an
Euler step is taken as above only when ``max_i 2 deg_i dt (gamma_i + dt phi_i ||eps_iu||^2) <= 1``
at its start (``deg_i`` the weighted degree, the diagonal of the Laplacian); otherwise that copy
integrates the interval ``dt`` by shorter Euler steps ``h = min(tau, min_i h_i)``, ``h_i`` the
largest step passing the same test at node ``i`` (recomputed after each step, at least
``dt / MAX_SPLIT``), with ``v`` held, and ``v <- expm(S dt) v`` once at the end.

Communication faults (issue 23, :mod:`.faults`): :func:`control_period_faulted_numpy` runs the same
period (the same loop, :func:`_advance`) with the consensus term of eq. (H_idefine) taken over the
links of the copy's active graph with the received copies ``r_ij`` that node ``i`` holds,
``d_i = sum_j a_ij^{g(b)} (xhat_i - r_ij)``, O-O broadcasts at the Euler steps that are multiples
of ``oo_period / dt`` (delivered after ``oo_delay`` periods from the snapshot ring, unless the link
lost the period's packets or is absent from the active graph), and the period's measurement noise
added to every ``y_i``. The stable-step test uses the active graph's degrees. With every fault off
it reproduces :func:`control_period_numpy` up to the rounding of the two ways of summing ``d_i``.
"""
from __future__ import annotations

import numpy as np

from . import fault_state as fstate
from .period_kernel import MAX_SPLIT

__all__ = ["control_period_numpy", "control_period_faulted_numpy"]


def _outputs(x, z, p, noise=None):
    """Eqs. (localmeasure), (hatxieq): ``y (B, N, P)`` (plus the held measurement noise) and ``xhat (B, N, n)``."""
    y = np.einsum("ipn,bn->bip", p.C, x)
    if noise is not None:
        y = y + noise
    xhat = z + np.einsum("inp,bip->bin", p.G_bar, y)
    return y, xhat


def _rates(x, z, gamma, gamma_s, v, y, d, bu, Bu, p):
    """Right-hand sides at the current state given the outputs ``y`` and the consensus disagreement
    ``d (B, N, n)`` of eq. (H_idefine): zdot, gdot, gsdot, xdot and ||eps_iu||^2 (B, N)."""
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


class _IdealExchange:
    """Today's O-O exchange: ``d = (L xhat)`` from the current estimates of every node (continuous)."""

    noise = None

    def __init__(self, p, B):
        self.p = p
        self.deg = np.broadcast_to(np.diagonal(p.laplacian), (B, p.laplacian.shape[0]))

    def grid(self, j, xhat):
        """``d`` at Euler step ``j`` of the period (all copies)."""
        return np.einsum("ij,bjn->bin", self.p.laplacian, xhat)

    def sub(self, rows, xhat):
        """``d`` inside a split Euler step (copies ``rows``; ``xhat`` theirs)."""
        return np.einsum("ij,bjn->bin", self.p.laplacian, xhat)


def _advance(x, z, gamma, gamma_s, v, x_r, u, r, p, ex):
    """``p.substeps`` Euler steps with the O-O exchange ``ex`` (:class:`_IdealExchange` or
    :class:`_FaultedExchange`: its degrees ``deg (B, N)``, held noise and ``d``). Returns new arrays."""
    x = x.copy(); z = z.copy(); gamma = gamma.copy(); gamma_s = gamma_s.copy()
    v = v.copy(); x_r = x_r.copy()
    dt = p.dt
    deg = ex.deg
    bu = np.einsum("inm,bm->bin", p.B_bar, u)  # held local inputs Bbar_i u_i
    Bu = u @ p.B.T
    Br = r @ p.B.T
    for j in range(p.substeps):
        y, xhat = _outputs(x, z, p, ex.noise)
        d = ex.grid(j, xhat)
        zdot, gdot, gsdot, xdot, nw2 = _rates(x, z, gamma, gamma_s, v, y, d, bu, Bu, p)
        # stability test of the Euler step (period_kernel module doc, "Stable steps"); NaN: not split
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
                rows = s[q]
                ys, xh = _outputs(xs[q], zs[q], p, None if ex.noise is None else ex.noise[rows])
                zd, gd, gsd, xd, n2 = _rates(xs[q], zs[q], gs[q], gss[q], vs[q], ys, ex.sub(rows, xh), bus[q], Bus[q], p)
                hreq = np.minimum(tau[q], _stable_step(deg[rows], gs[q], p.phi, n2))
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


def control_period_numpy(x, z, gamma, gamma_s, v, x_r, u, r, p):
    """Advance ``p.substeps`` Euler steps. Returns new arrays (inputs untouched).

    Shapes: x (B,n), z (B,N,n), gamma/gamma_s (B,N), v (B,m_v), x_r (B,n),
    u (B,m), r (B,m).
    """
    return _advance(x, z, gamma, gamma_s, v, x_r, u, r, p, _IdealExchange(p, x.shape[0]))


class _FaultedExchange:
    """The faulted O-O exchange of one control period (module doc of :mod:`.faults`).

    Holds copies of the received values ``r (B, E, n)`` and the snapshot ring of ``fs``; ``deliver
    (B, E)``: the links that are in the copy's active graph and do not lose this period's packets.
    """

    def __init__(self, p, fa, fs, trace=None):
        self.p, self.fa, self.trace = p, fa, trace
        self.k = fs.period
        self.r = fs.received.copy()
        self.snapshots = fs.snapshots.copy()
        self.w = fa.weight[fs.graph]  # (B, E) a_ij^{g(b)}
        self.deg = fa.degree[fs.graph]  # (B, N)
        self.deliver = (self.w > 0) & ~fstate.oo_losses(fa, fs)
        self.noise = fs.noise if fa.noise_std > 0 else None
        self.refresh = bool(fa.continuous and fa.lag == 0)  # continuous exchange: fresh r_ij in split steps too

    def grid(self, j, xhat):
        """Broadcasts at Euler step ``s = k S + j`` (copies with ``s`` a multiple of ``exchange_steps``), then ``d``."""
        fa = self.fa
        s = self.k * fa.substeps + j
        M = fa.exchange_steps
        now = np.ones_like(s, dtype=bool) if fa.continuous else (s % M == 0)
        if now.any():
            if fa.lag > 0:
                b = np.flatnonzero(now)
                q = s[b] // M  # broadcast number
                self.snapshots[b, q % fa.ring] = xhat[b]
                src = np.zeros_like(xhat)
                src[b] = self.snapshots[b, (q - fa.lag) % fa.ring]  # not yet written before lag broadcasts: t = 0
            else:
                src = xhat
            upd = self.deliver & now[:, None]
            self.r = np.where(upd[..., None], src[:, fa.sender], self.r)
        if self.trace is not None:
            self.trace(j, xhat, self.r)
        return self._d(slice(None), xhat)

    def sub(self, rows, xhat):
        """``d`` inside a split Euler step of copies ``rows``: continuous exchange refreshes ``r``."""
        if self.refresh:
            self.r[rows] = np.where(self.deliver[rows][..., None], xhat[:, self.fa.sender], self.r[rows])
        return self._d(rows, xhat)

    def _d(self, rows, xhat):
        """eq. (H_idefine) with held copies: ``d_i = sum_{e: receiver e = i} a_e (xhat_i - r_e)`` (links of
        weight 0 add nothing, even when a value is not finite)."""
        fa = self.fa
        w = self.w[rows][..., None]
        c = np.where(w != 0.0, w * (xhat[:, fa.receiver] - self.r[rows]), 0.0)
        d = np.zeros_like(xhat)
        np.add.at(d, (slice(None), fa.receiver), c)
        return d


def control_period_faulted_numpy(x, z, gamma, gamma_s, v, x_r, u, r, p, fa, fs, *, trace=None):
    """One control period with communication faults (module doc; :mod:`.faults` for the semantics).

    Parameters
    ----------
    x, z, gamma, gamma_s, v, x_r, u, r, p
        As :func:`control_period_numpy`.
    fa : FaultArgs of ``p`` (:func:`~dobs_envs.sim.fault_state.fault_args`).
    fs : FaultState of the ``B`` copies at the period's start (:func:`~dobs_envs.sim.fault_state.init_fault_state`).
    trace : callable, optional
        ``trace(j, xhat (B, N, n), received (B, E, n))`` after the broadcasts of every Euler step ``j``
        (diagnostics and tests; the arrays are the live ones: copy them).

    Returns
    -------
    x, z, gamma, gamma_s, v, x_r : new arrays (inputs untouched).
    fs : the new FaultState (``period + 1``, the received values and snapshots, the next period's
        graph, burst states and noise).
    """
    ex = _FaultedExchange(p, fa, fs, trace)
    out = _advance(x, z, gamma, gamma_s, v, x_r, u, r, p, ex)
    period = fs.period + 1
    graph, bad, noise = fstate.period_draws(fa, fs.seed, period, fs.graph, fs.bad)
    fs = fs.replace(period=period, received=ex.r, snapshots=ex.snapshots, graph=graph, bad=bad, noise=noise)
    return (*out, fs)
