"""numba-compiled control period with communication faults (issue 23; :mod:`.faults` for the semantics).

The compiled counterpart of :func:`~dobs_envs.sim.numpy_step.control_period_faulted_numpy` (tested
against it, ``tests/test_fault_kernel.py``) and of :func:`~dobs_envs.sim.fault_state.co_link_numpy`.
Used only when faults are on: ``faults=None`` runs :mod:`.period_kernel` as before, untouched.

Per copy. :func:`period_copy_faulted` advances one copy ``b`` of the batch-first arrays over one
control period with the same Euler steps as :func:`~dobs_envs.sim.period_kernel.period_copy` (the
same sparse products, the same stable-step test and split steps, "Stable steps" in
:mod:`.period_kernel`) and these changes:

- the period's O-O deliveries: link ``e`` of the copy's active graph ``g`` delivers unless its
  packet is lost (probability ``oo_loss``, or ``loss_bad``/``loss_good`` by its Gilbert-Elliott
  state), drawn from :mod:`.fault_rng` by (seed, stream, period, link);
- the measurement noise of the period (held) added to every ``y_i`` (eq. (localmeasure)), so
  it enters eqs. (hatxieq) and (zidynamic);
- the consensus term of eq. (H_idefine) over the received copies,
  ``d_i = sum_{e: receiver e = i} a_e^g (xhat_i - r_e)``, the active graph's degrees in the
  stable-step test;
- broadcasts at the Euler steps ``s`` (counted from the copy's reset) that are multiples of
  ``exchange_steps``: every delivering link takes the sender's estimate (``oo_delay = 0``) or the
  snapshot of ``lag`` broadcasts before from the copy's ring; with the continuous exchange
  (``oo_period=None``, no delay) the received copies are refreshed at every shortened step of a
  split Euler step too.

After the period :func:`_draws_rows` makes the next period's draws (graph chain, burst chains,
noise) and advances the period counter, as :func:`~dobs_envs.sim.fault_state.period_draws`
(:func:`period_draws_compiled`: the same draws for any periods, e.g. the first at a reset).
:func:`co_link_rows` is the C-O link of a range of copies at their control-period boundaries
(:func:`co_link_row` of one copy).

The arithmetic is the compiled kernel's (sparse sums in column order, FMA contraction allowed:
:data:`~dobs_envs.sim.period_kernel.FASTMATH`), so the continuous state agrees with the numpy
reference to rounding (the tolerance of the existing kernel/reference parity); every draw, the
graph and burst states, the noise, the period counter and the C-O buffers' bookkeeping are
bitwise those of the reference. A copy's result depends on its own state and seed only (batch
independence, bit for bit).

The fault state arrives as the plain tuple of :class:`~dobs_envs.sim.fault_state.FaultState`'s
fields in declaration order (``tuple(fs)``), unpacked positionally in :func:`_fields`; the
constants as :class:`~dobs_envs.sim.fault_state.FaultArgs` packed by :func:`dobs_envs.packing.pack`
and read by name (:func:`unpack_fault_args`, generated from the declaration).
"""
from __future__ import annotations

import numpy as np

from ..numba_cache import ensure_fresh
from ..packing import compiled_unpack, pack
from . import fault_rng as frng
from .fault_state import FaultArgs, FaultState
from .period_kernel import (FASTMATH, MAX_SPLIT, MIN_TILE, TILE, TILE_RECHECK, _crit, _gather, _scratch_copy,
                            _scratch_tile, _stable_step, _terms, _tile_dot, unpack_kernel_args)

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

import numba  # noqa: E402  (a hard dependency; the numpy reference needs nothing from here)

_njit = numba.njit(cache=True, fastmath=FASTMATH, nogil=True, error_model="numpy")
_njit_inline = numba.njit(cache=True, fastmath=FASTMATH, nogil=True, error_model="numpy", inline="always")

__all__ = ["unpack_fault_args", "loss_key", "delivers", "period_copy_faulted", "advance_rows_faulted", "co_link_row",
           "co_link_rows", "period_draws_compiled",
           "control_period_faulted_compiled", "co_link_compiled", "FAULT_STATE_FIELDS"]

#: the order of the fault-state tuple the kernels receive (``tuple(FaultState)``)
FAULT_STATE_FIELDS = FaultState._fields
_OO_LOSS = np.uint64(frng.STREAM_OO_LOSS)
_OO_BURST = np.uint64(frng.STREAM_OO_BURST)
_CO_LOSS = np.uint64(frng.STREAM_CO_LOSS)
_SWITCHING = np.uint64(frng.STREAM_SWITCHING)
_NOISE = np.uint64(frng.STREAM_NOISE)
_U0 = np.uint64(0)

#: ``unpack_fault_args(FF, FI)``: the :class:`~dobs_envs.sim.fault_state.FaultArgs` packed by
#: :func:`dobs_envs.packing.pack` (views; bool scalars as bool), compiled from the declaration.
unpack_fault_args = compiled_unpack(FaultArgs, _njit, "unpack_fault_args")


