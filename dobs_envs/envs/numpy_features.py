"""Reference (pure numpy) implementation of the observation/reward kernel.

:func:`write_features_reference` has the signature and the effects of the
compiled :func:`dobs_envs.envs.observation.write_features_packed` (the hot path
of every environment step) and is the specification it is tested against
(``tests/test_features_reference.py``), as :mod:`dobs_envs.sim.numpy_step` is
for the simulation kernel. From the batch-1 simulation arrays it computes

- eq. (localmeasure): ``y_i = C_i x`` (node ``i`` keeps its first ``p_i`` rows),
- eq. (hatxieq): ``xhat_i = z_i + Gbar_i y_i`` and ``est_i = ||xhat_i - x||``,
- the reference command of eq. (refxdy): ``r_j(t) = a_j sin(w_j t + phi_j)`` (tracking only),
- the task error ``e = x - x_r`` (tracking) or ``e = x`` (stabilisation),
- the step cost ``e'Qe + u'Ru`` and the norms ``||e||``, ``||x||``,
- whether the whole simulated state (``x``, ``x_r``, ``z``, ``gamma``, ``gamma_s``, ``v``) is finite,

writes them into the feature vector ``f`` (layout in :mod:`dobs_envs.envs.observation`)
and gathers all agents' observations ``out = f[idx]``.
"""
from __future__ import annotations

import numpy as np

from .observation import unpack_static

__all__ = ["write_features_reference"]


def write_features_reference(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, out):
    """Numpy counterpart of :func:`~dobs_envs.envs.observation.write_features_packed`.

    Parameters
    ----------
    x : (1, n) plant state; z : (1, N, n) observer states; x_r : (1, n) reference-model state;
    gamma, gamma_s : (1, N) adaptive gains; v : (1, m_v) unknown input; t : float time.
    W : (F + N + m,) work buffer ``[f | est | u]``, written in place (``u``, the
        applied input, is read; the constant 0/1 entries of ``f`` are left as they are).
    SF, SI : static arrays of :func:`~dobs_envs.envs.observation.pack_static`.
    has_ref : bool, tracking task (reference command and ``e = x - x_r``).
    out : (len(idx),) all agents' observations, written in place (cast to its dtype).

    Returns
    -------
    cost : float ``e'Qe + u'Ru``; track_err : float ``||e||``; x_norm : float ``||x||``;
    finite : bool, every entry of ``x``, ``x_r``, ``z``, ``gamma``, ``gamma_s``, ``v`` is finite.
    """
    with np.errstate(all="ignore"):  # IEEE semantics, silently (as the compiled kernel)
        return _features(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, out)


def _features(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, out):
    F, C, G, ref, Q, R, off, idx = unpack_static(SF, SI)
    N, n = z.shape[1], z.shape[2]
    p_i = off[10:10 + N]
    o_y, o_xhat, o_x, o_xr, o_g, o_gs, o_v, o_r, o_t, o_e = off[:10]
    f, est, u = W[:F], W[F:F + N], W[F + N:]
    x0, xr0 = x[0], x_r[0]

    y = np.einsum("ipn,n->ip", C, x0)  # (N, p), zero-padded rows
    xhat = z[0] + np.einsum("inp,ip->in", G, y)  # (N, n)
    f[o_y:o_y + int(p_i.sum())] = np.concatenate([y[i, :p_i[i]] for i in range(N)])
    f[o_xhat:o_xhat + N * n] = xhat.ravel()
    est[:] = np.linalg.norm(xhat - x0, axis=1)

    e = x0 - xr0 if has_ref else x0.copy()
    f[o_x:o_x + n] = x0
    f[o_xr:o_xr + n] = xr0
    f[o_e:o_e + n] = e
    f[o_g:o_g + N] = gamma[0]
    f[o_gs:o_gs + N] = gamma_s[0]
    f[o_v:o_v + v.shape[1]] = v[0]
    if has_ref:
        amplitude, frequency, phase = ref
        f[o_r:o_r + ref.shape[1]] = amplitude * np.sin(frequency * t + phase)
    f[o_t] = t

    cost = float(e @ (Q @ e) + u @ (R @ u))
    out[:] = f[idx]
    finite = all(np.isfinite(a).all() for a in (x, x_r, z, gamma, gamma_s, v))
    return cost, float(np.linalg.norm(e)), float(np.linalg.norm(x0)), bool(finite)
