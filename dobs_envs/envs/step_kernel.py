"""One environment step of every copy of a batch, compiled, with or without communication faults.

:func:`advance_batch` does, for every copy ``b`` (:func:`advance_range` for a range of copies,
which threads may run concurrently on disjoint ranges: it releases the GIL):

1. clip the input ``u[b]`` to ``[u_lo, u_hi]`` into the copy's work row (the applied input);
2. with the "random" disturbance, set ``v[b] = sum_l a sin(w t + phi)`` at the period's start (held);
3. simulate one control period (:func:`dobs_envs.sim.period_kernel.advance_rows`: SIMD tiles across
   copies) with the held input and the held reference command ``r^k(t)`` of eq. (refxdy) (the
   ``r`` block of the copy's feature vector, written at ``t`` by the previous step or reset);
4. ``t += T``, ``cycles += 1``; features, observations and the stage cost
   (:func:`dobs_envs.envs.features.features_row`);
5. reward ``-c * T`` (quadratic) or ``-log(1 + c / c0) * T`` (log); termination with reason
   code 1 (``||x|| > state_bound`` with every entry of ``x`` finite, whatever the other quantities)
   or else 2 (non-finite state: the kernel's finiteness flag); on
   termination a non-finite reward becomes ``-bound_step_cost``, the termination penalty
   ``bound_step_cost * max(0, penalty_cycles - cycles)`` is charged, and the copy's
   observations and feature vector are cleaned (NaN -> 0, +-inf -> +-largest finite value of
   their dtype); otherwise truncation (reason 3) when ``cycles >= max_cycles >= 0``.

Communication faults (the core's ``faults`` option): the argument ``fault`` is
:data:`~dobs_envs.sim.fault_state.NO_FAULT` (an empty tuple: numba compiles the step without any fault
code, the ``if len(fault) == 0:`` branches are pruned per specialisation, both ways) or the plain tuple ``(fp, fs, rx, fconsts)`` of :func:`~dobs_envs.envs.features.env_fault`.
Then step 3 is the faulted control period (:class:`~dobs_envs.sim.fault_kernel.FaultPeriod`), step 4
computes the features with the period's held measurement noise (``y_i = C_i x + n_i``, the draw the
observer node uses) and, per chunk of :data:`ROWS_CHUNK` copies, what the agents observe at the boundary
(:func:`~dobs_envs.envs.features.fault_rows`: the C-O link, the O-O copies held, the masks), before step 5.

Nothing is modified when some input is not finite: the kernel returns the first such copy
(else -1). The readable numpy reference is :func:`dobs_envs.envs.numpy_advance.advance_reference`.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..numba_cache import ensure_fresh
from ..sim.kernel_args import StateArrays
from ..sim.period_kernel import PeriodArrays, advance_rows, unpack_kernel_args
from ..sim.fault_kernel import FaultPeriod
from .features import env_fault, fault_rows, features_row, offsets, unpack_static

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

try:
    import numba as _numba

    _njit = _numba.njit(cache=True, fastmath=False, nogil=True)
    _njit_inline = _numba.njit(cache=True, fastmath=False, nogil=True, inline="always")
except ImportError:  # pragma: no cover
    def _njit(f):
        return f

    _njit_inline = _njit

__all__ = ["StepConsts", "StepOutputs", "advance_batch", "advance_range", "apply_inputs", "finish_row",
           "first_non_finite", "ROWS_CHUNK", "REASON_NONE", "REASON_STATE_BOUND", "REASON_NON_FINITE", "REASON_HORIZON"]

#: copies whose features, faulted observations and step results are written together by
#: :func:`advance_range` with faults (their rows stay in the cache between the three passes)
ROWS_CHUNK = 64

#: reason codes (int8) of a step
REASON_NONE, REASON_STATE_BOUND, REASON_NON_FINITE, REASON_HORIZON = 0, 1, 2, 3


class StepConsts(NamedTuple):
    """The scalar constants of one step of a core (:class:`~dobs_envs.envs.env_core.EnvCore` builds them by
    name). The compiled step receives them as a plain tuple in this field order (``tuple(consts)``:
    a named tuple costs ~1.5 us more per compiled call to dispatch) and reads them by name
    (``c = StepConsts(*consts)``, free in compiled code)."""

    u_lo: np.ndarray  # (m,) lower input bounds (clip)
    u_hi: np.ndarray  # (m,) upper input bounds
    period: float  # control period T
    state_bound: float  # ||x|| beyond which a copy terminates (reason 1)
    bound_step_cost: float  # cost of one control step on the bound (terminal penalty unit)
    log_c0: float  # cost scale of the log reward
    big_obs: float  # largest finite value of the observation dtype (cleaning)
    max_cycles: int  # truncation horizon in control steps (-1: none)
    penalty_cycles: int  # horizon charged by the termination penalty
    has_ref: bool  # tracking task (reference command)
    reward_code: int  # 0 quadratic, 1 log, 2 sqrt
    termination_penalty: bool  # charge bound_step_cost for every remaining step on termination
    random_v: bool  # the "random" disturbance (v set from the per-copy signal at each period's start)


class StepOutputs(NamedTuple):
    """The step's per-copy outputs by name: the rows of ``outs = (outf (4, B), outb (3, B), reason, cycles)``
    (:func:`step_outputs`, the one place that knows the row order)."""

    reward: np.ndarray  # (B,) float64
    cost: np.ndarray  # (B,) stage cost e'Qe + u'Ru
    err: np.ndarray  # (B,) ||e||
    xnorm: np.ndarray  # (B,) ||x||
    finite: np.ndarray  # (B,) bool: the whole simulated state is finite
    terminated: np.ndarray  # (B,) bool
    truncated: np.ndarray  # (B,) bool
    reason: np.ndarray  # (B,) int8 reason codes
    cycles: np.ndarray  # (B,) int64 control steps since the reset


@_njit_inline
def step_outputs(outs):
    """:class:`StepOutputs` of the buffers ``outs = (outf, outb, reason, cycles)`` (views)."""
    outf, outb, reason, cycles = outs
    return StepOutputs(outf[0], outf[1], outf[2], outf[3], outb[0], outb[1], outb[2], reason, cycles)


@_njit
def first_non_finite(u):
    """Index of the first copy whose input row has NaN/inf, or -1."""
    for b in range(u.shape[0]):
        if not _row_finite(u, b):
            return b
    return -1


@_njit
def _row_finite(a, b):
    """Whether every entry of row ``b`` of the 2-D array ``a`` is finite."""
    for j in range(a.shape[1]):
        if not np.isfinite(a[b, j]):
            return False
    return True


@_njit
def _clean(a, b, big, ncols):
    """NaN -> 0, +-inf -> +-big in the first ``ncols`` entries of row ``b`` of the 2-D array ``a``."""
    for j in range(ncols):
        o = a[b, j]
        if np.isnan(o):
            a[b, j] = 0.0
        elif np.isinf(o):
            a[b, j] = big if o > 0 else -big


@_njit_inline
def apply_inputs(lo, hi, t, v, W, u, sig, ou, c):
    """Steps 1-2 for the copies ``lo .. hi-1``: the clipped input into ``W[b, ou:ou+m]``, the "random"
    disturbance ``v[b]`` at the period's start (``c`` the :class:`StepConsts`)."""
    u_lo, u_hi = c.u_lo, c.u_hi
    sig_a, sig_w, sig_ph = sig[0], sig[1], sig[2]
    m = u.shape[1]
    for b in range(lo, hi):
        for j in range(m):
            uj = u[b, j]
            W[b, ou + j] = u_lo[j] if uj < u_lo[j] else (u_hi[j] if uj > u_hi[j] else uj)
        if c.random_v:
            tb = t[b]
            for j in range(v.shape[1]):
                s = 0.0
                for l in range(sig_a.shape[2]):
                    s += sig_a[b, j, l] * np.sin(sig_w[b, j, l] * tb + sig_ph[b, j, l])
                v[b, j] = s


