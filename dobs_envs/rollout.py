"""Closed-loop runs of a scenario with its paper controller, batched and compiled.

:func:`rollout` runs ``B`` copies of one scenario for ``t_end`` seconds with the paper's
controller applied at every Euler step (control period = ``dt``: the continuous-time laws
up to the O(dt) of the scheme), entirely in compiled code: per step the estimates
``xhat_i = z_i + Gbar_i C_i x`` (eq. hatxieq), the control law
(:func:`dobs_envs.control.law_kernel.law_copy`) and one Euler step of plant, observers,
adaptive gains, reference model and exosystem (:func:`dobs_envs.sim.period_kernel.advance_rows`).
Copies may differ in the controller's boundary layer ``epsilon`` and adaptation gain
``phi_beta`` (eqs. hepsfunc, adlawbeta), which is what the Theorem 6 study sweeps.

:func:`rollout_reference` is the readable reference: a Python loop over
:func:`dobs_envs.sim.step_env` (numpy or numba step) and
:meth:`SeparationController.act <dobs_envs.control.laws.SeparationController.act>`;
the two are tested against each other (``tests/test_rollout.py``).

Time-varying signals (reference command ``r(t)``, NE1's prescribed inputs) are evaluated
once on the grid ``t_k = k dt`` before the loop.

Communication faults (``faults=``, :mod:`dobs_envs.sim.faults`; issue 23): the control period of
these runs is the Euler step ``dt``, so the fault model's periods are Euler steps (``oo_loss``,
``co_loss`` drawn per step and link, ``oo_delay``/``co_delay`` in Euler steps, the graph chain and
the measurement noise stepped/redrawn every step; ``oo_period`` a multiple of ``dt`` as everywhere).
Per step and copy: the nodes' estimates with the held measurement noise, the C-O links
(:func:`dobs_envs.sim.fault_kernel.co_link_row`; not at ``t = 0``, where every controller holds the
initial estimate), the law applied to the estimates the controllers hold, then one faulted Euler
step (:func:`dobs_envs.sim.period_kernel.advance_rows` with a
:class:`~dobs_envs.sim.fault_kernel.FaultPeriod`: one compiled kernel, specialised without fault code for
``faults=None``). Each copy's faults are drawn from its own seed (``fault_seed``). Reference: :func:`rollout_reference` with the same ``faults``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from .control import paper_policy
from .control.law_kernel import law_arrays, law_copy
from .numba_cache import ensure_fresh
from .packing import pack
from .sim import estimates, step_env
from .sim.fault_kernel import FaultPeriod, co_link_row, unpack_fault_args
from .sim.fault_state import NO_FAULT, FaultState, co_link_numpy, fault_args, faulted_estimates, init_fault_state
from .sim.faults import Faults
from .sim.numpy_step import control_period_faulted_numpy
from .sim.period_kernel import advance_rows, period_arrays, unpack_kernel_args

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

__all__ = ["Trajectory", "rollout", "rollout_reference", "window_stats", "fault_seeds"]


@dataclass(frozen=True)
class Trajectory:
    """Time series of one closed-loop run (one copy), sampled every ``record_every`` Euler steps.

    t (T,), x (T, n), x_r (T, n) or None, est_err (T, N) = ||xhat_i - x||,
    gamma/gamma_s (T, N), u (T, m) (input applied on [t_k, t_{k+1}); the last sample repeats
    the one before), beta (T, Nc) or None.
    """

    t: np.ndarray
    x: np.ndarray
    x_r: np.ndarray | None
    est_err: np.ndarray
    gamma: np.ndarray
    gamma_s: np.ndarray
    u: np.ndarray
    beta: np.ndarray | None

    @property
    def tracking_error(self) -> np.ndarray:
        """``||x - x_r||`` (or ``||x||`` for stabilisation), (T,)."""
        e = self.x if self.x_r is None else self.x - self.x_r
        return np.linalg.norm(e, axis=-1)


def window_stats(t: np.ndarray, y: np.ndarray, seconds: float = 5.0) -> dict:
    """``{"rms", "peak", "end"}`` of the samples ``y (T,)`` over the last ``seconds`` of ``t (T,)``."""
    y = np.asarray(y, dtype=float)[int(np.searchsorted(t, max(0.0, float(t[-1]) - seconds))):]
    return {"rms": float(np.sqrt(np.mean(y ** 2))), "peak": float(np.max(y)), "end": float(y[-1])}


def _signal(sig, t: np.ndarray, m: int) -> np.ndarray:
    """``sig(t)`` on the grid ``t (T,)`` -> (T, m) (zeros for ``None``)."""
    return np.zeros((t.size, m)) if sig is None else np.ascontiguousarray(sig(t), dtype=float).reshape(t.size, m)


def _per_copy(name, val, default, batch):
    a = np.broadcast_to(np.asarray(default if val is None else val, dtype=float), (batch,)).copy()
    if not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"{name} must be positive and finite (scalar or one per copy), got {val!r}")
    return a


def _initial_x0(sc, x0, batch):
    """``(batch, n)`` initial plant states: the scenario's ``x0``, or ``x0`` given as ``(n,)`` or ``(batch, n)``."""
    if x0 is None:
        return None
    a = np.asarray(x0, dtype=float)
    n = sc.n_states
    if a.shape not in ((n,), (batch, n)) or not np.all(np.isfinite(a)):
        raise ValueError(f"x0 must be finite with shape ({n},) or ({batch}, {n}) (one state per copy), "
                         f"got shape {a.shape}")
    return np.array(np.broadcast_to(a, (batch, n)))


