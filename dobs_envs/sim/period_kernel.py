"""numba-compiled control period: the hot path of every environment, with or without communication faults.

Same operations as :func:`.numpy_step.control_period_numpy` (see its docstring for
the equations) and, given a :class:`~dobs_envs.sim.fault_kernel.FaultPeriod` instead of
:data:`~dobs_envs.sim.fault_state.NO_FAULT`,
:func:`.numpy_step.control_period_faulted_numpy`; tested against both.

One engine
----------
Every compiled function of a period takes the fault arguments or
:data:`~dobs_envs.sim.fault_state.NO_FAULT`, an empty tuple (``fault``; its work arrays ``fsc`` / ``ft``
are then None). numba compiles one specialisation per argument type, turns ``len(fault)`` into a constant
and prunes the ``if len(fault) == 0:`` branches before typing, so ``faults=None`` compiles to the ideal
network's code only and runs no fault code, and a faulted specialisation contains no ideal-network code
(``if fault is None:`` would be pruned for a None argument only: a faulted network compiled both). The two specialisations differ where the numpy reference's exchange objects
(``_IdealExchange`` / ``_FaultedExchange``) do: the degrees of the stable-step test (the active graph's),
the held measurement noise added to ``y_i`` (eq. (localmeasure)), and the consensus term ``d_i`` of eq.
(H_idefine): ``(L xhat)_i`` over the neighbour lists, or ``sum_{e: receiver e = i} a_e^g (xhat_i - r_e)``
over the copies ``r_e`` node ``i`` holds, refreshed by the broadcasts (in :func:`period_copy` and
:func:`period_tile`: at the Euler steps ``s`` counted from the copy's reset that are multiples of
``exchange_steps``, every delivering link takes the sender's estimate, or with ``oo_delay > 0`` the
snapshot of ``lag`` broadcasts before from the copy's ring; the continuous exchange without delay
refreshes them at every shortened step of a split Euler step too). The draws, the deliveries and the
C-O link are in :mod:`.fault_kernel`; after a faulted period :func:`advance_rows` makes each copy's
next-period draws (:func:`~dobs_envs.sim.fault_kernel.draws_rows`).

Sparse rows
-----------
The paper's design matrices are sparse (NE2: 55 of the 486 entries of ``Ebar`` are
nonzero, 8 of the 81 of ``A``): every matrix-vector product runs over the stored entries
of row-compressed matrices (:attr:`KernelArgs.rows <dobs_envs.sim.state.KernelArgs>`,
:func:`~dobs_envs.sim.state.compress_rows`), each sum in column order. Skipping exact zeros
leaves every finite result unchanged (``fma(0, x, s) = s``) and halves NE2's flops
(:func:`flops_per_period`).

Two layouts of the same arithmetic
----------------------------------
- :func:`period_copy` advances one copy ``b`` of a batch-first state
  (``x (B, n)``, ``z (B, N, n)``, ...): scalar code, one loop over the stored entries of
  each matrix (no data-dependent inner loops).
- :func:`period_tile` advances a *tile* of ``W`` copies stored with the copy axis
  **innermost** (``X (n, W)``, ``Z (N, n, W)``, ...): every statement is a loop over
  the ``W`` copies, which the compiler turns into SIMD instructions across copies.
  Compiled twice: with ``W`` a compile-time constant (:data:`TILE`: constant trip counts)
  and with ``W`` known at run time (any remainder of fewer than :data:`TILE` copies, unpadded;
  LLVM unrolls narrow *constant* widths completely, which takes minutes to compile).

:func:`advance_rows` cuts a range of copies into tiles of :data:`TILE` copies
(gathered from / scattered back to the batch-first arrays), then runs a remainder of at
least :data:`MIN_TILE` copies as one run-time-width tile, and a smaller one copy by copy. Every copy's arithmetic is identical in both layouts --
each sum is accumulated in the same order, term by term, and :data:`FASTMATH` allows only
FMA contraction -- so a copy's trajectory does not depend on the batch size or on its
position in the batch (tested bit for bit).

Stable steps
------------
Forward Euler on the observer nodes, eq. (zidynamic) with the consensus term of eq. (H_idefine),
and the adaptive laws of eq. (gammaiis)/(gagasbeta) is conditionally stable: the linear consensus
term ``-gamma_i P_u,i (L xhat)_i`` has, in the coordinates ``eps_u`` of the Appendix (eq.
(dotepsu)), the matrix ``M Gamma`` with ``M = T_u^T (L x I_n) T_u`` and ``Gamma = diag(gamma_i I)``;
its eigenvalues ``mu`` are real, nonnegative and at most ``rho(Gamma L) <= max_i 2 deg_i gamma_i``
(``Gamma^1/2 M Gamma^1/2 = T_u^T (Gamma^1/2 L Gamma^1/2 x I) T_u``, Gershgorin on the rows of
``Gamma L``). An Euler step of length ``h`` multiplies these modes by ``1 - h mu``. The gain law
``gamma_i += h phi_i ||eps_iu||^2`` grows the gain quadratically in the error, so a large error
(a large plant state: ``||eps_iu||`` is of the order of ``deg_i ||x||``) makes ``h mu`` exceed 2,
the modes oscillate with growing amplitude, ``||eps_iu||^2`` and with it ``gamma_i`` grow faster,
and the state overflows within a few steps (issue 19). Each Euler step therefore first evaluates,
from the state it starts at (:func:`_crit`),

    ``max_i 2 deg_i dt (gamma_i + dt phi_i ||eps_iu||^2) <= 1``,

i.e. the step is monotone in the consensus modes (``0 <= 1 - h mu <= 1``: no sign flip, so the
consensus term alone never increases the error the gain law integrates) both for the gain it uses
and for the gain it produces (the next step uses that one; the plant and ``Ebar`` parts are those
of the paper's runs, stable at the default ``dt``). Then it is the plain Euler step of length ``dt`` (every run of
the paper passes this test, so its results are bitwise those of the plain scheme). Otherwise
the interval ``dt`` is integrated by Euler steps of length ``h = min(tau, min_i h_i)``
(:func:`_stable_step`: the largest ``h_i`` that passes the same test at node ``i``, ``tau``
the time left), recomputed from the state after every step, the exosystem input ``v`` held over
the interval as the plain step holds it, and ``v <- expm(S dt) v`` once at its end. No step is
shorter than ``dt / MAX_SPLIT``. The discontinuous term ``gamma_is h(eps_iu)`` is left out of the
test: it moves ``eps_iu`` by at most ``h 2 deg_i gamma_is`` per step (the O(dt) chattering band of
:mod:`.numpy_step`), a bounded perturbation that cannot make the step unstable, and its
coefficient ``gamma_is / ||eps_iu||`` is unbounded near consensus where the paper's runs live.

Per copy: :func:`period_copy` runs the test; a tile flags every lane whose test exceeds
:data:`TILE_RECHECK` at some step and :func:`advance_rows` recomputes those copies from the
period's start with :func:`period_copy`, so a copy's result still depends on nothing but its own
state (the unflagged lanes pass the copy's test with a margin: the same plain steps).

Named state. The batch-first arrays of a period (state and held inputs) travel as one
:class:`PeriodArrays`, the work arrays as :class:`CopyScratch` / :class:`TileState` /
:class:`TileWork` (and the fault ones of :mod:`.fault_kernel`), all read by name.

The constants arrive as one :class:`~dobs_envs.sim.kernel_args.KernelArgs` named tuple ``ka``
(declared once in :mod:`.kernel_args`; built once per parameter set), read by name (``ka.dt``,
``ka.rows.E_bar``); from Python they are passed packed into two buffers
(``SimParams.kernel_packed``), which :func:`unpack_kernel_args` (generated from the declaration)
unpacks in compiled code.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..numba_cache import ensure_fresh
from ..packing import compiled_unpack, pack
from . import fault_kernel as fk
from .fault_state import NO_FAULT, FaultArgs, FaultState
from .jit import FASTMATH, HAVE_NUMBA
from .jit import njit as _njit
from .jit import njit_inline as _njit_inline
from .kernel_args import KernelArgs

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

#: Copies per SIMD tile of :func:`advance_rows`, a compile-time constant (NE2, one core: 5.0 us per
#: copy and control step at 128, 5.4 at 64; the same code with a run-time width: 5.8 at 128).
TILE = 128
#: Fewest remaining copies (fewer than TILE) run as one tile of exactly that many copies (run-time
#: width, no padding); fewer run one by one. The cost crossover on NE2 (one core, us per control
#: period): 4 copies 166 copy by copy / 183 as a tile, 8 copies 240 / 115, 16 copies 480 / 161
#: (the padded 64-copy tile used before: 369).
MIN_TILE = 6
#: Most steps one Euler step is split into when its stability test fails (module doc, "Stable steps"):
#: no step is shorter than ``dt / MAX_SPLIT``, which bounds the work per control period.
MAX_SPLIT = 4096
#: A tile lane whose stability test exceeds this (half the limit 1 of :func:`period_copy`, a margin
#: against any rounding difference between the layouts) is recomputed by :func:`period_copy`.
TILE_RECHECK = 0.5

__all__ = ["HAVE_NUMBA", "FASTMATH", "TILE", "MIN_TILE", "MAX_SPLIT", "PeriodArrays", "CopyScratch", "TileState",
           "TileWork", "period_copy", "period_tile", "advance_rows", "period_arrays", "unpack_kernel_args",
           "control_period_compiled", "control_period_faulted_compiled", "flops_per_period"]


class PeriodArrays(NamedTuple):
    """The batch-first arrays of one control period: the state (updated in place) and the held inputs."""

    x: np.ndarray  # (B, n) plant
    z: np.ndarray  # (B, N, n) observer nodes
    gamma: np.ndarray  # (B, N) adaptive gains
    gamma_s: np.ndarray  # (B, N)
    v: np.ndarray  # (B, m_v) exosystem
    x_r: np.ndarray  # (B, n) reference model
    u: np.ndarray  # (B, m) held input (read)
    r: np.ndarray  # (B, m) held reference command (read)


class CopyScratch(NamedTuple):
    """Work arrays of :func:`period_copy` (:func:`_scratch_copy`); node ``i``'s block at ``i * n`` (``i * p``)."""

    y: np.ndarray  # (N p,) outputs
    xhat: np.ndarray  # (N n,) estimates
    d: np.ndarray  # (N n,) consensus disagreement
    cq: np.ndarray  # (N rq,) projection coordinates
    w: np.ndarray  # (N n,) P_u,i d_i
    bu: np.ndarray  # (N n,) Bbar_i u (held)
    Bu: np.ndarray  # (n,) B u (held)
    Br: np.ndarray  # (n,) B r (held)
    zn: np.ndarray  # (N n,) observer right-hand side
    xdot: np.ndarray  # (n,)
    xrdot: np.ndarray  # (n,)
    vnew: np.ndarray  # (m_v,)
    nw: np.ndarray  # (N,) ||eps_iu||
    nw2: np.ndarray  # (N,) ||eps_iu||^2
    coef: np.ndarray  # (N,) gamma_i + gamma_s,i / ||eps_iu||


