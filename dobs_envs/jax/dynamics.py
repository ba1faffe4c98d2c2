"""One control period of one copy in JAX, with the structure of :mod:`dobs_envs.sim.numpy_step`.

The numpy reference is the specification; this module follows it function by function
(``_outputs``, ``_rates``, ``_stable_step``, ``_advance`` with the O-O exchange as a part) for one
copy, ``jax.vmap`` batching it. Inside the period every vector is a tuple of scalars and every
product a sum over its matrix's nonzeros (:mod:`dobs_envs.jax.operators`: the layout of the compiled
kernel :mod:`dobs_envs.sim.period_kernel`). One forward-Euler step of length ``dt`` with the held
input ``u`` and the held reference command ``r``, every right-hand side at the old state:

- eq. (localmeasure): ``y_i = C_i x``; eq. (hatxieq): ``xhat_i = z_i + Gbar_i y_i``;
- the consensus disagreement ``d_i = sum_j a_ij (xhat_i - xhat_j) = (L xhat)_i``
  (:class:`IdealExchange`, the paper's continuous links);
- eq. (H_idefine): ``H_i = gamma_i P_u,i d_i + gamma_is P_u,i d_i / ||P_u,i d_i||`` (``h(0) = 0``,
  eq. (hfunc)), with ``eps_iu`` of norm ``||P_u,i d_i||`` (eq. (TidTiu));
- eq. (zidynamic): ``z_i += dt (Ebar_i z_i + Fbar_i y_i + Bbar_i u - H_i)``;
- eqs. (gammaiis)/(gagasbeta): ``gamma_i += dt (-sigma_i gamma_i + phi_i ||eps_iu||^2)``,
  ``gamma_is += dt (-sigma_is gamma_is + phi_is ||eps_iu||)``;
- eq. (LTIsys): ``x += dt (A x + B u + B_v v)``; eq. (refxdy): ``x_r += dt (A_r x_r + B r)``;
- the exosystem ``v <- expm(S dt) v``.

Stable steps (:mod:`dobs_envs.sim.period_kernel`, "Stable steps"): when
``max_i 2 deg_i dt (gamma_i + dt phi_i ||eps_iu||^2) > 1`` at a step's start, the interval ``dt`` is
integrated by shorter Euler steps ``h = min(tau, min_i h_i)`` (at least ``dt / MAX_SPLIT``), ``h_i``
the largest step passing the same test at node ``i``, in a ``lax.while_loop`` that runs only for the
copies whose test failed. Under ``jax.vmap`` the loop runs in lock-step: while one copy of the batch
splits, every copy's iteration is computed and the others' results discarded
(``benchmarks/bench_jax_envs.py`` measures what that costs).
"""
from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from ..sim.period_kernel import MAX_SPLIT
from .operators import coefficients, matvec, stack, unstack

__all__ = ["Coefs", "IdealExchange", "control_period", "coefs", "outputs"]


class Coefs(NamedTuple):
    """The coefficients of every product of one parameter set (:func:`dobs_envs.jax.operators.coefficients`),
    read once per control period, outside the Euler loop."""

    C: tuple
    G: tuple
    P: tuple
    E: tuple
    F: tuple
    Bbar: tuple
    L: tuple
    A: tuple
    B: tuple
    Bv: tuple
    Ar: tuple
    Phi: tuple


def coefs(params, structure) -> Coefs:
    """:class:`Coefs` of ``params`` at the nonzeros of ``structure.patterns``."""
    from .operators import OPERATORS

    pat = structure.patterns
    return Coefs(*(coefficients(getattr(params, OPERATORS[op][0]), pat[op]) for op in Coefs._fields))


def outputs(X, Z, K: Coefs, zero, noise=None):
    """Eqs. (localmeasure), (hatxieq) on tuples: ``y`` (``N p`` scalars, node-major; plus the held measurement
    noise) and ``xhat`` (``N n`` scalars)."""
    y = matvec(K.C, X, zero)
    if noise is not None:
        y = tuple(a + b for a, b in zip(y, noise))
    xhat = tuple(a + b for a, b in zip(Z, matvec(K.G, y, zero)))
    return y, xhat


def consensus(K: Coefs, xhat, N: int, n: int, zero):
    """``d = L xhat`` (``N n`` scalars): the Laplacian applied to each state component."""
    d = [zero] * (N * n)
    for k in range(n):
        col = matvec(K.L, tuple(xhat[j * n + k] for j in range(N)), zero)
        for i in range(N):
            d[i * n + k] = col[i]
    return tuple(d)


class IdealExchange:
    """The paper's O-O exchange: ``d = L xhat`` from every node's current estimate (continuous links).
    ``deg``: the nodes' weighted degrees (the Laplacian's diagonal), a tuple of scalars."""

    noise = None

    def __init__(self, params, structure, K: Coefs, zero):
        self.K, self.N, self.n, self.zero = K, structure.N, structure.n, zero
        self.deg = unstack(params.degree)

    def grid(self, j, xhat, carry):
        """``(d, carry)`` at Euler step ``j`` of the period (``carry``: the exchange's own state)."""
        return consensus(self.K, xhat, self.N, self.n, self.zero), carry

    def sub(self, xhat, carry):
        """``(d, carry)`` inside a split Euler step."""
        return consensus(self.K, xhat, self.N, self.n, self.zero), carry