@_njit_inline
def finish_row(b, cb, xn, fin, x, W, F, obs2, o, c):
    """Step 5 of copy ``b`` from its stage cost ``cb``, ``||x||`` ``xn`` and finiteness ``fin``: reward,
    termination (reason codes), truncation, cleaning of a terminal copy's observations and features
    (``o`` the :class:`StepOutputs`, ``c`` the :class:`StepConsts`)."""
    reward, term, trunc, reason, cycles = o.reward, o.terminated, o.truncated, o.reason, o.cycles
    if c.reward_code == 1:  # log
        shaped = np.log1p(cb / c.log_c0) if cb < np.inf else np.inf
    elif c.reward_code == 2:  # sqrt
        shaped = np.sqrt(cb)
    else:
        shaped = cb
    rw = -shaped * c.period
    if xn > c.state_bound and _row_finite(x, b):  # a finite plant state beyond the bound: reason 1
        tm, rs = True, REASON_STATE_BOUND
    elif not fin:
        tm, rs = True, REASON_NON_FINITE
    else:
        tm, rs = False, REASON_NONE
    tr = False
    if tm:
        _clean(obs2, b, c.big_obs, obs2.shape[1])
        _clean(W, b, np.finfo(np.float64).max, F)  # the feature vector; est/u stay raw (diagnostics)
        if not np.isfinite(rw):
            rw = -c.bound_step_cost
        if c.termination_penalty:
            rw -= c.bound_step_cost * max(0, c.penalty_cycles - cycles[b])
    elif c.max_cycles >= 0 and cycles[b] >= c.max_cycles:
        tr, rs = True, REASON_HORIZON
    reward[b] = rw
    term[b] = tm
    trunc[b] = tr
    reason[b] = rs


