"""The environment step and reset of one copy as pure functions (the engine of both JAX views).

:func:`advance` is the JAX form of one step of :class:`~dobs_envs.envs.env_core.EnvCore` (its numpy
reference :func:`dobs_envs.envs.numpy_advance.advance_reference` is the specification):

1. the inputs are clipped to the action bounds and held over the control period (ZOH);
2. the ``"random"`` disturbance is evaluated at the period's start and held;
3. one control period (:func:`dobs_envs.jax.dynamics.control_period`) with the reference command
   ``r(t)`` of eq. (refxdy) held from the period's start;
4. the features of :mod:`dobs_envs.envs.observation` (:func:`features`: ``y``, the estimates of eq.
   (hatxieq), ``x``, ``x_r``, the gains, ``v``, ``r``, ``t``, the task error ``e``), the stage cost
   ``c = e'Qe + u'Ru``, the norms and the finiteness of the whole state;
5. the reward ``-shape(c) T`` (``T`` the control period), the termination on the state bound or a
   non-finite state with the termination penalty, the truncation after ``max_steps_in_episode`` steps,
   and the reason codes of :data:`dobs_envs.envs.env_core.REASONS`;
6. the observations of a terminated copy cleaned (NaN -> 0, +-inf -> +-the dtype's largest value).

:func:`reset` draws what :class:`~dobs_envs.envs.distributions.ResetDistribution` draws, from the same
distributions, with ``jax.random``; :func:`initial_state` builds the state from given values (the
``x0``/``v0``/``x_r0`` reset options of the compiled environments).
"""
from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import expm

from ..envs.distributions import N_RANDOM_TERMS
from ..envs.step_kernel import REASON_HORIZON, REASON_NON_FINITE, REASON_NONE, REASON_STATE_BOUND
from . import faults as _faults
from .dynamics import coefs, control_period, outputs
from .operators import stack, unstack
from .params import EnvState

__all__ = ["Features", "StepOut", "advance", "features", "observations", "initial_state", "reset", "task_error",
           "bound_step_cost"]


class Features(NamedTuple):
    """What one copy's step computes besides the state (module doc, item 4)."""

    f: jax.Array  # (F,) the feature vector of dobs_envs.envs.observation
    estimation_errors: jax.Array  # (N,) ||xhat_i - x||
    cost: jax.Array  # e'Qe + u'Ru
    tracking_error: jax.Array  # ||e||
    xnorm: jax.Array  # ||x||
    finite: jax.Array  # every entry of x, x_r, z, gamma, gamma_s, v is finite
    fault: object = None  # faults: the fault state after the boundary's C-O link (dobs_envs.jax.faults.FaultState)
    received: object = None  # faults: what the agents received (dobs_envs.jax.faults.Received)


class StepOut(NamedTuple):
    """:func:`advance`'s outputs besides the new state."""

    obs: jax.Array  # (K, D) padded observations (cleaned when terminated)
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    reason: jax.Array  # int32 code of dobs_envs.envs.env_core.REASONS
    features: Features


def reference_command(t, params, structure):
    """``r(t) = a sin(w t + phi)`` of eq. (refxdy) (zeros without a reference), ``(m,)``."""
    if not structure.has_reference:
        return jnp.zeros(structure.m, dtype=structure.dtype)
    a, w, ph = params.ref
    return a * jnp.sin(w * t + ph)


def features(state: EnvState, params, structure, *, link: bool = False) -> Features:
    """Eqs. (localmeasure), (hatxieq), the reference command, the task error, the cost and the
    finiteness of one copy (:func:`dobs_envs.envs.numpy_features.write_features_reference`).

    With faults the outputs carry the period's measurement noise and the feature vector ends with what the
    agents received (:func:`dobs_envs.jax.faults.boundary`; ``link``: run the C-O link, as after a step;
    False: as at a reset); the fault state after the boundary is :attr:`Features.fault`."""
    x, z, xr, t = state.x, state.z, state.x_r, state.t
    N, n, dt = structure.N, structure.n, structure.dtype
    fst = structure.faults
    noise = unstack(state.fault.noise) if fst is not None and fst.noisy else None
    y, xhat = outputs(unstack(x), unstack(z), coefs(params, structure), jnp.zeros((), dt), noise)
    y, xhat = stack(y, (N * structure.p,), dt), stack(xhat, (N, n), dt)
    est = jnp.linalg.norm(xhat - x[None, :], axis=1)
    e = x - xr if structure.has_reference else x
    fault = rx = None
    received = []
    if fst is not None:
        fault, rx = _faults.boundary(fst, params.faults, state.fault, xhat, link=link)
        received = [rx.xhat_rx.reshape(-1), rx.nbr_rx.reshape(-1), rx.co_rx.astype(dt), rx.oo_rx.astype(dt)]
    f = jnp.concatenate([
        y[structure.y_index], xhat.reshape(-1), x, xr, state.gamma, state.gamma_s, state.v,
        reference_command(t, params, structure), t[None], e, *received, jnp.zeros(1, dt), jnp.ones(1, dt)])
    u = state.u
    cost = e @ (params.Q @ e) + u @ (params.R @ u)
    finite = (jnp.all(jnp.isfinite(x)) & jnp.all(jnp.isfinite(xr)) & jnp.all(jnp.isfinite(z))
              & jnp.all(jnp.isfinite(state.gamma)) & jnp.all(jnp.isfinite(state.gamma_s))
              & jnp.all(jnp.isfinite(state.v)))
    return Features(f, est, cost, jnp.linalg.norm(e), jnp.linalg.norm(x), finite, fault, rx)