@_njit_inline
def _fields(fs):
    """The arrays of the fault-state tuple, in :class:`FaultState` order."""
    seed, period, received, snapshots, bad, graph, noise, co_sent, co_held = fs
    return seed, period, received, snapshots, bad, graph, noise, co_sent, co_held


@_njit
def _scratch_fault(fa, N):
    """Work arrays of :func:`period_copy_faulted`: the active graph's degrees ``(N,)``, link weights
    ``(E,)`` and deliveries ``(E,)``."""
    E = fa.sender.shape[0]
    return np.empty(N), np.empty(E), np.zeros(E, dtype=np.bool_)


@_njit_inline
def _take(rec, src, sender, deliver, n):
    """``rec[e] = src[sender[e]]`` (``src`` flat, node ``j`` at ``j * n``) for every delivering link."""
    for e in range(sender.shape[0]):
        if deliver[e]:
            js = sender[e] * n
            for c in range(n):
                rec[e, c] = src[js + c]


@_njit_inline
def loss_key(seed_a, b, k):
    """The :func:`~dobs_envs.sim.fault_rng.period_key` of copy ``b``'s O-O losses in period ``k``."""
    return frng.period_key(seed_a[b], _OO_LOSS, np.uint64(k))


@_njit_inline
def delivers(b, e, fa, key, bad_a, g):
    """Whether link ``e`` of copy ``b`` delivers in the period of the loss key ``key`` (:func:`loss_key`)
    with active graph ``g``: it is in ``g`` and does not lose the period's packets (probability
    ``oo_loss``, or ``loss_bad``/``loss_good`` by its burst state ``bad_a[b, e]``;
    :func:`~dobs_envs.sim.fault_state.oo_losses`)."""
    if not fa.weight[g, e] > 0.0:
        return False
    if fa.burst:
        pl = fa.loss_bad if bad_a[b, e] else fa.loss_good
    else:
        pl = fa.oo_loss
    if pl > 0.0:
        return not frng.uniform_at(key, np.uint64(e)) < pl
    return True