def _stable_step(deg, gamma, phi, nw2):
    """Largest ``h`` with ``2 deg_i h (gamma_i + h phi_i ||eps_iu||^2) <= 1`` at every node."""
    hmin = None
    for di, gi, pi, wi in zip(deg, gamma, phi, nw2):
        a = 2.0 * di * gi
        b = 2.0 * di * pi * wi
        den = a + jnp.sqrt(a * a + 4.0 * b)
        h = jnp.where(den > 0.0, 2.0 / jnp.where(den > 0.0, den, 1.0), jnp.inf)
        hmin = h if hmin is None else jnp.minimum(hmin, h)
    return hmin


def control_period(x, z, gamma, gamma_s, v, x_r, u, r, params, structure, exchange=None, carry=None):
    """``structure.substeps`` Euler steps of one copy with the held input ``u (m,)`` and reference command
    ``r (m,)`` (module doc). ``exchange(params, structure, coefs, zero)`` builds the O-O exchange (default
    :class:`IdealExchange`); ``carry`` is its state.

    Returns ``(x, z, gamma, gamma_s, v, x_r, carry)`` (arrays of the input shapes).
    """
    st, p = structure, params
    n, N = st.n, st.N
    zero = jnp.zeros((), st.dtype)
    K = coefs(p, st)
    ex = (exchange or IdealExchange)(p, st, K, zero)
    U, R = unstack(u), unstack(r)
    bu = matvec(K.Bbar, U, zero)  # held local inputs Bbar_i u_i
    Bu = matvec(K.B, U, zero)
    Br = matvec(K.B, R, zero)
    phi, phi_s, sigma, sigma_s = (unstack(a) for a in (p.phi, p.phi_s, p.sigma, p.sigma_s))
    deg = ex.deg
    dt = p.dt
    hmin = dt / MAX_SPLIT
    has_ref = st.has_reference

    def rates(s, d, y):
        """Right-hand sides given ``y`` and the disagreement ``d`` of eq. (H_idefine): ``zdot, gdot, gsdot,
        xdot`` and ``||eps_iu||^2`` (tuples)."""
        X, Z, G, GS, V, XR = s
        w = matvec(K.P, d, zero)
        Ez, Fy = matvec(K.E, Z, zero), matvec(K.F, y, zero)
        zd, gd, gsd, nw2 = [], [], [], []
        for i in range(N):
            wi = w[i * n:(i + 1) * n]
            ss = wi[0] * wi[0]
            for a in wi[1:]:
                ss = ss + a * a
            nw = jnp.sqrt(ss)
            pos = nw > 0.0
            safe = jnp.where(pos, nw, 1.0)
            for k in range(n):
                o = i * n + k
                unit = jnp.where(pos, w[o] / safe, 0.0)
                zd.append(Ez[o] + Fy[o] + bu[o] - (G[i] * w[o] + GS[i] * unit))
            nw2.append(nw * nw)  # as the reference's nw**2
            gd.append(-sigma[i] * G[i] + phi[i] * nw2[i])
            gsd.append(-sigma_s[i] * GS[i] + phi_s[i] * nw)
        xd = tuple(a + b + c for a, b, c in zip(matvec(K.A, X, zero), Bu, matvec(K.Bv, V, zero)))
        return tuple(zd), tuple(gd), tuple(gsd), xd, tuple(nw2)

    def euler(s, h, rt):
        X, Z, G, GS, V, XR = s
        zd, gd, gsd, xd, _ = rt
        if has_ref:
            XR = tuple(a + h * (b + c) for a, b, c in zip(XR, matvec(K.Ar, XR, zero), Br))
        step = lambda a, b: tuple(ai + h * bi for ai, bi in zip(a, b))  # noqa: E731
        return step(X, xd), step(Z, zd), step(G, gd), step(GS, gsd), V, XR

    def split_body(c):
        s, tau, live, ec = c
        y, xh = outputs(s[0], s[1], K, zero, ex.noise)
        d, ec = ex.sub(xh, ec)
        rt = rates(s, d, y)
        hreq = jnp.minimum(tau, _stable_step(deg, s[2], phi, rt[4]))
        h = jnp.where(jnp.isnan(hreq), tau, jnp.where(hreq < hmin, hmin, hreq))
        last = h >= tau
        h = jnp.where(last, tau, h)
        return euler(s, h, rt), tau - h, live & ~last, ec

    def euler_step(j, c):
        s, ec = c
        y, xh = outputs(s[0], s[1], K, zero, ex.noise)
        d, ec = ex.grid(j, xh, ec)
        rt = rates(s, d, y)
        # stability test of the Euler step (module doc); NaN: not split
        split = None
        for di, gi, pi, wi in zip(deg, s[2], phi, rt[4]):
            t = 2.0 * di * dt * (gi + dt * pi * wi) > 1.0
            split = t if split is None else split | t
        plain = euler(s, dt, rt)
        fin, _, _, ec = lax.while_loop(lambda c: c[2], split_body, (s, dt, split, ec))
        s = jax.tree.map(lambda a, b: jnp.where(split, a, b), fin, plain)
        return (s[0], s[1], s[2], s[3], matvec(K.Phi, s[4], zero), s[5]), ec

    s0 = (unstack(x), unstack(z), unstack(gamma), unstack(gamma_s), unstack(v), unstack(x_r))
    (X, Z, G, GS, V, XR), carry = lax.fori_loop(0, st.substeps, euler_step, (s0, carry))
    dt_ = st.dtype
    return (stack(X, (n,), dt_), stack(Z, (N, n), dt_), stack(G, (N,), dt_), stack(GS, (N,), dt_),
            stack(V, (st.m_v,), dt_), stack(XR, (n,), dt_), carry)