class TileState(NamedTuple):
    """A tile's state and held inputs, copy axis last (:func:`_scratch_tile`, :func:`_gather`)."""

    X: np.ndarray  # (n, W)
    Z: np.ndarray  # (N, n, W)
    G: np.ndarray  # (N, W)
    GS: np.ndarray  # (N, W)
    V: np.ndarray  # (m_v, W)
    XR: np.ndarray  # (n, W)
    U: np.ndarray  # (m, W)
    R: np.ndarray  # (m, W)


class TileWork(NamedTuple):
    """Work arrays of :func:`period_tile`, copy axis last."""

    Y: np.ndarray  # (N, p, W)
    XH: np.ndarray  # (N, n, W)
    D: np.ndarray  # (N, n, W)
    CQ: np.ndarray  # (rq, W)
    Wv: np.ndarray  # (n, W)
    BU: np.ndarray  # (N, n, W)
    Bu: np.ndarray  # (n, W)
    Br: np.ndarray  # (n, W)
    ZN: np.ndarray  # (n, W)
    XD: np.ndarray  # (n, W)
    XRD: np.ndarray  # (n, W)
    VN: np.ndarray  # (m_v, W)
    nw2: np.ndarray  # (W,)
    coef: np.ndarray  # (W,)
    nw: np.ndarray  # (W,)
    flags: np.ndarray  # (W,) 1.0: the lane failed the stability test (recomputed by period_copy)