@_njit
def period_copy_faulted(b, x, z, gamma, gamma_s, v, x_r, u, r, ka, fa, fs, delivered, sc, fsc):
    """One faulted control period of copy ``b`` in place (module doc; shapes as
    :func:`~dobs_envs.sim.period_kernel.period_copy`).

    ``fa`` the unpacked :class:`FaultArgs`; ``fs`` the fault-state tuple (its received copies and
    snapshot ring of copy ``b`` are updated; the period's draws are read, not advanced: see
    :func:`_draws_rows`); ``delivered (B, E)`` bool receives the period's deliveries (links of the
    active graph that did not lose their packets); ``sc``/``fsc`` work arrays
    (:func:`~dobs_envs.sim.period_kernel._scratch_copy`, :func:`_scratch_fault`).
    """
    rows = ka.rows
    proj_range = ka.proj_range
    phi, phi_s, sigma, sigma_s = ka.phi, ka.phi_s, ka.sigma, ka.sigma_s
    dt, substeps, has_reference = ka.dt, ka.substeps, ka.has_reference
    y, xhat, d, cq, w, bu, Bu, Br, zn, xdot, xrdot, vnew, nwv, nw2v, coef = sc
    deg, wl, deliver = fsc
    seed_a, period_a, received_a, snapshots_a, bad_a, graph_a, noise_a, co_sent_a, co_held_a = _fields(fs)
    sender, receiver = fa.sender, fa.receiver
    E = sender.shape[0]
    N, n = z.shape[1], z.shape[2]
    p, mv = ka.C.shape[1], ka.B_v.shape[1]
    k = period_a[b]
    g = graph_a[b]
    rec = received_a[b]  # (E, n) held copies r_e
    snaps = snapshots_a[b]  # (R, N, n)
    # the period's deliveries (fault_state.oo_losses) and the active graph
    for i in range(N):
        deg[i] = fa.degree[g, i]
    key = loss_key(seed_a, b, k)
    for e in range(E):
        wl[e] = fa.weight[g, e]
        dl = delivers(b, e, fa, key, bad_a, g)
        deliver[e] = dl
        delivered[b, e] = dl
    M, lag, ring = fa.exchange_steps, fa.lag, fa.ring
    continuous = fa.continuous
    refresh = continuous and lag == 0
    noisy = fa.noise_std > 0.0
    xb, xrb, vb, ub, rb = x[b], x_r[b], v[b], u[b], r[b]
    zb = z[b].reshape(N * n)
    bu[:] = 0.0
    _terms(bu, rows.B_bar, ub)
    Bu[:] = 0.0
    _terms(Bu, rows.B, ub)
    Br[:] = 0.0
    _terms(Br, rows.B, rb)
    hmin = dt / MAX_SPLIT
    for j in range(substeps):
        tau = dt
        h = dt
        split = False
        first = True
        while True:
            # eq. (localmeasure) with the held noise, eq. (hatxieq)
            for q in range(N * p):
                y[q] = 0.0
            _terms(y, rows.C, xb)
            if noisy:
                for i in range(N):
                    for q in range(p):
                        y[i * p + q] = y[i * p + q] + noise_a[b, i, q]
            for q in range(N * n):
                xhat[q] = zb[q]
            _terms(xhat, rows.G_bar, y)
            if first:
                s = k * substeps + j  # Euler steps since the copy's reset
                if continuous or s % M == 0:  # a broadcast
                    if lag > 0:
                        qb = s // M
                        slot = qb % ring
                        for i in range(N):
                            for c in range(n):
                                snaps[slot, i, c] = xhat[i * n + c]
                        old = snaps[(qb - lag) % ring]  # not yet written before lag broadcasts: t = 0
                        _take(rec, old.reshape(N * n), sender, deliver, n)
                    else:
                        _take(rec, xhat, sender, deliver, n)
            elif refresh:  # continuous exchange: fresh copies in the shortened steps too
                _take(rec, xhat, sender, deliver, n)
            # eq. (H_idefine) with held copies: d_i = sum_e a_e (xhat_i - r_e) over the links into i
            for q in range(N * n):
                d[q] = 0.0
            for e in range(E):
                a = wl[e]
                if a != 0.0:
                    ir = receiver[e] * n
                    for c in range(n):
                        d[ir + c] = d[ir + c] + a * (xhat[ir + c] - rec[e, c])
            # w_i = P_u,i d_i (as period_copy)
            rq = ka.Q_proj.shape[2]
            for q in range(N * rq):
                cq[q] = 0.0
            _terms(cq, rows.Q_projT, d)
            for q in range(N * n):
                w[q] = 0.0
            _terms(w, rows.Q_proj, cq)
            crit = 0.0
            for i in range(N):
                nw2 = 0.0
                for c in range(n):
                    s_ = w[i * n + c]
                    if not proj_range[i]:
                        s_ = d[i * n + c] - s_
                    w[i * n + c] = s_
                    nw2 = nw2 + s_ * s_
                nw = np.sqrt(nw2)
                nwv[i] = nw
                nw2v[i] = nw2
                coef[i] = gamma[b, i] + (gamma_s[b, i] / nw if nw > 0.0 else 0.0)
                if first:
                    c_ = _crit(deg[i], dt, gamma[b, i], phi[i], nw2)
                    if c_ > crit:
                        crit = c_
            if first:
                split = crit > 1.0
                first = False
            if split:
                hreq = tau
                for i in range(N):
                    hi = _stable_step(deg[i], gamma[b, i], phi[i], nw2v[i])
                    if hi < hreq:
                        hreq = hi
                if hreq != hreq:
                    h = tau
                elif hreq < hmin:
                    h = hmin
                else:
                    h = hreq
                if h >= tau:
                    h = tau
            for i in range(N):
                ci = coef[i]
                for c in range(n):
                    zn[i * n + c] = bu[i * n + c] - ci * w[i * n + c]
            _terms(zn, rows.E_bar, zb)
            _terms(zn, rows.F_bar, y)
            for q in range(N * n):
                zb[q] = zb[q] + h * zn[q]
            for i in range(N):
                g_ = gamma[b, i]
                gs = gamma_s[b, i]
                gamma[b, i] = g_ + h * (-sigma[i] * g_ + phi[i] * nw2v[i])
                gamma_s[b, i] = gs + h * (-sigma_s[i] * gs + phi_s[i] * nwv[i])
            for c in range(n):
                xdot[c] = Bu[c]
            _terms(xdot, rows.A, xb)
            _terms(xdot, rows.B_v, vb)
            if has_reference:
                for c in range(n):
                    xrdot[c] = Br[c]
                _terms(xrdot, rows.A_r, xrb)
                for c in range(n):
                    xrb[c] = xrb[c] + h * xrdot[c]
            for c in range(n):
                xb[c] = xb[c] + h * xdot[c]
            if h >= tau:
                break
            tau = tau - h
        for jv in range(mv):
            vnew[jv] = 0.0
        _terms(vnew, rows.Phi_v, vb)
        for jv in range(mv):
            vb[jv] = vnew[jv]