def _steps(sc, dt, t_end):
    dt = float(sc.dt if dt is None else dt)
    t_end = float(sc.t_end if t_end is None else t_end)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive and finite, got {dt!r}")
    if not (np.isfinite(t_end) and t_end > 0):
        raise ValueError(f"t_end must be positive and finite, got {t_end!r}")
    return dt, t_end, max(1, int(round(t_end / dt)))


class LoopArgs(NamedTuple):
    """The constants of one compiled closed-loop run (:func:`_rollout_kernel`)."""

    oracle: bool  # apply the law to the true state
    eps: np.ndarray  # (B,) boundary layer per copy, eq. (hepsfunc)
    phi_beta: np.ndarray  # (B,) adaptation gain per copy, eq. (adlawbeta)
    decay: float  # exp(-sigma_beta dt)
    gain: float  # (1 - decay) / sigma_beta (dt when sigma_beta = 0)
    cmd: np.ndarray  # (steps, m) prescribed input on the grid (open loop)
    ref: np.ndarray  # (steps, m) reference command on the grid
    steps: int  # Euler steps
    stride: int  # record every stride-th step


class Recording(NamedTuple):
    """The samples :func:`_rollout_kernel` writes, ``(B, R, ...)`` (the fields of :class:`Trajectory`)."""

    x: np.ndarray  # (B, R, n)
    x_r: np.ndarray  # (B, R, n)
    est_err: np.ndarray  # (B, R, N)
    gamma: np.ndarray  # (B, R, N)
    gamma_s: np.ndarray  # (B, R, N)
    u: np.ndarray  # (B, R, m)
    beta: np.ndarray  # (B, R, Nc)


@numba.njit(cache=True, fastmath=False, nogil=True, error_model="numpy", inline="always")
def _record_sample(rec, b, s, xb, x_r, xhat, gamma, gamma_s, beta):
    """Sample ``s`` of copy ``b``: state, reference state, each node's estimation error ``||xhat_i - x||``
    and the adaptive gains."""
    N, n = xhat.shape
    rec.x[b, s] = xb
    rec.x_r[b, s] = x_r[b]
    for i in range(N):
        e2 = 0.0
        for c in range(n):
            d = xhat[i, c] - xb[c]
            e2 += d * d
        rec.est_err[b, s, i] = np.sqrt(e2)
    rec.gamma[b, s] = gamma[b]
    rec.gamma_s[b, s] = gamma_s[b]
    rec.beta[b, s] = beta[b]