@_njit
def _scratch_copy(ka):
    """:class:`CopyScratch` (allocated once per batch call)."""
    N, n, p, rq, mv = ka.E_bar.shape[0], ka.E_bar.shape[1], ka.C.shape[1], ka.Q_proj.shape[2], ka.B_v.shape[1]
    return CopyScratch(np.empty(N * p), np.empty(N * n), np.empty(N * n), np.empty(N * rq), np.empty(N * n),
                       np.empty(N * n), np.empty(n), np.empty(n), np.empty(N * n), np.empty(n), np.empty(n),
                       np.empty(mv), np.empty(N), np.empty(N), np.empty(N))


@_njit_inline
def _terms(out, sp, vec):
    """``out[row[j]] += val[j] * vec[gcol[j]]`` over every stored entry ``j`` of a row-compressed
    matrix ``sp`` (:class:`~dobs_envs.sim.kernel_args.Sparse`): each output row sums its terms in
    column order (one loop over all entries, no data-dependent inner loops)."""
    val, row, gcol = sp.val, sp.row, sp.gcol
    for j in range(val.shape[0]):
        q = row[j]
        out[q] = out[q] + val[j] * vec[gcol[j]]


@_njit_inline
def _take(rec, src, sender, deliver, n):
    """``rec[e] = src[sender[e]]`` (``src`` flat, node ``j`` at ``j * n``) for every delivering link."""
    for e in range(sender.shape[0]):
        if deliver[e]:
            js = sender[e] * n
            for c in range(n):
                rec[e, c] = src[js + c]