@_njit
def _period_draws_rows(lo, hi, fa, seed_a, period_a, graph_a, bad_a, noise_a):
    """The draws of period ``period_a[b]`` of copies ``lo .. hi-1``, in place (as
    :func:`~dobs_envs.sim.fault_state.period_draws`): period 0 the graph ``initial_graph`` and burst states
    from the stationary distribution, a later period one step of the graph chain from ``graph_a[b]`` and of
    each link's burst chain from ``bad_a[b]``; the measurement noise (``noise_a`` untouched without it). The
    arrays are taken out of their tuples by the caller, once for the range (per copy, each unpacked array
    cost an atomic reference count update on entry and exit)."""
    cum_transition, last_state = fa.cum_transition, fa.last_state
    noise_mask = fa.noise_mask
    switching, burst, initial_graph = fa.switching, fa.burst, fa.initial_graph
    p_bad_good, p_good_bad, stationary_bad, noise_std = fa.p_bad_good, fa.p_good_bad, fa.stationary_bad, fa.noise_std
    E = fa.sender.shape[0]
    N, P = noise_mask.shape
    G = cum_transition.shape[1]
    for b in range(lo, hi):
        seed = seed_a[b]
        k = period_a[b]
        first = k == 0
        ku = np.uint64(k)
        if not switching:
            graph_a[b] = 0
        elif first:
            graph_a[b] = initial_graph
        else:
            g = graph_a[b]
            thr = frng.uniform_at(frng.period_key(seed, _SWITCHING, ku), _U0) * cum_transition[g, G - 1]
            nxt = 0
            for c in range(G):
                if cum_transition[g, c] <= thr:
                    nxt += 1
            last = last_state[g]
            graph_a[b] = nxt if nxt < last else last
        if burst:
            key = frng.period_key(seed, _OO_BURST, ku)
            for e in range(E):
                uu = frng.uniform_at(key, np.uint64(e))
                if first:
                    bad_a[b, e] = uu < stationary_bad
                elif bad_a[b, e]:
                    bad_a[b, e] = uu >= p_bad_good  # stays bad unless it recovers
                else:
                    bad_a[b, e] = uu < p_good_bad
        else:
            for e in range(E):
                bad_a[b, e] = False
        if noise_std > 0.0:
            key = frng.period_key(seed, _NOISE, ku)
            for i in range(N):
                for q in range(P):
                    zq = frng.normal_at(key, np.uint64(i * P + q))
                    noise_a[b, i, q] = noise_std * zq * noise_mask[i, q]


@_njit
def _draws_rows(lo, hi, fa, fs):
    """The period counters of copies ``lo .. hi-1`` ``+ 1`` and the draws of their new period
    (:func:`_period_draws_rows`)."""
    seed_a, period_a, received_a, snapshots_a, bad_a, graph_a, noise_a, co_sent_a, co_held_a = _fields(fs)
    for b in range(lo, hi):
        period_a[b] = period_a[b] + 1
    _period_draws_rows(lo, hi, fa, seed_a, period_a, graph_a, bad_a, noise_a)


@_njit
def _period_draws(FF, FI, seed, period, graph, bad, noise):
    _period_draws_rows(0, seed.shape[0], unpack_fault_args(FF, FI), seed, period, graph, bad, noise)


def period_draws_compiled(fa: FaultArgs, seed, period, graph_prev, bad_prev, *, packed=None):
    """Compiled counterpart of :func:`~dobs_envs.sim.fault_state.period_draws` (same arguments and returns,
    bitwise the same draws: :mod:`.fault_rng`), e.g. as ``init_fault_state(..., draws=...)`` at the resets of
    an environment. ``packed``: ``fa`` already packed (:func:`dobs_envs.packing.pack`), to skip packing."""
    FF, FI = pack(fa) if packed is None else packed
    seed = np.ascontiguousarray(seed, dtype=np.uint64).reshape(-1)
    B = seed.shape[0]
    E = fa.sender.shape[0]
    period = np.ascontiguousarray(np.broadcast_to(np.asarray(period, dtype=np.int64), (B,)))
    graph = np.array(np.broadcast_to(np.asarray(graph_prev, dtype=np.int64), (B,)), order="C")
    bad = np.array(np.broadcast_to(np.asarray(bad_prev, dtype=np.bool_), (B, E)), order="C")
    noise = np.zeros((B,) + fa.noise_mask.shape)
    _period_draws(FF, FI, seed, period, graph, bad, noise)
    return graph, bad, noise


@_njit
def _scratch_fault_tile(fa, N, n, p, W):
    """Per-lane fault arrays of :func:`_tile_faulted`: received copies ``REC (E, n, W)``, noise ``NZ (N, p, W)``,
    degrees ``DEG (N, W)``, link weights ``WL (E, W)``, deliveries ``DL (E, W)``, periods ``KP (W,)``, the
    Euler step count of the period's start modulo ``exchange_steps`` ``PH (W,)``, broadcast flags ``BC (W,)``;
    with ``oo_delay > 0`` the period's snapshots ``TSN (nb, N, n, W)``, their ring slots ``TSLOT (nb, W)`` and
    counts ``TCNT (W,)`` (``nb`` the most broadcasts in a period); a lane mask ``MK (W,)``; the links into each
    node, ``LK[LP[i]:LP[i+1]]`` in increasing order (without faults switching graphs: only those of nonzero
    weight)."""
    E = fa.sender.shape[0]
    nb = fa.substeps // fa.exchange_steps + 1 if fa.lag > 0 else 0
    LK = np.empty(E, dtype=np.int64)
    LP = np.zeros(N + 1, dtype=np.int64)
    t = 0
    for i in range(N):
        LP[i] = t
        for e in range(E):
            if fa.receiver[e] == i and (fa.switching or fa.weight[0, e] != 0.0):
                LK[t] = e
                t += 1
    LP[N] = t
    return (np.empty((E, n, W)), np.zeros((N, p, W)), np.empty((N, W)), np.empty((E, W)),
            np.zeros((E, W), dtype=np.bool_), np.zeros(W, dtype=np.int64), np.zeros(W, dtype=np.int64),
            np.zeros(W, dtype=np.bool_),
            np.empty((nb, N, n, W)), np.zeros((nb, W), dtype=np.int64), np.zeros(W, dtype=np.int64),
            np.zeros(W, dtype=np.bool_), LK, LP)


