"""Reference (pure numpy) implementation of the batched observation/reward kernel.

:func:`write_features_reference` has the signature and the effects of the
compiled :func:`dobs_envs.envs.features.write_features` (the per-copy part of every
environment step) and is the specification it is tested against
(``tests/test_features_reference.py``), as :mod:`dobs_envs.sim.numpy_step` is for the
simulation kernel. For every copy ``b`` in ``rows`` it computes

- eq. (localmeasure): ``y_i = C_i x`` (node ``i`` keeps its first ``p_i`` rows),
- eq. (hatxieq): ``xhat_i = z_i + Gbar_i y_i`` and ``est_i = ||xhat_i - x||``,
- the reference command of eq. (refxdy): ``r_j(t) = a_j sin(w_j t + phi_j)`` (tracking only),
- the task error ``e = x - x_r`` (tracking) or ``e = x`` (stabilisation),
- the step cost ``e'Qe + u'Ru`` and the norms ``||e||``, ``||x||``,
- whether the whole simulated state (``x``, ``x_r``, ``z``, ``gamma``, ``gamma_s``, ``v``) is finite,

writes them into the work rows ``W[b] = [f | est | u]`` (layout of ``f`` in
:mod:`dobs_envs.envs.observation`) and gathers the agents' padded observations
``obs[b] = f[padded_index]``, vectorised over the copies.
"""
from __future__ import annotations

import numpy as np

from ..packing import unpack
from .features import FeatureArgs

__all__ = ["write_features_reference"]


def write_features_reference(rows, state, W, obs, SF, SI, has_ref, out):
    """Numpy counterpart of :func:`~dobs_envs.envs.features.write_features`.

    Parameters
    ----------
    rows : (k,) int copies to process.
    state : ``(t (B,), x (B, n), z (B, N, n), gamma, gamma_s (B, N), v (B, m_v), x_r (B, n))``, the fields of
        :class:`~dobs_envs.sim.kernel_args.StateArrays` (read).
    W : (B, F + N + m) work rows ``[f | est | u]``, written in place at ``rows`` (``u``, the
        applied input, is read; the constant 0/1 entries of ``f`` are left as they are).
    obs : (B, K, D) padded observations, written at ``rows`` (cast to its dtype).
    SF, SI : static arrays of :func:`~dobs_envs.envs.features.pack_static`.
    has_ref : bool, tracking task (reference command and ``e = x - x_r``).
    out : ``(cost, err, xnorm, finite)``, (B,) float64 x 3 and (B,) bool, written at ``rows``:
        ``e'Qe + u'Ru``, ``||e||``, ``||x||``, and whether every entry of the copy's
        ``x``, ``x_r``, ``z``, ``gamma``, ``gamma_s``, ``v`` is finite.
    """
    t, x, z, gamma, gamma_s, v, x_r = state
    cost, err, xnorm, finite = out
    with np.errstate(all="ignore"):  # IEEE semantics, silently (as the compiled kernel)
        _features(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, obs, np.asarray(rows), cost, err, xnorm,
                  finite)


def _features(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, obs, rows, cost, err, xnorm, finite):
    fa = unpack(FeatureArgs, SF, SI)
    F, C, G, ref, Q, R, off, idx = fa.F, fa.C, fa.G, fa.ref, fa.Q, fa.R, fa.off, fa.idx
    N, n = z.shape[1], z.shape[2]
    p_i = off[10:10 + N]
    o_y, o_xhat, o_x, o_xr, o_g, o_gs, o_v, o_r, o_t, o_e = off[:10]
    X, Xr, tb = x[rows], x_r[rows], t[rows]
    f = W[rows, :F]  # (k, F) copies, written back below
    u = W[rows, F + N:]

    y = np.einsum("ipn,bn->bip", C, X)  # (k, N, p), zero-padded rows
    xhat = z[rows] + np.einsum("inp,bip->bin", G, y)  # (k, N, n)
    f[:, o_y:o_y + int(p_i.sum())] = np.concatenate([y[:, i, :p_i[i]] for i in range(N)], axis=1)
    f[:, o_xhat:o_xhat + N * n] = xhat.reshape(len(rows), N * n)
    W[rows, F:F + N] = np.linalg.norm(xhat - X[:, None, :], axis=2)

    e = X - Xr if has_ref else X.copy()
    f[:, o_x:o_x + n] = X
    f[:, o_xr:o_xr + n] = Xr
    f[:, o_e:o_e + n] = e
    f[:, o_g:o_g + N] = gamma[rows]
    f[:, o_gs:o_gs + N] = gamma_s[rows]
    f[:, o_v:o_v + v.shape[1]] = v[rows]
    if has_ref:
        amplitude, frequency, phase = ref
        f[:, o_r:o_r + ref.shape[1]] = amplitude * np.sin(frequency * tb[:, None] + phase)
    f[:, o_t] = tb
    W[rows, :F] = f

    cost[rows] = np.einsum("bk,kl,bl->b", e, Q, e) + np.einsum("bk,kl,bl->b", u, R, u)
    err[rows] = np.linalg.norm(e, axis=1)
    xnorm[rows] = np.linalg.norm(X, axis=1)
    obs.reshape(obs.shape[0], -1)[rows] = f[:, idx]
    finite[rows] = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(Xr), axis=1) \
        & np.all(np.isfinite(z[rows]), axis=(1, 2)) & np.all(np.isfinite(gamma[rows]), axis=1) \
        & np.all(np.isfinite(gamma_s[rows]), axis=1) & np.all(np.isfinite(v[rows]), axis=1)