@_njit
def period_copy(b, pa, ka, sc, fault, fsc):
    """One control period of copy ``b`` in place (batch-first :class:`PeriodArrays` ``pa``, see module doc).

    ``ka`` the :class:`~dobs_envs.sim.kernel_args.KernelArgs`; ``sc`` the :class:`CopyScratch`;
    ``fault`` :data:`~dobs_envs.sim.fault_state.NO_FAULT` (the ideal network) or a
    :class:`~dobs_envs.sim.fault_kernel.FaultPeriod` with its
    work arrays ``fsc`` (:class:`~dobs_envs.sim.fault_kernel.FaultCopyScratch`; None without faults):
    the copy's deliveries are written to ``fault.delivered[b]``, its received copies and snapshot ring
    updated, the period's draws read, not advanced (:func:`advance_rows` does). Every matrix-vector
    product runs over the stored entries of a row-compressed matrix (``ka.rows``), each output summing
    its terms in column order, as :func:`period_tile` does per copy.
    """
    rows = ka.rows
    proj_range, nbr_idx, nbr_w = ka.proj_range, ka.nbr_idx, ka.nbr_w
    phi, phi_s, sigma, sigma_s = ka.phi, ka.phi_s, ka.sigma, ka.sigma_s
    dt, substeps, has_reference = ka.dt, ka.substeps, ka.has_reference
    y, xhat, d, cq, w, bu, Bu, Br = sc.y, sc.xhat, sc.d, sc.cq, sc.w, sc.bu, sc.Bu, sc.Br
    zn, xdot, xrdot, vnew, nwv, nw2v, coef = sc.zn, sc.xdot, sc.xrdot, sc.vnew, sc.nw, sc.nw2, sc.coef
    gamma, gamma_s = pa.gamma, pa.gamma_s
    N, n = pa.z.shape[1], pa.z.shape[2]
    p, mv = ka.C.shape[1], ka.B_v.shape[1]
    rq, maxdeg = ka.Q_proj.shape[2], nbr_idx.shape[1]
    if len(fault) == 0:
        deg = ka.degree
    else:
        # the faulted O-O exchange (numpy_step._FaultedExchange): its arrays taken out of the bundles once
        # per period (per Euler step, each unpacked array would cost a reference count update)
        fk.deliveries_copy(b, fault, fsc)  # the period's deliveries (fault_state.oo_losses), the active graph
        fa, fs = fault.args, fault.state
        deg, wl, deliver = fsc.degree, fsc.weight, fsc.deliver
        noisy = fa.noise_std > 0.0
        noise_a = fs.noise
        sender, receiver = fa.sender, fa.receiver
        E = sender.shape[0]
        k0 = fs.period[b]
        rec = fs.received[b]  # (E, n) held copies r_e
        snaps = fs.snapshots[b]  # (R, N, n)
        M, lag, ring = fa.exchange_steps, fa.lag, fa.ring
        continuous = fa.continuous
        refresh = continuous and lag == 0
    xb, xrb, vb, ub, rb = pa.x[b], pa.x_r[b], pa.v[b], pa.u[b], pa.r[b]
    zb = pa.z[b].reshape(N * n)  # node i's state at i * n
    # held inputs (ZOH over the control period): Bbar_i u, B u, B r
    bu[:] = 0.0
    _terms(bu, rows.B_bar, ub)
    Bu[:] = 0.0
    _terms(Bu, rows.B, ub)
    Br[:] = 0.0
    _terms(Br, rows.B, rb)
    hmin = dt / MAX_SPLIT
    for j in range(substeps):
        # one Euler step of length dt; split into shorter steps (v held) when the stability
        # test on the adaptive gains fails (module doc, "Stable steps"; eqs. (zidynamic), (gammaiis))
        tau = dt  # time left in this Euler step
        h = dt
        split = False
        first = True
        while True:
            # eq. (localmeasure) y_i = C_i x (+ the held noise) ; eq. (hatxieq) xhat_i = z_i + Gbar_i y_i
            for q in range(N * p):
                y[q] = 0.0
            _terms(y, rows.C, xb)
            if len(fault) > 0:
                if noisy:
                    for i in range(N):
                        for q in range(p):
                            y[i * p + q] = y[i * p + q] + noise_a[b, i, q]
            for q in range(N * n):
                xhat[q] = zb[q]
            _terms(xhat, rows.G_bar, y)
            if len(fault) == 0:
                # d_i = sum_j a_ij (xhat_i - xhat_j) over the neighbour lists (sparse L xhat)
                for i in range(N):
                    for k in range(n):
                        d[i * n + k] = deg[i] * xhat[i * n + k]
                    for q in range(maxdeg):
                        a = nbr_w[i, q]
                        if a != 0.0:
                            jn = nbr_idx[i, q] * n
                            for k in range(n):
                                d[i * n + k] = d[i * n + k] - a * xhat[jn + k]
            else:
                # broadcasts (at the Euler steps s counted from the copy's reset that are multiples of M)
                if first:
                    s_ = k0 * substeps + j
                    if continuous or s_ % M == 0:
                        if lag > 0:
                            qb = s_ // M
                            slot = qb % ring
                            for i in range(N):
                                for k in range(n):
                                    snaps[slot, i, k] = xhat[i * n + k]
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
                        for k in range(n):
                            d[ir + k] = d[ir + k] + a * (xhat[ir + k] - rec[e, k])
            # w_i = P_u,i d_i through the thinner of the two bases:
            # Q spans Im T_iu (w = Q Q^T d) or Im T_id (w = d - Q Q^T d)
            for q in range(N * rq):
                cq[q] = 0.0
            _terms(cq, rows.Q_projT, d)
            for q in range(N * n):
                w[q] = 0.0
            _terms(w, rows.Q_proj, cq)
            crit = 0.0
            for i in range(N):
                nw2 = 0.0
                for k in range(n):
                    s = w[i * n + k]
                    if not proj_range[i]:
                        s = d[i * n + k] - s
                    w[i * n + k] = s
                    nw2 = nw2 + s * s
                nw = np.sqrt(nw2)
                nwv[i] = nw
                nw2v[i] = nw2
                coef[i] = gamma[b, i] + (gamma_s[b, i] / nw if nw > 0.0 else 0.0)  # eq. (H_idefine), h(0) = 0
                if first:
                    c_ = _crit(deg[i], dt, gamma[b, i], phi[i], nw2)
                    if c_ > crit:
                        crit = c_
            if first:
                split = crit > 1.0  # NaN: not split (the non-finite state propagates)
                first = False
            if split:
                # the longest step h <= tau with 2 deg_i h (gamma_i + h phi_i ||eps_iu||^2) <= 1 at every node
                hreq = tau
                for i in range(N):
                    hi = _stable_step(deg[i], gamma[b, i], phi[i], nw2v[i])
                    if hi < hreq:
                        hreq = hi
                if hreq != hreq:
                    h = tau  # NaN: no stable step exists, let it propagate
                elif hreq < hmin:
                    h = hmin  # at most MAX_SPLIT steps per Euler step
                else:
                    h = hreq
                if h >= tau:
                    h = tau
            # eq. (zidynamic) for every node
            for i in range(N):
                ci = coef[i]
                for k in range(n):
                    zn[i * n + k] = bu[i * n + k] - ci * w[i * n + k]
            _terms(zn, rows.E_bar, zb)
            _terms(zn, rows.F_bar, y)
            for q in range(N * n):
                zb[q] = zb[q] + h * zn[q]
            # eqs. (gammaiis)/(gagasbeta)
            for i in range(N):
                g = gamma[b, i]
                gs = gamma_s[b, i]
                gamma[b, i] = g + h * (-sigma[i] * g + phi[i] * nw2v[i])
                gamma_s[b, i] = gs + h * (-sigma_s[i] * gs + phi_s[i] * nwv[i])
            # eq. (LTIsys) plant and eq. (refxdy) reference model
            for k in range(n):
                xdot[k] = Bu[k]
            _terms(xdot, rows.A, xb)
            _terms(xdot, rows.B_v, vb)
            if has_reference:
                for k in range(n):
                    xrdot[k] = Br[k]
                _terms(xrdot, rows.A_r, xrb)
                for k in range(n):
                    xrb[k] = xrb[k] + h * xrdot[k]
            for k in range(n):
                xb[k] = xb[k] + h * xdot[k]
            if h >= tau:
                break
            tau = tau - h
        # exosystem v <- expm(S dt) v
        for jv in range(mv):
            vnew[jv] = 0.0
        _terms(vnew, rows.Phi_v, vb)
        for jv in range(mv):
            vb[jv] = vnew[jv]