@_njit
def _gather_fault(ft, lo, nl, fa, fs, N, p):
    """The fault state of copies ``lo .. lo+nl-1`` into the tile arrays ``ft`` (lanes past ``nl`` repeat the
    last copy), with each lane's deliveries of the period (:func:`delivers`)."""
    REC, NZ, DEG, WL, DL, KP, PH, BC, TSN, TSLOT, TCNT, MK, LK, LP = ft
    seed_a, period_a, received_a, snapshots_a, bad_a, graph_a, noise_a, co_sent_a, co_held_a = _fields(fs)
    W = KP.shape[0]
    E, n = REC.shape[0], REC.shape[1]
    for c in range(W):
        b = lo + (c if c < nl else nl - 1)
        g = graph_a[b]
        KP[c] = period_a[b]
        TCNT[c] = 0
        key = loss_key(seed_a, b, period_a[b])
        for i in range(N):
            DEG[i, c] = fa.degree[g, i]
            for q in range(p):
                NZ[i, q, c] = noise_a[b, i, q]
        for e in range(E):
            WL[e, c] = fa.weight[g, e]
            DL[e, c] = delivers(b, e, fa, key, bad_a, g)
            for k in range(n):
                REC[e, k, c] = received_a[b, e, k]


@_njit_inline
def _tile_faulted(X, Z, G, GS, V, XR, U, R, ka, work, W, fa, ft, fs, lo):
    """One faulted control period of a tile of ``W`` copies (``lo ..``), copy axis last, in place: the body of
    :func:`~dobs_envs.sim.period_kernel._tile_body` with the faulted exchange of :func:`period_copy_faulted`
    (per lane: deliveries, active graph's degrees and weights, held noise, broadcasts at its own Euler step
    count). Per copy the same operations in the same order as :func:`period_copy_faulted` (a link of weight 0
    is skipped by a select), so every unflagged lane's result is bitwise the per-copy one. Snapshots
    (``oo_delay > 0``) are kept in the tile (``TSN``) and written into the batch's ring by
    :func:`_scatter_faulted` for the unflagged lanes only (a flagged lane is recomputed from the ring as it
    was); reads come from the batch's ring: no snapshot of a period is read in that period
    (``lag >= substeps / exchange_steps``)."""
    rows = ka.rows
    proj_range = ka.proj_range
    phi, phi_s, sigma, sigma_s = ka.phi, ka.phi_s, ka.sigma, ka.sigma_s
    dt, substeps, has_reference = ka.dt, ka.substeps, ka.has_reference
    Y, XH, D, CQ, Wv, BU, Bu, Br, ZN, XD, XRD, VN, nw2, coef, nw, FL = work
    REC, NZ, DEG, WL, DL, KP, PH, BC, TSN, TSLOT, TCNT, MK, LK, LP = ft
    snapshots_a = fs[3]
    sender, receiver = fa.sender, fa.receiver
    E = sender.shape[0]
    N, n = Z.shape[0], Z.shape[1]
    p, mv = ka.C.shape[1], ka.B_v.shape[1]
    rq = ka.Q_proj.shape[2]
    M, lag, ring = fa.exchange_steps, fa.lag, fa.ring
    continuous = fa.continuous
    noisy = fa.noise_std > 0.0
    switching = fa.switching
    for c in range(W):
        FL[c] = 0.0
        PH[c] = (KP[c] * substeps) % M  # once per period: no integer division per lane and Euler step
    for i in range(N):
        for k in range(n):
            _tile_dot(BU[i, k], None, rows.B_bar, i * n + k, U, W)
    for k in range(n):
        _tile_dot(Bu[k], None, rows.B, k, U, W)
        _tile_dot(Br[k], None, rows.B, k, R, W)
    for j in range(substeps):
        for i in range(N):
            for q in range(p):
                _tile_dot(Y[i, q], None, rows.C, i * p + q, X, W)
                if noisy:
                    for c in range(W):
                        Y[i, q, c] = Y[i, q, c] + NZ[i, q, c]
            for k in range(n):
                _tile_dot(XH[i, k], Z[i, k], rows.G_bar, i * n + k, Y[i], W)
        # broadcasts (per lane: its own Euler step count s = k S + j): s % M == 0 exactly when
        # PH + j % M (both in [0, M)) is 0 or M
        jm = j % M
        any_bc = False
        for c in range(W):
            ph = PH[c] + jm
            bc = continuous or ph == 0 or ph == M
            BC[c] = bc
            any_bc = any_bc or bc
        if any_bc:
            if lag > 0:
                for c in range(W):
                    if BC[c]:
                        b = lo + c
                        qb = (KP[c] * substeps + j) // M
                        slot = qb % ring
                        old = (qb - lag) % ring
                        t = TCNT[c]
                        TSLOT[t, c] = slot
                        TCNT[c] = t + 1
                        for i in range(N):
                            for k in range(n):
                                TSN[t, i, k, c] = XH[i, k, c]
                        for e in range(E):
                            if DL[e, c]:
                                js = sender[e]
                                for k in range(n):
                                    REC[e, k, c] = snapshots_a[b, old, js, k]
            else:
                for e in range(E):
                    js = sender[e]
                    for c in range(W):
                        MK[c] = BC[c] & DL[e, c]  # no short-circuit: a vector select below
                    for k in range(n):
                        for c in range(W):
                            REC[e, k, c] = XH[js, k, c] if MK[c] else REC[e, k, c]
        # d_i = sum_e a_e (xhat_i - r_e) over the links into i (weight 0: skipped, as period_copy_faulted)
        if switching:  # the lanes' graphs differ: a select per lane
            for i in range(N):
                for k in range(n):
                    for c in range(W):
                        D[i, k, c] = 0.0
            for e in range(E):
                ir = receiver[e]
                for k in range(n):
                    for c in range(W):
                        a = WL[e, c]
                        D[ir, k, c] = D[ir, k, c] + a * (XH[ir, k, c] - REC[e, k, c]) if a != 0.0 else D[ir, k, c]
        else:  # one graph: the link's weight is every lane's; node i's links LK[LP[i]:LP[i+1]] (increasing e),
            # up to two per pass over the lanes: ((0 + a_0 t_0) + a_1 t_1) + ..., the sums of period_copy_faulted
            weight = fa.weight
            for i in range(N):
                l0, l1 = LP[i], LP[i + 1]
                for k in range(n):
                    if l0 == l1:
                        for c in range(W):
                            D[i, k, c] = 0.0
                    j = l0
                    while j < l1:
                        e0 = LK[j]
                        a0 = weight[0, e0]
                        if j + 1 < l1:
                            e1 = LK[j + 1]
                            a1 = weight[0, e1]
                            if j == l0:
                                for c in range(W):
                                    xh = XH[i, k, c]
                                    D[i, k, c] = 0.0 + a0 * (xh - REC[e0, k, c]) + a1 * (xh - REC[e1, k, c])
                            else:
                                for c in range(W):
                                    xh = XH[i, k, c]
                                    D[i, k, c] = D[i, k, c] + a0 * (xh - REC[e0, k, c]) + a1 * (xh - REC[e1, k, c])
                            j += 2
                        else:
                            if j == l0:
                                for c in range(W):
                                    D[i, k, c] = 0.0 + a0 * (XH[i, k, c] - REC[e0, k, c])
                            else:
                                for c in range(W):
                                    D[i, k, c] = D[i, k, c] + a0 * (XH[i, k, c] - REC[e0, k, c])
                            j += 1
        for i in range(N):
            for c_ in range(rq):
                _tile_dot(CQ[c_], None, rows.Q_projT, i * rq + c_, D[i], W)
            for c in range(W):
                nw2[c] = 0.0
            rng_ = proj_range[i]
            for k in range(n):
                _tile_dot(Wv[k], None, rows.Q_proj, i * n + k, CQ, W)
                if rng_:
                    for c in range(W):
                        nw2[c] = nw2[c] + Wv[k, c] * Wv[k, c]
                else:
                    for c in range(W):
                        w = D[i, k, c] - Wv[k, c]
                        Wv[k, c] = w
                        nw2[c] = nw2[c] + w * w
            for c in range(W):
                nw[c] = np.sqrt(nw2[c])
                coef[c] = G[i, c] + (GS[i, c] / nw[c] if nw[c] > 0.0 else 0.0)
            phi_i = phi[i]
            for c in range(W):
                if _crit(DEG[i, c], dt, G[i, c], phi_i, nw2[c]) > TILE_RECHECK:
                    FL[c] = 1.0
            for k in range(n):
                for c in range(W):
                    ZN[k, c] = BU[i, k, c] - coef[c] * Wv[k, c]
                _tile_dot(ZN[k], ZN[k], rows.E_bar, i * n + k, Z[i], W)
                _tile_dot(ZN[k], ZN[k], rows.F_bar, i * n + k, Y[i], W)
                for c in range(W):
                    ZN[k, c] = Z[i, k, c] + dt * ZN[k, c]
            for k in range(n):
                for c in range(W):
                    Z[i, k, c] = ZN[k, c]
            sg, ph, sgs, phs = sigma[i], phi[i], sigma_s[i], phi_s[i]
            for c in range(W):
                g = G[i, c]
                gs = GS[i, c]
                G[i, c] = g + dt * (-sg * g + ph * nw2[c])
                GS[i, c] = gs + dt * (-sgs * gs + phs * nw[c])
        for k in range(n):
            _tile_dot(XD[k], Bu[k], rows.A, k, X, W)
            if mv:
                _tile_dot(XD[k], XD[k], rows.B_v, k, V, W)
        if has_reference:
            for k in range(n):
                _tile_dot(XRD[k], Br[k], rows.A_r, k, XR, W)
            for k in range(n):
                for c in range(W):
                    XR[k, c] = XR[k, c] + dt * XRD[k, c]
        for k in range(n):
            for c in range(W):
                X[k, c] = X[k, c] + dt * XD[k, c]
        for jv in range(mv):
            _tile_dot(VN[jv], None, rows.Phi_v, jv, V, W)
        for jv in range(mv):
            for c in range(W):
                V[jv, c] = VN[jv, c]