@numba.njit(cache=True, fastmath=False, nogil=True, error_model="numpy")
def _rollout_kernel(state, beta, kp, law, loop, rec, fault):
    """Run ``loop.steps`` Euler steps of every copy in place (``state = (x, z, gamma, gamma_s, v, x_r)``,
    controller gains ``beta (B, Nc)``), the law :class:`~dobs_envs.control.law_kernel.LawArrays` ``law``
    applied at every step, recording into :class:`Recording` ``rec`` every ``loop.stride`` steps;
    ``kp = (KF, KI)`` the packed kernel arguments. ``fault`` NO_FAULT (the ideal network: a specialisation
    without fault code) or ``(FF, FI, fs, co_nodes)``, communication faults (module doc): the estimates
    carry the held measurement noise, the law reads the estimates the controllers hold after the C-O links
    (node ``co_nodes[l]``'s row replaced by link ``l``'s held estimate), the Euler steps are faulted."""
    x, z, gamma, gamma_s, v, x_r = state
    KF, KI = kp
    ka = unpack_kernel_args(KF, KI)
    C, G_bar = ka.C, ka.G_bar
    oracle, eps, phi_beta, decay, gain = loop.oracle, loop.eps, loop.phi_beta, loop.decay, loop.gain
    cmd, ref, steps, stride = loop.cmd, loop.ref, loop.steps, loop.stride
    Bsz, N, n = z.shape[0], z.shape[1], z.shape[2]
    m = law.K.shape[0]
    p = C.shape[1]
    xhat = np.empty((N, n))
    y = np.empty(p)
    u = np.zeros((Bsz, m))
    r = np.zeros((Bsz, m))
    w = np.empty(m)
    pa = period_arrays(x, z, gamma, gamma_s, v, x_r, u, r)  # the environments' PeriodArrays type
    lo = np.int64(0)
    if len(fault) > 0:
        FF, FI, fst, co_nodes = fault
        ff = unpack_fault_args(FF, FI)
        fs = FaultState(*fst)
        fperiod = FaultPeriod(ff, fs, np.empty((Bsz, ff.sender.shape[0]), dtype=np.bool_))
        noise_a, co_held_a = fs.noise, fs.co_held
        K = co_nodes.shape[0]
        xl = np.empty((N, n))
        co_rx = np.ones((Bsz, K), dtype=np.bool_)
    s = 0
    for k in range(steps + 1):
        record = k % stride == 0
        for b in range(Bsz):
            xb = x[b]
            # eq. (localmeasure) y_i = C_i x (+ the held noise), eq. (hatxieq) xhat_i = z_i + Gbar_i y_i
            for i in range(N):
                for q in range(p):
                    acc = 0.0
                    for c in range(n):
                        acc += C[i, q, c] * xb[c]
                    if len(fault) == 0:
                        y[q] = acc
                    else:
                        y[q] = acc + noise_a[b, i, q]
                for c in range(n):
                    acc = z[b, i, c]
                    for q in range(p):
                        acc += G_bar[i, c, q] * y[q]
                    xhat[i, c] = acc
            if len(fault) == 0:
                xl = xhat
            else:  # the C-O links (not at t = 0), the controllers' held estimates in their node rows
                if k > 0:
                    co_link_row(b, xhat.reshape(N * n), co_nodes, ff, fs, co_rx)
                for i in range(N):
                    for c in range(n):
                        xl[i, c] = xhat[i, c]
                for l in range(K):
                    for c in range(n):
                        xl[co_nodes[l], c] = co_held_a[b, l, c]
            if record:
                _record_sample(rec, b, s, xb, x_r, xhat, gamma, gamma_s, beta)
            if k < steps:
                law_copy(law, xl, xb, oracle, ref[k], cmd[k], beta[b], eps[b], phi_beta[b], decay, gain, u[b], w)
                for j in range(m):
                    r[b, j] = ref[k, j]
            if record:
                rec.u[b, s] = u[b]  # the input applied from t_k on (at the last sample: the one before)
        if record:
            s += 1
        if k < steps:
            if len(fault) == 0:
                advance_rows(pa, ka, lo, Bsz, fault)
            else:
                advance_rows(pa, ka, lo, Bsz, fperiod)


def fault_seeds(seed, batch: int) -> np.ndarray:
    """``(batch,)`` uint64 fault seeds of the copies of a rollout: ``numpy.random.SeedSequence(seed)``'s
    first ``batch`` 64-bit words (``seed`` a non-negative int), or ``seed`` itself as one per copy."""
    arr = np.asarray(seed)
    if arr.ndim == 1:
        from .sim.fault_rng import as_seeds

        return as_seeds(list(seed), batch, "fault_seed")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"fault_seed must be a non-negative int or one per copy, got {seed!r}")
    return np.random.SeedSequence(int(seed)).generate_state(batch, dtype=np.uint64)


def _fault_setup(sc, params, faults, state, seeds):
    """``(FaultArgs, FaultState, co_nodes)`` of a faulted rollout (ValueError naming ``faults`` where the
    controllers share observer nodes: one held estimate per node row of the law)."""
    fa = fault_args(faults, params)
    co_nodes = np.asarray(sc.links, dtype=np.int64)
    if np.unique(co_nodes).size != co_nodes.size:
        raise ValueError(f"faults: rollout needs one observer node per controller (the law reads node rows), "
                         f"got links {list(sc.links)}")
    fs = init_fault_state(params, fa, state.x, state.z, seeds, co_nodes=co_nodes)
    return fa, fs, co_nodes