@_njit_inline
def _crit(dg, dt, g, ph, nw2):
    """Stability test of one Euler step of length ``dt`` at node i (module doc, "Stable steps"):
    ``2 deg_i dt (gamma_i + dt phi_i ||eps_iu||^2)``, at most 1 for a stable step. The same
    expression in :func:`period_copy` and :func:`period_tile` (eqs. (zidynamic), (gammaiis))."""
    return 2.0 * dg * dt * (g + dt * ph * nw2)


@_njit_inline
def _stable_step(dg, g, ph, nw2):
    """The largest ``h`` with ``2 deg_i h (gamma_i + h phi_i ||eps_iu||^2) <= 1``: the positive root
    ``2 / (a + sqrt(a^2 + 4 b))`` of ``b h^2 + a h = 1``, ``a = 2 deg_i gamma_i``,
    ``b = 2 deg_i phi_i ||eps_iu||^2`` (inf when ``a = b = 0``); eq. (gammaiis)."""
    a = 2.0 * dg * g
    bb = 2.0 * dg * ph * nw2
    den = a + np.sqrt(a * a + 4.0 * bb)
    return 2.0 / den if den > 0.0 else np.inf


@_njit
def _scratch_tile(ka, W):
    """:class:`TileState` and :class:`TileWork` of :func:`period_tile` for ``W`` copies."""
    N, n, p, rq = ka.E_bar.shape[0], ka.E_bar.shape[1], ka.C.shape[1], ka.Q_proj.shape[2]
    mv, m = ka.B_v.shape[1], ka.B.shape[1]
    state = TileState(np.empty((n, W)), np.empty((N, n, W)), np.empty((N, W)), np.empty((N, W)), np.empty((mv, W)),
                      np.empty((n, W)), np.empty((m, W)), np.empty((m, W)))
    work = TileWork(np.empty((N, p, W)), np.empty((N, n, W)), np.empty((N, n, W)), np.empty((rq, W)),
                    np.empty((n, W)), np.empty((N, n, W)), np.empty((n, W)), np.empty((n, W)), np.empty((n, W)),
                    np.empty((n, W)), np.empty((n, W)), np.empty((mv, W)), np.empty(W), np.empty(W), np.empty(W),
                    np.empty(W))
    return state, work