@_njit
def _tile_faulted_const(X, Z, G, GS, V, XR, U, R, ka, work, W, fa, ft, fs, lo):
    """:func:`_tile_faulted` compiled for the constant width ``W`` (:data:`~dobs_envs.sim.period_kernel.TILE`:
    constant trip counts, as :func:`~dobs_envs.sim.period_kernel.period_tile`)."""
    numba.literally(W)
    _tile_faulted(X, Z, G, GS, V, XR, U, R, ka, work, W, fa, ft, fs, lo)


@_njit
def _tile_faulted_any(X, Z, G, GS, V, XR, U, R, ka, work, W, fa, ft, fs, lo):
    """:func:`_tile_faulted` with the width ``W`` known at run time (one compilation for every width)."""
    _tile_faulted(X, Z, G, GS, V, XR, U, R, ka, work, W, fa, ft, fs, lo)


@_njit
def _scatter_faulted(state, ft, lo, nl, x, z, gamma, gamma_s, v, x_r, FL, u, r, ka, fa, fs, delivered, sc, fsc):
    """Copies ``lo .. lo+nl-1`` and their received copies back from the tile, except lanes flagged by the
    stability test: those are advanced again from their unchanged batch rows by :func:`period_copy_faulted`."""
    X, Z, G, GS, V, XR, U, R = state
    REC, NZ, DEG, WL, DL, KP, PH, BC, TSN, TSLOT, TCNT, MK, LK, LP = ft
    received_a, snapshots_a = fs[2], fs[3]
    N, n = Z.shape[0], Z.shape[1]
    E = REC.shape[0]
    for c in range(nl):
        b = lo + c
        if FL[c] != 0.0:
            period_copy_faulted(b, x, z, gamma, gamma_s, v, x_r, u, r, ka, fa, fs, delivered, sc, fsc)
            continue
        for k in range(n):
            x[b, k] = X[k, c]
            x_r[b, k] = XR[k, c]
        for i in range(N):
            gamma[b, i] = G[i, c]
            gamma_s[b, i] = GS[i, c]
            for k in range(n):
                z[b, i, k] = Z[i, k, c]
        for j in range(V.shape[0]):
            v[b, j] = V[j, c]
        for e in range(E):
            delivered[b, e] = DL[e, c]
            for k in range(n):
                received_a[b, e, k] = REC[e, k, c]
        for t in range(TCNT[c]):
            sl = TSLOT[t, c]
            for i in range(N):
                for k in range(n):
                    snapshots_a[b, sl, i, k] = TSN[t, i, k, c]


