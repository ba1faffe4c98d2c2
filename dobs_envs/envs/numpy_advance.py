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

from ..packing import unpack
from ..sim.kernel_args import StateArrays, unpack_kernel_args
from ..sim.numpy_step import control_period_numpy
from .features import FeatureArgs
from .numpy_features import write_features_reference
from .step_kernel import REASON_HORIZON, REASON_NON_FINITE, REASON_NONE, REASON_STATE_BOUND, StepConsts

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
    s = StateArrays(*state)
    t, x, z, gamma, gamma_s, v, x_r = s.t, s.x, s.z, s.gamma, s.gamma_s, s.v, s.x_r
    outf, outb, reason, cycles = outs
    reward, cost, err, xnorm = outf
    finite, term, trunc = outb
    c = StepConsts(*consts)
    period = c.period
    fa = unpack(FeatureArgs, SF, SI)
    F, off = fa.F, fa.off
    B, N = z.shape[0], z.shape[1]
    m = u.shape[1]
    # 1-2: applied inputs (clipped), disturbance at the period's start
    W[:, F + N:F + N + m] = np.minimum(np.maximum(u, c.u_lo), c.u_hi)
    if c.random_v:
        a, w, ph = sig
        v[:] = (a * np.sin(w * t[:, None, None] + ph)).sum(axis=2)
    # 3: one control period with the held input and reference command
    k = unpack_kernel_args(*ka)
    lap = np.diag(k.degree) - _adjacency(k.nbr_idx, k.nbr_w, N)
    P_u = np.einsum("ikc,ilc->ikl", k.Q_proj, k.Q_proj)
    P_u = np.where(k.proj_range[:, None, None], P_u, np.eye(z.shape[2]) - P_u)
    p = SimpleNamespace(**k._asdict(), laplacian=lap, P_u=P_u)
    U = W[:, F + N:F + N + m].copy()
    Rc = W[:, off[7]:off[7] + m].copy()
    x[:], z[:], gamma[:], gamma_s[:], v[:], x_r[:] = control_period_numpy(x, z, gamma, gamma_s, v, x_r, U, Rc, p)
    # 4: time, features, cost
    t += period
    cycles += 1
    rows = np.arange(B)
    write_features_reference(x, z, x_r, gamma, gamma_s, v, t, W, SF, SI, c.has_ref, obs, rows, cost, err, xnorm,
                             finite)
    # 5: reward and termination
    if c.reward_code == 1:  # log
        shaped = np.where(cost < np.inf, np.log1p(cost / c.log_c0), np.inf)
    elif c.reward_code == 2:  # sqrt
        shaped = np.sqrt(cost)
    else:
        shaped = cost
    rw = -shaped * period
    bound = (xnorm > c.state_bound) & np.all(np.isfinite(x), axis=1)  # a finite plant beyond the bound: reason 1
    non_finite = ~finite & ~bound
    tm = non_finite | bound
    rw = np.where(tm & ~np.isfinite(rw), -c.bound_step_cost, rw)
    if c.termination_penalty:
        rw = np.where(tm, rw - c.bound_step_cost * np.maximum(0, c.penalty_cycles - cycles), rw)
    tr = ~tm & (c.max_cycles >= 0) & (cycles >= c.max_cycles)
    reason[:] = np.where(non_finite, REASON_NON_FINITE, np.where(bound, REASON_STATE_BOUND,
                                                                  np.where(tr, REASON_HORIZON, REASON_NONE)))
    reward[:], term[:], trunc[:] = rw, tm, tr
    o2 = obs.reshape(B, -1)
    o2[tm] = np.nan_to_num(o2[tm], nan=0.0, posinf=c.big_obs, neginf=-c.big_obs)
    W[tm, :F] = np.nan_to_num(W[tm, :F])


def _adjacency(nbr_idx, nbr_w, N):
    adj = np.zeros((N, N))
    for i in range(N):
        for j, a in zip(nbr_idx[i], nbr_w[i]):
            if a != 0.0:
                adj[i, j] = a
    return adj