@_njit
def period_tile(ts, ka, wk, W, fault, ft, lo):
    """One control period of a tile of ``W`` copies (``lo ..``), copy axis last, in place.

    ``ts`` the :class:`TileState` (``X (n, W)``, ``Z (N, n, W)``, ``G``/``GS (N, W)``, ``V (m_v, W)``,
    ``XR (n, W)``, ``U``/``R (m, W)``, arrays at least ``W`` wide), ``wk`` the :class:`TileWork`;
    ``fault`` NO_FAULT or a :class:`~dobs_envs.sim.fault_kernel.FaultPeriod` with the tile's fault arrays
    ``ft`` (:class:`~dobs_envs.sim.fault_kernel.FaultTile`). Per copy the same operations in the same
    order as :func:`period_copy`; the innermost loops run over the copies (SIMD), each pass over the
    copies adding up to four terms. Compiled per kind of ``W``: called with ``W`` a literal (:data:`TILE`
    from :func:`_advance_tiles`: a specialisation per width, loops of constant trip count; widths of 32 or
    more: LLVM unrolls narrower constant tiles completely, minutes of compilation) or with ``W`` a run-time
    integer (one specialisation for every width; loops vectorised with run-time trip counts; a call from
    Python is one). The same arithmetic per copy either way: results are bitwise those of
    :func:`period_copy`. The branches on ``len(fault)`` (a tuple argument: numba makes it a constant) are pruned per
    specialisation (:data:`~dobs_envs.sim.fault_state.NO_FAULT`). Not inlined (``inline="always"``): numba
    copies an inlined body block by block, each block with its own copy of the whole variable scope: for
    this body that took ~10 % of the engine's cold compile (2026-12-06, a fresh process stepping the tracking
    core, beside another job: ideal network 124 -> 107 CPU s, faulted 207 -> 191 CPU s). No wrapper either:
    every compiled caller level links, optimises and compiles to machine code the whole body again.
    """
    rows = ka.rows
    proj_range, nbr_idx, nbr_w, deg = ka.proj_range, ka.nbr_idx, ka.nbr_w, ka.degree
    phi, phi_s, sigma, sigma_s = ka.phi, ka.phi_s, ka.sigma, ka.sigma_s
    dt, substeps, has_reference = ka.dt, ka.substeps, ka.has_reference
    X, Z, G, GS, V, XR, U, R = ts.X, ts.Z, ts.G, ts.GS, ts.V, ts.XR, ts.U, ts.R
    Y, XH, D, CQ, Wv, BU, Bu, Br = wk.Y, wk.XH, wk.D, wk.CQ, wk.Wv, wk.BU, wk.Bu, wk.Br
    ZN, XD, XRD, VN, nw2, coef, nw, FL = wk.ZN, wk.XD, wk.XRD, wk.VN, wk.nw2, wk.coef, wk.nw, wk.flags
    N, n = Z.shape[0], Z.shape[1]
    p, mv = ka.C.shape[1], ka.B_v.shape[1]
    rq, maxdeg = ka.Q_proj.shape[2], nbr_idx.shape[1]
    if len(fault) == 0:
        for c in range(W):
            FL[c] = 0.0
    else:
        # the faulted O-O exchange, per lane (its deliveries, its graph's weights, broadcasts at its own Euler
        # step count); the arrays taken out of the bundles once per period
        fa = fault.args
        snapshots_a = fault.state.snapshots
        noisy = fa.noise_std > 0.0
        NZ, DEG, KP, PH = ft.noise, ft.degree, ft.period, ft.phase
        REC, WL, DL, BC = ft.received, ft.weight, ft.deliver, ft.broadcast
        TSN, TSLOT, TCNT, MK, LK, LP = ft.snap, ft.snap_slot, ft.snap_count, ft.mask, ft.links, ft.link_ptr
        sender, receiver, weight = fa.sender, fa.receiver, fa.weight
        E = sender.shape[0]
        M, lag, ring = fa.exchange_steps, fa.lag, fa.ring
        continuous, switching = fa.continuous, fa.switching
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
                if len(fault) > 0:
                    if noisy:
                        for c in range(W):
                            Y[i, q, c] = Y[i, q, c] + NZ[i, q, c]
            for k in range(n):
                _tile_dot(XH[i, k], Z[i, k], rows.G_bar, i * n + k, Y[i], W)
        if len(fault) == 0:
            for i in range(N):
                dg = deg[i]
                for k in range(n):
                    for c in range(W):
                        D[i, k, c] = dg * XH[i, k, c]
                for q in range(maxdeg):
                    a = nbr_w[i, q]
                    if a != 0.0:
                        jn = nbr_idx[i, q]
                        for k in range(n):
                            for c in range(W):
                                D[i, k, c] = D[i, k, c] - a * XH[jn, k, c]
        else:
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
            # d_i = sum_e a_e (xhat_i - r_e) over the links into i (weight 0: skipped, as period_copy)
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
                # up to two per pass over the lanes: ((0 + a_0 t_0) + a_1 t_1) + ..., the sums of period_copy
                for i in range(N):
                    l0, l1 = LP[i], LP[i + 1]
                    for k in range(n):
                        if l0 == l1:
                            for c in range(W):
                                D[i, k, c] = 0.0
                        jl = l0
                        while jl < l1:
                            e0 = LK[jl]
                            a0 = weight[0, e0]
                            if jl + 1 < l1:
                                e1 = LK[jl + 1]
                                a1 = weight[0, e1]
                                if jl == l0:
                                    for c in range(W):
                                        xh = XH[i, k, c]
                                        D[i, k, c] = 0.0 + a0 * (xh - REC[e0, k, c]) + a1 * (xh - REC[e1, k, c])
                                else:
                                    for c in range(W):
                                        xh = XH[i, k, c]
                                        D[i, k, c] = D[i, k, c] + a0 * (xh - REC[e0, k, c]) + a1 * (xh - REC[e1, k, c])
                                jl += 2
                            else:
                                if jl == l0:
                                    for c in range(W):
                                        D[i, k, c] = 0.0 + a0 * (XH[i, k, c] - REC[e0, k, c])
                                else:
                                    for c in range(W):
                                        D[i, k, c] = D[i, k, c] + a0 * (XH[i, k, c] - REC[e0, k, c])
                                jl += 1
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
            # the stability test of period_copy (with a margin): a lane whose Euler step would be
            # split is flagged and recomputed copy by copy (advance_rows)
            if len(fault) == 0:
                dgi, phi_i = deg[i], phi[i]
                for c in range(W):
                    if _crit(dgi, dt, G[i, c], phi_i, nw2[c]) > TILE_RECHECK:
                        FL[c] = 1.0
            else:
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


@_njit_inline
def _tile_dot(out, init, sp, q, X, W):
    """``out[c] = init[c] + sum_l M[q, l] X[l, c]`` (``init`` None: 0) for the ``W`` copies ``c``,
    ``M = sp`` row-compressed (:class:`~dobs_envs.sim.kernel_args.Sparse`): the stored entries of
    row ``q`` in column order, up to four per pass over the copies."""
    ptr, col, val = sp.ptr, sp.col, sp.val
    if init is None:
        for c in range(W):
            out[c] = 0.0
    else:
        for c in range(W):
            out[c] = init[c]
    j, hi = ptr[q], ptr[q + 1]
    while j + 4 <= hi:
        e0, e1, e2, e3 = val[j], val[j + 1], val[j + 2], val[j + 3]
        l0, l1, l2, l3 = col[j], col[j + 1], col[j + 2], col[j + 3]
        for c in range(W):
            out[c] = out[c] + e0 * X[l0, c] + e1 * X[l1, c] + e2 * X[l2, c] + e3 * X[l3, c]
        j += 4
    while j < hi:
        e, l = val[j], col[j]
        for c in range(W):
            out[c] = out[c] + e * X[l, c]
        j += 1


@_njit
def _gather(ts, lo, nl, pa):
    """Copies ``lo .. lo+nl-1`` of ``pa`` into the tile ``ts`` (lanes past ``nl`` repeat the last copy)."""
    X, Z, G, GS, V, XR, U, R = ts.X, ts.Z, ts.G, ts.GS, ts.V, ts.XR, ts.U, ts.R
    x, z, gamma, gamma_s, v, x_r, u, r = pa.x, pa.z, pa.gamma, pa.gamma_s, pa.v, pa.x_r, pa.u, pa.r
    W = X.shape[1]
    N, n = Z.shape[0], Z.shape[1]
    for c in range(W):
        b = lo + (c if c < nl else nl - 1)
        for k in range(n):
            X[k, c] = x[b, k]
            XR[k, c] = x_r[b, k]
        for i in range(N):
            G[i, c] = gamma[b, i]
            GS[i, c] = gamma_s[b, i]
            for k in range(n):
                Z[i, k, c] = z[b, i, k]
        for j in range(V.shape[0]):
            V[j, c] = v[b, j]
        for j in range(U.shape[0]):
            U[j, c] = u[b, j]
            R[j, c] = r[b, j]