@_njit
def advance_rows_faulted(x, z, gamma, gamma_s, v, x_r, u, r, ka, fa, fs, delivered, lo, hi):
    """One faulted control period of copies ``lo .. hi-1`` in place, then each copy's next-period draws
    (module doc): tiles of :data:`~dobs_envs.sim.period_kernel.TILE` copies and a remainder of at least
    :data:`~dobs_envs.sim.period_kernel.MIN_TILE` as one tile (constant width :func:`_tile_faulted_const`, run-time
    width :func:`_tile_faulted_any`),
    a smaller remainder copy by copy (:func:`period_copy_faulted`); the same per-copy arithmetic either way.
    Threads may run disjoint ranges concurrently (no GIL)."""
    N, n, p = z.shape[1], z.shape[2], ka.C.shape[1]
    sc = _scratch_copy(ka)
    fsc = _scratch_fault(fa, N)
    b = lo
    if hi - b >= TILE:
        st, wk = _scratch_tile(ka, TILE)
        ft = _scratch_fault_tile(fa, N, n, p, TILE)
    while hi - b >= MIN_TILE:
        nl = TILE if hi - b >= TILE else hi - b
        if nl < TILE:  # the remainder: a tile of exactly its width
            st, wk = _scratch_tile(ka, nl)
            ft = _scratch_fault_tile(fa, N, n, p, nl)
        _gather(st, b, nl, x, z, gamma, gamma_s, v, x_r, u, r)
        _gather_fault(ft, b, nl, fa, fs, N, p)
        if nl == TILE:
            _tile_faulted_const(st[0], st[1], st[2], st[3], st[4], st[5], st[6], st[7], ka, wk, TILE, fa, ft, fs, b)
        else:
            _tile_faulted_any(st[0], st[1], st[2], st[3], st[4], st[5], st[6], st[7], ka, wk, nl, fa, ft, fs, b)
        _scatter_faulted(st, ft, b, nl, x, z, gamma, gamma_s, v, x_r, wk[15], u, r, ka, fa, fs, delivered, sc, fsc)
        b += nl
    for c in range(b, hi):
        period_copy_faulted(c, x, z, gamma, gamma_s, v, x_r, u, r, ka, fa, fs, delivered, sc, fsc)
    _draws_rows(lo, hi, fa, fs)