def task_error(state: EnvState, structure):
    """The task's own error (hetero_mas: the rendezvous disagreement ``||p - pbar 1||`` of the positions ``p``,
    as :class:`dobs_envs.envs.hetero_mas.Disagreement`), or None when the task has none."""
    if structure.task_positions is None:
        return None
    pos = state.x[structure.task_positions]
    return jnp.linalg.norm(pos - jnp.mean(pos))


def observations(feat: Features, structure) -> jax.Array:
    """The agents' padded observations ``(K, D)`` in the observation dtype."""
    return feat.f[structure.padded_index].astype(structure.obs_dtype)


def _shaped(c, params, structure):
    """The stage cost of the reward: ``c``, ``log(1 + c / c0)`` or ``sqrt(c)``."""
    if structure.reward_code == 1:
        c0 = jnp.maximum(params.lam_q, jnp.finfo(structure.dtype).tiny) * params.cost_scale ** 2
        return jnp.where(c < jnp.inf, jnp.log1p(c / c0), jnp.inf)
    if structure.reward_code == 2:
        return jnp.sqrt(c)
    return c


def bound_step_cost(params, structure):
    """The cost of one control period on the state bound, ``shape(lambda_max(Q) state_bound^2) T``: the
    termination penalty per remaining step."""
    return _shaped(params.lam_q * params.state_bound ** 2, params, structure) * (params.dt * structure.substeps)


def _check_x64(structure) -> None:
    """A float64 environment traced without 64-bit JAX would run in float32 silently: refuse it."""
    if structure.dtype == np.float64 and not jax.config.jax_enable_x64:
        raise ValueError("this environment was made with dtype='float64' but 64-bit JAX is off here: call "
                         "jax.config.update('jax_enable_x64', True) (or make it with dtype='float32')")
    if structure.faults is not None:
        _faults.check_x64()


def advance(state: EnvState, u, params, structure) -> tuple[EnvState, StepOut]:
    """One control step of one copy with the input ``u (m,)`` (module doc). Returns ``(state, out)``."""
    _check_x64(structure)
    p, st = params, structure
    period = p.dt * st.substeps
    u = jnp.minimum(jnp.maximum(u.astype(st.dtype), p.action_low), p.action_high)
    v = state.v
    if st.disturbance == 2:  # random: v(t) at the period's start, held
        a, w, ph = state.sig
        v = jnp.sum(a * jnp.sin(w * state.t + ph), axis=1)
    r = reference_command(state.t, p, st)
    fs = state.fault
    if st.faults is None:
        x, z, g, gs, v, xr, _ = control_period(state.x, state.z, state.gamma, state.gamma_s, v, state.x_r, u, r, p, st)
    else:  # the faulted O-O exchange at the ideal one's seam; then the period's end draws
        x, z, g, gs, v, xr, (rec, snaps) = control_period(
            state.x, state.z, state.gamma, state.gamma_s, v, state.x_r, u, r, p, st,
            exchange=partial(_faults.FaultedExchange, fs=fs), carry=(unstack(fs.received), fs.snapshots))
        fs = _faults.next_period(st.faults, p.faults, fs, stack(rec, fs.received.shape, st.dtype), snaps)
    time = state.time + 1
    new = state.replace(t=state.t + period, x=x, z=z, gamma=g, gamma_s=gs, v=v, x_r=xr, u=u, time=time, fault=fs)
    feat = features(new, p, st, link=True)
    if st.faults is not None:
        new = new.replace(fault=feat.fault)
    rw = -_shaped(feat.cost, p, st) * period
    bound = (feat.xnorm > p.state_bound) & jnp.all(jnp.isfinite(x))  # a finite plant beyond the bound
    non_finite = ~feat.finite & ~bound
    term = non_finite | bound
    bsc = bound_step_cost(p, st)
    rw = jnp.where(term & ~jnp.isfinite(rw), -bsc, rw)
    if st.termination_penalty:
        rw = jnp.where(term, rw - bsc * jnp.maximum(0, p.max_steps_in_episode - time), rw)
    trunc = ~term & (time >= p.max_steps_in_episode)
    reason = jnp.where(non_finite, REASON_NON_FINITE, jnp.where(bound, REASON_STATE_BOUND,
                                                               jnp.where(trunc, REASON_HORIZON, REASON_NONE)))
    obs = observations(feat, st)
    big = np.finfo(st.obs_dtype).max
    obs = jnp.where(term, jnp.nan_to_num(obs, nan=0.0, posinf=big, neginf=-big), obs)
    return new, StepOut(obs, rw, term, trunc, reason.astype(jnp.int32), feat)