def rollout(sc, *, dt: float | None = None, t_end: float | None = None, batch: int = 1, epsilon=None,
            phi_beta=None, oracle: bool = False, record_every: int = 1, faults=None,
            fault_seed=0, x0=None) -> list[Trajectory]:
    """Compiled closed-loop runs of ``batch`` copies of scenario ``sc`` with its paper controller.

    Parameters
    ----------
    sc : Scenario
        The system, its observer design, controller (``sc.controller``) and printed initial
        conditions (every copy starts from them unless ``x0`` is given).
    dt, t_end : float, optional
        Euler step (= control period) and horizon (s); default the scenario's.
    batch : int
        Number of copies ``B``.
    epsilon, phi_beta : float or array_like (B,), optional
        Per-copy boundary layer and adaptation gain of the adaptive sliding-mode law (eqs.
        hepsfunc, adlawbeta); default the scenario's. Ignored by the other laws.
    oracle : bool
        Apply the control law to the true state ``x`` instead of the linked estimates.
    record_every : int
        Record every ``record_every``-th Euler step (and the last one if it falls on the grid).
    faults : dict or Faults, optional
        Communication faults (module doc; periods are Euler steps here); None: the ideal network.
    fault_seed : int or array_like (B,)
        The copies' fault seeds (:func:`fault_seeds`).
    x0 : array_like (n,) or (B, n), optional
        Initial plant states (one for every copy or one per copy); default the scenario's printed
        ``x0``. The other initial conditions are the scenario's (``z_i(0) = 0``, ``gamma(0)``, ...).

    Returns
    -------
    list of Trajectory
        One per copy, sampled at ``t = k * record_every * dt`` (``est_err``: of the nodes' own,
        noisy-measurement estimates).
    """
    faults = Faults.from_value(faults)
    dt, t_end, steps = _steps(sc, dt, t_end)
    batch, stride = int(batch), int(record_every)
    if batch < 1:
        raise ValueError(f"batch must be >= 1, got {batch}")
    if stride < 1:
        raise ValueError(f"record_every must be >= 1, got {record_every}")
    params = sc.sim_params(dt=dt, substeps=1)
    state = sc.initial_state(params, x0=_initial_x0(sc, x0, batch), batch=batch)
    ctrl = paper_policy(sc)
    n, N, m = params.n_states, params.n_nodes, params.n_inputs
    law = law_arrays(ctrl, m, n)
    sigma_b = law.sigma_beta
    decay = float(np.exp(-sigma_b * dt))
    t_grid = np.arange(steps) * dt
    loop = LoopArgs(oracle=bool(oracle), eps=_per_copy("epsilon", epsilon, law.epsilon, batch),
                    phi_beta=_per_copy("phi_beta", phi_beta, law.phi_beta if law.phi_beta > 0 else 1.0, batch),
                    decay=decay, gain=(1.0 - decay) / sigma_b if sigma_b > 0 else dt,
                    cmd=_signal(getattr(sc, "prescribed_input", None) if law.code == 0 else None, t_grid, m),
                    ref=_signal(sc.reference, t_grid, m), steps=steps, stride=stride)
    Nc = law.starts.shape[0]
    beta = np.full((batch, Nc), law.beta0)
    R = steps // stride + 1
    rec = Recording(x=np.empty((batch, R, n)), x_r=np.empty((batch, R, n)), est_err=np.empty((batch, R, N)),
                    gamma=np.empty((batch, R, N)), gamma_s=np.empty((batch, R, N)), u=np.zeros((batch, R, m)),
                    beta=np.empty((batch, R, Nc)))
    x, z, g, gs, v, xr = (np.array(a, dtype=float, order="C") for a in
                          (state.x, state.z, state.gamma, state.gamma_s, state.v, state.x_r))
    fault = NO_FAULT
    if faults is not None:
        fa, fs, co_nodes = _fault_setup(sc, params, faults, state, fault_seeds(fault_seed, batch))
        fault = (*pack(fa), tuple(np.array(a, copy=True, order="C") for a in fs), co_nodes)
    _rollout_kernel((x, z, g, gs, v, xr), beta, params.kernel_packed, law, loop, rec, fault)
    if steps % stride == 0 and R > 1:
        rec.u[:, -1] = rec.u[:, -2]
    t = np.arange(R) * (dt * stride)
    has_beta = law.code in (3, 4)
    return [Trajectory(t=t, x=rec.x[b], x_r=rec.x_r[b] if sc.reference is not None else None,
                       est_err=rec.est_err[b], gamma=rec.gamma[b], gamma_s=rec.gamma_s[b], u=rec.u[b],
                       beta=rec.beta[b] if has_beta else None) for b in range(batch)]