@_njit
def co_link_rows(lo, hi, X, xoff, o, co_nodes, fa, fs, received):
    """The C-O links of copies ``lo .. hi-1``, each at the boundary of its period ``fs.period[b]`` (as
    :func:`~dobs_envs.sim.fault_state.co_link_numpy`): link ``l`` of copy ``b`` sends node
    ``co_nodes[l]``'s estimate, ``X[b - xoff, o + co_nodes[l] n : ... + n]`` (``X`` 2-D, the estimates
    flat from column ``o``, node ``i`` at ``o + i n``), into the ring ``co_sent``; unless lost
    (probability ``co_loss``; ``received[b, l]`` = not lost), ``co_held[b, l]`` becomes what was sent
    ``co_delay`` boundaries before. One call for the range (the arrays are taken out of the tuples once)."""
    seed_a, period_a, received_a, snapshots_a, bad_a, graph_a, noise_a, co_sent, co_held = _fields(fs)
    co_delay, co_loss = fa.co_delay, fa.co_loss
    Lc = co_delay + 1
    n = co_held.shape[2]
    for b in range(lo, hi):
        k = period_a[b]
        slot = k % Lc
        src = (k - co_delay) % Lc
        xr = b - xoff
        key = frng.period_key(seed_a[b], _CO_LOSS, np.uint64(k))
        for l in range(co_nodes.shape[0]):
            i = o + co_nodes[l] * n
            for c in range(n):
                co_sent[b, slot, l, c] = X[xr, i + c]
            lost = False
            if co_loss > 0.0:
                lost = frng.uniform_at(key, np.uint64(l)) < co_loss
            received[b, l] = not lost
            if not lost:
                for c in range(n):
                    co_held[b, l, c] = co_sent[b, src, l, c]


@_njit
def co_link_row(b, xhat, co_nodes, fa, fs, received):
    """The C-O links of copy ``b`` at the boundary of its period (:func:`co_link_rows`; ``xhat`` flat
    ``(N n,)``, node ``i`` at ``i n``)."""
    co_link_rows(b, b + 1, xhat.reshape((1, xhat.shape[0])), b, 0, co_nodes, fa, fs, received)


@_njit
def _control_period_faulted(x, z, gamma, gamma_s, v, x_r, u, r, KF, KI, FF, FI, fs, delivered):
    advance_rows_faulted(x, z, gamma, gamma_s, v, x_r, u, r, unpack_kernel_args(KF, KI), unpack_fault_args(FF, FI),
                         fs, delivered, 0, x.shape[0])


def _copy_state(fs: FaultState) -> tuple:
    return tuple(np.array(a, copy=True, order="C") for a in fs)


def control_period_faulted_compiled(x, z, gamma, gamma_s, v, x_r, u, r, p, fa, fs, *, delivered=None):
    """Compiled counterpart of :func:`~dobs_envs.sim.numpy_step.control_period_faulted_numpy` (same
    arguments and returns: new arrays, the new :class:`FaultState`; inputs untouched).

    ``fa`` a :class:`FaultArgs` (packed here on every call: tests and scripts; the environments pack
    it once) or its packed ``(FF, FI)``; ``delivered (B, E)`` bool, optional, receives the period's
    deliveries.
    """
    FF, FI = pack(fa) if isinstance(fa, FaultArgs) else fa
    out = [np.array(a, dtype=np.float64, copy=True, order="C") for a in (x, z, gamma, gamma_s, v, x_r)]
    st = _copy_state(fs)
    if delivered is None:
        delivered = np.zeros((out[0].shape[0], st[2].shape[1]), dtype=np.bool_)
    _control_period_faulted(*out, np.ascontiguousarray(u, dtype=np.float64), np.ascontiguousarray(r, dtype=np.float64),
                            *p.kernel_packed, FF, FI, st, delivered)
    return (*out, FaultState(*st))


@_njit
def _co_link(sent, co_nodes, FF, FI, fs, received):
    co_link_rows(0, sent.shape[0], sent, 0, 0, co_nodes, unpack_fault_args(FF, FI), fs, received)


def co_link_compiled(xhat, co_nodes, fs: FaultState, fa, received=None):
    """Compiled C-O link of every copy (tests): ``xhat (B, N, n)`` the nodes' estimates at the boundary,
    ``co_nodes (K,)``; returns ``(held (B, K, n), new FaultState, received (B, K) bool)``."""
    FF, FI = pack(fa) if isinstance(fa, FaultArgs) else fa
    st = _copy_state(fs)
    B = st[0].shape[0]
    received = np.zeros((B, np.asarray(co_nodes).shape[0]), dtype=np.bool_) if received is None else received
    sent = np.ascontiguousarray(np.asarray(xhat, dtype=np.float64).reshape(B, -1))
    _co_link(sent, np.ascontiguousarray(co_nodes, dtype=np.int64), FF, FI, st, received)
    return st[8].copy(), FaultState(*st), received
