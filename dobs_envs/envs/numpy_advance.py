"""Reference (pure numpy) implementation of one batched environment step.

:func:`advance_reference` has the signature and the effects of the compiled
:func:`dobs_envs.envs.step_kernel.advance_batch` and is the specification it is
tested against (``tests/test_core.py``): the simulation is
:func:`dobs_envs.sim.numpy_step.control_period_numpy`, the features
:func:`dobs_envs.envs.numpy_features.write_features_reference`, and the reward and
termination rules are written out below, vectorised over the copies.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..sim.numpy_step import control_period_numpy
from ..sim.state import KernelArgs
from .features import unpack_static
from .numpy_features import write_features_reference
from ..sim.kernel import unpack_kernel_args
from .step_kernel import REASON_HORIZON, REASON_NON_FINITE, REASON_NONE, REASON_STATE_BOUND

__all__ = ["advance_reference"]


def advance_reference(state, W, obs, outs, u, sig, ka, SF, SI, consts):
    """Numpy counterpart of :func:`~dobs_envs.envs.step_kernel.advance_batch` (same arguments, same effects)."""
    bad = np.flatnonzero(~np.all(np.isfinite(u), axis=1))
    if bad.size:
        return int(bad[0])
    with np.errstate(all="ignore"):
        _advance(state, W, obs, outs, u, sig, ka, SF, SI, consts)
    return -1


def _advance(state, W, obs, outs, u, sig, ka, SF, SI, consts):
    t, x, z, gamma, gamma_s, v, x_r = state
    outf, outb, reason, cycles = outs
    reward, cost, err, xnorm = outf
    finite, term, trunc = outb
    u_lo, u_hi, period, state_bound, bound_cost, log_c0, big_obs, max_cycles, penalty_cycles, \
        has_ref, reward_code, penalty, random_v = consts
    F, C, G, ref, Q, R, off, idx = unpack_static(SF, SI)
    B, N = z.shape[0], z.shape[1]
    m = u.shape[1]
    # 1-2: applied inputs (clipped), disturbance at the period's start
    W[:, F + N:F + N + m] = np.minimum(np.maximum(u, u_lo), u_hi)
    if random_v:
        a, w, ph = sig
        v[:] = (a * np.sin(w * t[:, None, None] + ph)).sum(axis=2)
    # 3: one control period with the held input and reference command
    k = KernelArgs(*unpack_kernel_args(*ka))
    lap = np.diag(k.degree) - _adjacency(k.nbr_idx, k.nbr_w, N)
    P_u = np.einsum("ikc,ilc->ikl", k.Q_proj, k.Q_proj)
    P_u = np.where(k.proj_range.astype(bool)[:, None, None], P_u, np.eye(z.shape[2]) - P_u)
    p = SimpleNamespace(**{**k._asdict(), "proj_range": k.proj_range.astype(bool)}, laplacian=lap, P_u=P_u)
    U = W[:, F + N:F + N + m].copy()
    Rc = W[:, off[7]:off[7] + m].copy()
    x[:], z[:], gamma[:], gamma_s[:], v[:], x_r[:] = control_period_numpy(x, z, gamma, gamma_s, v, x_r, U, Rc, p)
    # 4: time, features, cost
    t += period
    cycles += 1
    rows = np.arange(B)
    write_features_reference(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, has_ref, obs, rows, cost, err, xnorm, finite)
    # 5: reward and termination
    if reward_code == 1:  # log
        shaped = np.where(cost < np.inf, np.log1p(cost / log_c0), np.inf)
    elif reward_code == 2:  # sqrt
        shaped = np.sqrt(cost)
    else:
        shaped = cost
    rw = -shaped * period
    bound = (xnorm > state_bound) & np.all(np.isfinite(x), axis=1)  # a finite plant beyond the bound: reason 1
    non_finite = ~finite & ~bound
    tm = non_finite | bound
    rw = np.where(tm & ~np.isfinite(rw), -bound_cost, rw)
    if penalty:
        rw = np.where(tm, rw - bound_cost * np.maximum(0, penalty_cycles - cycles), rw)
    tr = ~tm & (max_cycles >= 0) & (cycles >= max_cycles)
    reason[:] = np.where(non_finite, REASON_NON_FINITE, np.where(bound, REASON_STATE_BOUND,
                                                                  np.where(tr, REASON_HORIZON, REASON_NONE)))
    reward[:], term[:], trunc[:] = rw, tm, tr
    o2 = obs.reshape(B, -1)
    o2[tm] = np.nan_to_num(o2[tm], nan=0.0, posinf=big_obs, neginf=-big_obs)
    W[tm, :F] = np.nan_to_num(W[tm, :F])


def _adjacency(nbr_idx, nbr_w, N):
    adj = np.zeros((N, N))
    for i in range(N):
        for j, a in zip(nbr_idx[i], nbr_w[i]):
            if a != 0.0:
                adj[i, j] = a
    return adj