@_njit
def _scatter(ts, wk, ft, lo, nl, pa, ka, sc, fault, fsc):
    """Copies ``lo .. lo+nl-1`` back from the tile (with their fault state), except lanes flagged in
    ``wk.flags`` (stability test of :func:`period_tile`): those are advanced again from their unchanged
    batch rows by :func:`period_copy`."""
    X, Z, G, GS, V, XR = ts.X, ts.Z, ts.G, ts.GS, ts.V, ts.XR
    x, z, gamma, gamma_s, v, x_r = pa.x, pa.z, pa.gamma, pa.gamma_s, pa.v, pa.x_r
    FL = wk.flags
    N, n = Z.shape[0], Z.shape[1]
    for c in range(nl):
        b = lo + c
        if FL[c] != 0.0:
            period_copy(b, pa, ka, sc, fault, fsc)
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
        if len(fault) > 0:
            fk.scatter_lane(ft, c, b, fault)


@_njit
def advance_rows(pa, ka, lo, hi, fault):
    """One control period of copies ``lo .. hi-1`` of ``pa`` (:class:`PeriodArrays`) in place: tiles of
    :data:`TILE` copies, then a remainder of at least :data:`MIN_TILE` copies as one tile of exactly that
    width (:func:`period_tile` with a run-time width), both in :func:`_advance_tiles`; a smaller remainder copy by copy; the
    same per-copy arithmetic either way. ``fault`` None, or a :class:`~dobs_envs.sim.fault_kernel.FaultPeriod`:
    the faulted period, then each copy's next-period draws (:func:`~dobs_envs.sim.fault_kernel.draws_rows`).
    Threads may run disjoint ranges concurrently (no GIL)."""
    sc = _scratch_copy(ka)
    if len(fault) == 0:
        fsc = None
    else:
        fsc = fk.scratch_copy(fault.args, pa.z.shape[1])
    b = lo
    if hi - b >= MIN_TILE:
        b = _advance_tiles(pa, ka, lo, hi, fault, sc, fsc)
    for c in range(b, hi):
        period_copy(c, pa, ka, sc, fault, fsc)
    if len(fault) > 0:
        fk.draws_rows(lo, hi, fault.args, fault.state)


@_njit
def _advance_tiles(pa, ka, lo, hi, fault, sc, fsc):
    """The tiles of :func:`advance_rows` (copies ``lo ..``: whole tiles of :data:`TILE`, then a remainder of
    at least :data:`MIN_TILE` copies as one tile); returns the first copy left for copy-by-copy steps. Its own
    function: the tile work (:class:`TileState`, :class:`TileWork` and the fault tile) kept out of
    :func:`advance_rows`'s frame made a step of one copy ~1.5 us faster (NE2, B = 1, one substep, the
    period through :func:`advance_rows`: 7.7-7.9 -> 6.1-6.4 us). Only :func:`period_tile` gets the width
    :data:`TILE` as a constant (a literal: constant trip counts); the helpers get it as a run-time integer
    (``wt``), like the remainder's, so each of them is compiled once for both."""
    N, n, p = pa.z.shape[1], pa.z.shape[2], ka.C.shape[1]
    b = lo
    if hi - b >= TILE:
        wt = np.int64(TILE)
        ts, wk = _scratch_tile(ka, wt)
        if len(fault) == 0:
            ft = None
        else:
            ft = fk.scratch_tile(fault.args, N, n, p, wt)
        while hi - b >= TILE:
            _gather(ts, b, wt, pa)
            if len(fault) > 0:
                fk.gather_tile(ft, b, wt, fault)
            period_tile(ts, ka, wk, TILE, fault, ft, b)
            _scatter(ts, wk, ft, b, wt, pa, ka, sc, fault, fsc)
            b += TILE
    if hi - b >= MIN_TILE:
        nl = hi - b
        ts, wk = _scratch_tile(ka, nl)
        if len(fault) == 0:
            ft = None
        else:
            ft = fk.scratch_tile(fault.args, N, n, p, nl)
        _gather(ts, b, nl, pa)
        if len(fault) > 0:
            fk.gather_tile(ft, b, nl, fault)
        period_tile(ts, ka, wk, nl, fault, ft, b)
        _scatter(ts, wk, ft, b, nl, pa, ka, sc, fault, fsc)
        b = hi
    return b


#: ``unpack_kernel_args(KF, KI)``: the :class:`~dobs_envs.sim.kernel_args.KernelArgs` packed in
#: ``SimParams.kernel_packed`` (views of the buffers; ``proj_range`` as 0/1 integers), compiled from
#: source generated from the declaration (:func:`dobs_envs.packing.compiled_unpack`).
unpack_kernel_args = compiled_unpack(KernelArgs, _njit, "unpack_kernel_args")


@_njit_inline
def period_arrays(x, z, gamma, gamma_s, v, x_r, u, r):
    """The :class:`PeriodArrays` of C-contiguous ``u``, ``r (B, m)`` as the environments' step passes them:
    column slices (layout "A"; the step's are columns of its work rows). One type of :class:`PeriodArrays`,
    so :func:`advance_rows` and everything below it is compiled once for the environments and the
    simulation (a C-layout ``u`` was a second compilation of the whole period kernel: ~75 CPU s on the
    ideal network, ~130 s faulted)."""
    m = u.shape[1]
    return PeriodArrays(x, z, gamma, gamma_s, v, x_r, u[:, 0:m], r[:, 0:m])


