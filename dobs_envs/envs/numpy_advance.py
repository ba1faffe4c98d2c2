"""Reference (pure numpy) implementation of one batched environment step.

:func:`advance_reference` has the signature and the effects of the compiled
:func:`dobs_envs.envs.step_kernel.advance_batch` and is the specification it is
tested against (``tests/test_core.py``): the simulation is
:func:`dobs_envs.sim.numpy_step.control_period_numpy`, the features
:func:`dobs_envs.envs.numpy_features.write_features_reference`, and the reward and
termination rules are written out below, vectorised over the copies.

With ``fault`` (communication faults, the same argument as the compiled step's) the simulation
is :func:`dobs_envs.sim.numpy_step.control_period_faulted_numpy`, and after the features the
agents' received quantities are written (:func:`_fault_observations`; what they are:
:func:`dobs_envs.envs.features.fault_rows`).
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..packing import unpack
from ..sim import fault_rng
from ..sim.fault_state import NO_FAULT, FaultArgs, FaultState, co_link_numpy, oo_losses
from ..sim.kernel_args import StateArrays, unpack_kernel_args
from ..sim.numpy_step import control_period_faulted_numpy, control_period_numpy
from .features import FeatureArgs
from .numpy_features import write_features_reference
from .step_kernel import REASON_HORIZON, REASON_NON_FINITE, REASON_NONE, REASON_STATE_BOUND, StepConsts

__all__ = ["advance_reference"]


def advance_reference(state, W, obs, outs, u, sig, ka, SF, SI, consts, fault=NO_FAULT):
    """Numpy counterpart of :func:`~dobs_envs.envs.step_kernel.advance_batch` (same arguments, same effects:
    with ``fault = (fp, fs, rx, fconsts)``, ``fs`` and ``rx`` updated in place)."""
    bad = np.flatnonzero(~np.all(np.isfinite(u), axis=1))
    if bad.size:
        return int(bad[0])
    if len(fault) > 0:
        fp, fs, rx, fconsts = fault
        fault = (unpack(FaultArgs, *fp), fs, rx, fconsts)
    with np.errstate(all="ignore"):
        _advance(state, W, obs, outs, u, sig, ka, SF, SI, consts, fault)
    return -1


def _fault_observations(x, z, W, obs, fa, ff, fs, rx, fconsts, link: bool):
    """What the agents receive at the boundary (:func:`dobs_envs.envs.features.fault_rows`): noisy
    ``y``/``xhat``/estimation errors into ``W``, the C-O link (``link``), the O-O copies held at the boundary
    instant, the masks ``rx``; then the observation gathers. ``fs`` a :class:`FaultState` (its C-O buffers are
    the arrays of the caller's tuple); returns it."""
    F, C, G, off, idx = fa.F, fa.C, fa.G, fa.off, fa.idx
    B, N, n = z.shape
    co_nodes, foff = fconsts
    K, E = co_nodes.shape[0], ff.sender.shape[0]
    co_rx, oo_rx = rx
    if ff.noise_std > 0:
        y = np.einsum("ipn,bn->bip", C, x) + fs.noise
        p_i = off[10:10 + N]
        W[:, off[0]:off[0] + int(p_i.sum())] = np.concatenate([y[:, i, :p_i[i]] for i in range(N)], axis=1)
        xhat = z + np.einsum("inp,bip->bin", G, y)
        W[:, off[1]:off[1] + N * n] = xhat.reshape(B, N * n)
        W[:, F:F + N] = np.linalg.norm(xhat - x[:, None, :], axis=2)
    xh = W[:, off[1]:off[1] + N * n].reshape(B, N, n)
    if link:
        held, new = co_link_numpy(xh[:, co_nodes], fs, ff)
        fs.co_sent[...], fs.co_held[...] = new.co_sent, new.co_held
        lost = np.zeros((B, K), dtype=bool)
        if ff.co_loss > 0:
            lost = fault_rng.uniform(fs.seed[:, None], fault_rng.STREAM_CO_LOSS, fs.period[:, None],
                                     np.arange(K)[None, :]) < ff.co_loss
        co_rx[...] = ~lost
    else:
        co_rx[...] = True
    s = fs.period * ff.substeps
    due = np.full(B, True) if ff.continuous else (s % ff.exchange_steps == 0)
    fresh = due[:, None] & (ff.weight[fs.graph] > 0) & ~oo_losses(ff, fs)
    if ff.lag > 0:
        old = (s // ff.exchange_steps - ff.lag) % ff.ring
        src = fs.snapshots[np.arange(B), old][:, ff.sender]
    else:
        src = xh[:, ff.sender]
    oo_rx[...] = fresh
    W[:, foff[0]:foff[0] + K * n] = fs.co_held.reshape(B, K * n)
    W[:, foff[1]:foff[1] + E * n] = np.where(fresh[..., None], src, fs.received).reshape(B, E * n)
    W[:, foff[2]:foff[2] + K] = co_rx
    W[:, foff[3]:foff[3] + E] = oo_rx
    obs.reshape(B, -1)[...] = W[:, idx]
    return fs


def _advance(state, W, obs, outs, u, sig, ka, SF, SI, consts, faults):
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
    if len(faults) == 0:
        x[:], z[:], gamma[:], gamma_s[:], v[:], x_r[:] = control_period_numpy(x, z, gamma, gamma_s, v, x_r, U, Rc, p)
    else:
        ff, fs_arrays, rx, fconsts = faults
        fs = FaultState(*fs_arrays)
        *new, fs_new = control_period_faulted_numpy(x, z, gamma, gamma_s, v, x_r, U, Rc, p, ff, fs)
        x[:], z[:], gamma[:], gamma_s[:], v[:], x_r[:] = new
        for dst, src in zip(fs_arrays, fs_new):
            dst[...] = src
    # 4: time, features, cost
    t += period
    cycles += 1
    rows = np.arange(B)
    write_features_reference(rows, state, W, obs, SF, SI, c.has_ref, (cost, err, xnorm, finite))
    if len(faults) > 0:
        _fault_observations(x, z, W, obs, fa, ff, fs, rx, fconsts, link=True)
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