def initial_state(params, structure, x0, v0=None, x_r0=None, sig=None, fault_seed=None) -> EnvState:
    """The state at reset with the given plant state ``x0 (n,)`` (``v0 (m_v,)``: the unknown input, default
    the scenario's; ``x_r0 (n,)``: the reference model, default the scenario's; ``sig (3, m_v, L)``: the
    ``"random"`` disturbance's parameters, ``v0`` then follows from them; ``fault_seed``: with faults, the
    copy's fault seed, a ``uint64`` (:class:`dobs_envs.sim.fault_state.FaultState` ``seed``: the compiled
    core's copy with that seed draws the same faults), required then)."""
    st, dt = structure, structure.dtype
    N, m, m_v = st.N, st.m, st.m_v
    if sig is None:
        sig = jnp.zeros((3, m_v, N_RANDOM_TERMS), dt)
    else:
        sig = jnp.asarray(sig, dt)
        if st.disturbance == 2:
            a, w, ph = sig
            v0 = jnp.sum(a * jnp.sin(ph), axis=1)
    v = params.v0 if v0 is None else jnp.asarray(v0, dt)
    if st.disturbance == 0:
        v = jnp.zeros(m_v, dt)
    x0 = jnp.asarray(x0, dt)
    z0 = jnp.zeros((N, st.n), dt)
    fault = None
    if st.faults is not None:
        if fault_seed is None:
            raise ValueError("fault_seed: this environment has communication faults (option faults); give the "
                             "copy's fault seed (an unsigned 64-bit integer)")
        K = coefs(params, st)

        def xhat0(noise):
            y, xh = outputs(unstack(x0), unstack(z0), K, jnp.zeros((), dt), None if noise is None else unstack(noise))
            return stack(xh, (N, st.n), dt)

        fault = _faults.init_state(st.faults, params.faults, fault_seed, xhat0, dt)
    return EnvState(t=jnp.zeros((), dt), x=x0, z=z0, gamma=params.gamma0,
                    gamma_s=params.gamma_s0, v=v, x_r=params.x_r0 if x_r0 is None else jnp.asarray(x_r0, dt),
                    u=jnp.zeros(m, dt), time=jnp.zeros((), jnp.int32), sig=sig, fault=fault)


def reset(key, params, structure) -> EnvState:
    """A reset draw of one copy (:class:`~dobs_envs.envs.distributions.ResetDistribution`'s distributions,
    drawn with ``jax.random``; with faults, the copy's fault seed too, uniform over 64 bits)."""
    _check_x64(structure)
    st, dt = structure, structure.dtype
    if st.faults is not None:
        key, kf = jax.random.split(key)
        fault_seed = jax.random.bits(kf, (), jnp.uint64)
    else:
        fault_seed = None
    kx, kv = jax.random.split(key)
    if st.x0_uniform:
        x0 = jax.random.uniform(kx, (st.n,), dt, -params.x0_scale, params.x0_scale)
    else:
        x0 = params.x0 + jax.random.uniform(kx, (st.n,), dt, -params.init_noise, params.init_noise)
    if st.disturbance == 2:  # random: w ~ U[0.1, 2], phase ~ U[0, 2 pi], amplitudes summing to the bound
        kw, kp, ka = jax.random.split(kv, 3)
        shape = (st.m_v, N_RANDOM_TERMS)
        w = jax.random.uniform(kw, shape, dt, 0.1, 2.0)
        ph = jax.random.uniform(kp, shape, dt, 0.0, 2 * np.pi)
        a = jax.random.uniform(ka, shape, dt, 0.0, 1.0)
        a = params.disturbance_amplitude * a / jnp.sum(a, axis=1, keepdims=True)
        return initial_state(params, st, x0, sig=jnp.stack([a, w, ph]), fault_seed=fault_seed)
    if st.disturbance == 1 and st.exosystem:  # a random time shift of the exosystem's trajectory
        tau = jax.random.uniform(kv, (), dt, 0.0, 4 * np.pi)
        return initial_state(params, st, x0, v0=expm(params.S * tau) @ params.v0, fault_seed=fault_seed)
    return initial_state(params, st, x0, fault_seed=fault_seed)