@_njit
def advance_range(lo, hi, u, args, fault):
    """Steps 1-5 (module docstring) for the copies ``lo .. hi-1``; releases the GIL: threads may advance
    disjoint ranges of one batch concurrently. ``args`` the plain tuple ``(state, W, obs, outs, sig, ka, SF,
    SI, consts)`` (:func:`advance_batch`'s arguments but ``u``), ``fault`` NO_FAULT or the faults' plain
    tuple (module doc). Returns -1, or the first copy of the range whose input is not finite: then nothing
    was modified (a caller running several ranges checks the whole batch first, :func:`first_non_finite`)."""
    for b in range(lo, hi):
        if not _row_finite(u, b):
            return b
    state, W, obs, outs, sig, kp, SF, SI, consts = args
    KF, KI = kp
    ka = unpack_kernel_args(KF, KI)
    fa = unpack_static(SF, SI)
    c = StepConsts(*consts)
    st = StateArrays(*state)
    o = step_outputs(outs)
    t, x = st.t, st.x
    cost, err, xnorm, finite, cycles = o.cost, o.err, o.xnorm, o.finite, o.cycles
    F = fa.F
    N = st.z.shape[1]
    m = u.shape[1]
    ou = F + N
    o_r = offsets(fa.off).r
    # 1-2: applied inputs, disturbance at the period's start
    apply_inputs(lo, hi, t, st.v, W, u, sig, ou, c)
    # 3: one control period (held input and reference command)
    pa = PeriodArrays(x, st.z, st.gamma, st.gamma_s, st.v, st.x_r, W[:, ou:ou + m], W[:, o_r:o_r + m])
    if len(fault) == 0:
        advance_rows(pa, ka, lo, hi, fault)
    else:
        ef = env_fault(fault)
        noisy = ef.args.noise_std > 0.0
        noise_a = ef.state.noise
        delivered = np.empty((x.shape[0], ef.args.sender.shape[0]), dtype=np.bool_)  # the period's (not observed)
        advance_rows(pa, ka, lo, hi, FaultPeriod(ef.args, ef.state, delivered))
    # 4-5: features, reward, termination
    obs2 = obs.reshape((obs.shape[0], obs.shape[1] * obs.shape[2]))
    y = np.empty(fa.C.shape[1])
    if len(fault) == 0:
        for b in range(lo, hi):
            t[b] = t[b] + c.period
            cycles[b] += 1
            cb, e, xn, fin = features_row(b, st, W, fa, c.has_ref, obs2, y, None)
            cost[b] = cb
            err[b] = e
            xnorm[b] = xn
            finite[b] = fin
            finish_row(b, cb, xn, fin, x, W, F, obs2, o, c)
    else:
        # per chunk: features (with the held noise), the faulted observations, then reward and termination
        # (from the stored cost, ||x|| and finiteness): per copy the order of the unfaulted step
        for b0 in range(lo, hi, ROWS_CHUNK):
            b1 = min(b0 + ROWS_CHUNK, hi)
            for b in range(b0, b1):
                t[b] = t[b] + c.period
                cycles[b] += 1
                if noisy:
                    cb, e, xn, fin = features_row(b, st, W, fa, c.has_ref, obs2, y, noise_a)
                else:
                    cb, e, xn, fin = features_row(b, st, W, fa, c.has_ref, obs2, y, None)
                cost[b] = cb
                err[b] = e
                xnorm[b] = xn
                finite[b] = fin
            fault_rows(b0, b1, st, W, obs2, fa, ef, True)
            for b in range(b0, b1):
                finish_row(b, cost[b], xnorm[b], finite[b], x, W, F, obs2, o, c)
    return -1


def advance_batch(state, W, obs, outs, u, sig, ka, SF, SI, consts, fault):
    """One step of every copy (see module docstring), serial: :func:`advance_range` over all copies (not a
    compiled function around it: numba would link, optimise and compile to machine code the whole step
    again for that level, ~10 CPU s of every cold compile on the ideal network, ~15 s faulted).

    Parameters
    ----------
    state : (t (B,), x (B, n), z (B, N, n), gamma (B, N), gamma_s (B, N), v (B, m_v), x_r (B, n)), the
        fields of :class:`~dobs_envs.sim.kernel_args.StateArrays` as a plain tuple, updated in place.
    W : (B, F + N + m) work rows ``[f | est | u]``; obs : (B, K, D) padded observations.
    outs : (outf (4, B) float64 rows reward, cost, ||e||, ||x||; outb (3, B) bool rows finite,
        terminated, truncated; reason (B,) int8; cycles (B,) int64), written (:class:`StepOutputs`).
    u : (B, m) float64 requested inputs (read).
    sig : (3, B, m_v, L): amplitudes, frequencies, phases of the "random" disturbance.
    ka : ``SimParams.kernel_packed`` (KF, KI); SF, SI : :func:`~dobs_envs.envs.features.pack_static`.
    consts : a plain tuple of the fields of :class:`StepConsts`, in its field order.
    fault : NO_FAULT (``()``), or ``(fp, fs, rx, fconsts)`` (:func:`~dobs_envs.envs.features.env_fault`): ``fs`` and
        ``rx`` updated.

    Returns
    -------
    int : -1, or the first copy whose input is not finite (then nothing was modified).
    """
    return advance_range(0, u.shape[0], u, (state, W, obs, outs, sig, ka, SF, SI, consts), fault)