@_njit
def fault_period(FF, FI, fs, delivered):
    """The :class:`~dobs_envs.sim.fault_kernel.FaultPeriod` of the packed
    :class:`~dobs_envs.sim.fault_state.FaultArgs` ``(FF, FI)``, the fault-state tuple ``fs`` (plain, in
    :class:`~dobs_envs.sim.fault_state.FaultState` order) and the deliveries ``delivered (B, E)``."""
    return fk.FaultPeriod(fk.unpack_fault_args(FF, FI), FaultState(*fs), delivered)


@_njit
def _control_period(x, z, gamma, gamma_s, v, x_r, u, r, kp, fault):
    """:func:`advance_rows` on copies of the state (made here: ~4 us cheaper per call than numpy
    ``.copy()`` x 6); ``kp = (KF, KI)``; ``fault`` None or ``(FF, FI, fs, delivered)``."""
    x = x.copy()
    z = z.copy()
    gamma = gamma.copy()
    gamma_s = gamma_s.copy()
    v = v.copy()
    x_r = x_r.copy()
    KF, KI = kp
    pa = period_arrays(x, z, gamma, gamma_s, v, x_r, u, r)
    lo = np.int64(0)
    if len(fault) == 0:
        advance_rows(pa, unpack_kernel_args(KF, KI), lo, x.shape[0], fault)
    else:
        FF, FI, fs, delivered = fault
        advance_rows(pa, unpack_kernel_args(KF, KI), lo, x.shape[0], fault_period(FF, FI, fs, delivered))
    return x, z, gamma, gamma_s, v, x_r


def control_period_compiled(x, z, gamma, gamma_s, v, x_r, u, r, p):
    """Compiled counterpart of :func:`control_period_numpy` (same signature).

    State inputs must be C-contiguous float64 arrays (those of :class:`SimState`
    are); they are copied, never modified.
    """
    if u.dtype != np.float64 or not u.flags.c_contiguous:
        u = np.ascontiguousarray(u, dtype=np.float64)
    if r.dtype != np.float64 or not r.flags.c_contiguous:
        r = np.ascontiguousarray(r, dtype=np.float64)
    return _control_period(x, z, gamma, gamma_s, v, x_r, u, r, p.kernel_packed, NO_FAULT)


def control_period_faulted_compiled(x, z, gamma, gamma_s, v, x_r, u, r, p, fa, fs, *, delivered=None):
    """Compiled counterpart of :func:`~dobs_envs.sim.numpy_step.control_period_faulted_numpy` (same
    arguments and returns: new arrays, the new :class:`~dobs_envs.sim.fault_state.FaultState`; inputs
    untouched).

    ``fa`` a :class:`~dobs_envs.sim.fault_state.FaultArgs` (packed here on every call: tests and
    scripts; the environments pack it once) or its packed ``(FF, FI)``; ``delivered (B, E)`` bool,
    optional, receives the period's deliveries.
    """
    FF, FI = pack(fa) if isinstance(fa, FaultArgs) else fa
    state = [np.ascontiguousarray(a, dtype=np.float64) for a in (x, z, gamma, gamma_s, v, x_r)]
    st = tuple(np.array(a, copy=True, order="C") for a in fs)
    if delivered is None:
        delivered = np.zeros((state[0].shape[0], FaultState(*st).received.shape[1]), dtype=np.bool_)
    out = _control_period(*state, np.ascontiguousarray(u, dtype=np.float64), np.ascontiguousarray(r, dtype=np.float64),
                          p.kernel_packed, (FF, FI, st, delivered))
    return (*out, FaultState(*st))


def flops_per_period(p, *, dense: bool = False) -> int:
    """Floating-point operations of one control period of one copy (an FMA counts 2).

    Counted from the loops of :func:`period_copy` with the parameters ``p``
    (:class:`~dobs_envs.sim.state.SimParams`): the stored entries of the row-compressed
    matrices (``dense=True``: every entry, as a dense kernel would), the sparse neighbour
    lists; square roots and divisions count 1.
    """
    N, n, m, mv = p.n_nodes, p.n_states, p.n_inputs, p.n_unknown
    P, rq = p.C.shape[1], p.Q_proj.shape[2]
    if dense:
        nnz = dict(B_bar=N * n * m, B=n * m, C=N * P * n, G_bar=N * n * P, Q_projT=N * rq * n, Q_proj=N * n * rq,
                   E_bar=N * n * n, F_bar=N * n * P, A=n * n, B_v=n * mv, A_r=n * n, Phi_v=mv * mv)
    else:
        nnz = {name: int(sp.ptr[-1]) for name, sp in p.kernel_args.rows._asdict().items()}
    BB, BU, CC, GG, QT, QQ, EE, FF = (nnz[k] for k in ("B_bar", "B", "C", "G_bar", "Q_projT", "Q_proj", "E_bar", "F_bar"))
    AA, BV, AR, PV = nnz["A"], nnz["B_v"], nnz["A_r"], nnz["Phi_v"]
    nbr = int(np.count_nonzero(p.nbr_w))
    held = 2 * (BB + 2 * BU)
    sub = (2 * CC + 2 * GG  # y, xhat
           + N * n + 2 * nbr * n  # d
           + 2 * QT + 2 * QQ + N * n * (0 if np.all(p.proj_range) else 1) + 2 * N * n  # w, ||w||^2
           + 3 * N  # sqrt, division, gain
           + 2 * N * n + 2 * EE + 2 * FF + 2 * N * n  # z update: bu - coef w, Ebar z, Fbar y, Euler step
           + 8 * N  # adaptive gains
           + 5 * N  # stability test (_crit) and its comparison
           + 2 * AA + 2 * BV + 2 * n  # plant
           + (2 * AR + 2 * n if p.has_reference else 0)  # reference model
           + 2 * PV)  # exosystem
    return int(held + p.substeps * sub)