def rollout_reference(sc, *, dt: float | None = None, t_end: float | None = None, oracle: bool = False,
                      backend: str = "numpy", progress: bool = False, faults=None, fault_seed=0,
                      x0=None) -> Trajectory:
    """Reference implementation of :func:`rollout` (one copy, the scenario's own gains).

    A Python loop: per Euler step :func:`~dobs_envs.sim.estimates`, the controller's ``act``
    (numpy) and :func:`~dobs_envs.sim.step_env` with the given ``backend`` (``"numpy"``: the
    reference step, ``"numba"``: the compiled step). With ``faults``: the noisy estimates
    (:func:`~dobs_envs.sim.fault_state.faulted_estimates`), the C-O links
    (:func:`~dobs_envs.sim.fault_state.co_link_numpy`) and
    :func:`~dobs_envs.sim.numpy_step.control_period_faulted_numpy` (``backend`` ignored); the copy's
    fault seed is ``fault_seeds(fault_seed, 1)``; ``x0 (n,)``: the initial plant state (default the printed one).
    """
    faults = Faults.from_value(faults)
    dt, t_end, steps = _steps(sc, dt, t_end)
    params = sc.sim_params(dt=dt, substeps=1)
    state = sc.initial_state(params, x0=_initial_x0(sc, x0, 1))
    if faults is not None:
        fa, fs, co_nodes = _fault_setup(sc, params, faults, state, fault_seeds(fault_seed, 1))
    ctrl = paper_policy(sc)
    cstate = ctrl.initial_state(1)
    n, N, m = params.n_states, params.n_nodes, params.n_inputs
    has_beta = getattr(ctrl, "kind", None) in ("sliding_mode", "adaptive_sliding_mode")
    T = steps + 1
    xs = np.empty((T, n)); xrs = np.empty((T, n)); ee = np.empty((T, N))
    gs = np.empty((T, N)); gss = np.empty((T, N)); us = np.zeros((T, m))
    bs = np.empty((T, ctrl.n_controllers)) if has_beta else None
    it = range(steps + 1)
    if progress:
        from tqdm.auto import tqdm
        it = tqdm(it, desc=sc.name, unit="step", mininterval=0.5, leave=False)
    for k in it:
        if faults is None:
            xhat = estimates(state, params)
        else:
            xhat = faulted_estimates(state.x, state.z, params, fs)
            if k > 0:
                _, fs = co_link_numpy(xhat[:, co_nodes], fs, fa)
        xs[k] = state.x[0]; xrs[k] = state.x_r[0]
        ee[k] = np.linalg.norm(xhat[0] - state.x[0], axis=-1)
        gs[k] = state.gamma[0]; gss[k] = state.gamma_s[0]
        if has_beta:
            bs[k] = cstate.beta[0]
        if k == steps:
            break
        t = np.array([k * dt])
        if faults is not None:
            xhat = xhat.copy()
            xhat[:, co_nodes] = fs.co_held  # what the controllers hold
        src = np.broadcast_to(state.x[:, None, :], xhat.shape) if oracle else xhat
        u, cstate = ctrl.act(src, t, cstate, dt)
        us[k] = u[0]
        r = np.zeros((1, m)) if sc.reference is None else sc.reference(t)
        if faults is None:
            state = step_env(state, u, params, r, backend=backend, validate=False)
        else:
            *new, fs = control_period_faulted_numpy(state.x, state.z, state.gamma, state.gamma_s, state.v,
                                                    state.x_r, u, r, params, fa, fs)
            state = state.replace(t=state.t + dt, x=new[0], z=new[1], gamma=new[2], gamma_s=new[3], v=new[4],
                                  x_r=new[5])
    us[-1] = us[-2] if T > 1 else us[-1]
    return Trajectory(t=np.arange(T) * dt, x=xs, x_r=xrs if sc.reference is not None else None,
                      est_err=ee, gamma=gs, gamma_s=gss, u=us, beta=bs)
