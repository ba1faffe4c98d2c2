"""Parity of the JAX environments with the compiled core (the gymnax / JaxMARL way of checking a port).

:func:`state_from_core` copies copy ``c`` of a compiled :class:`~dobs_envs.envs.env_core.EnvCore` into an
:class:`~dobs_envs.jax.params.EnvState`. :func:`one_step_episode` runs an episode of the compiled core
and, at every step, steps the JAX form from the core's state with the same input, recording the
largest difference of every quantity; :func:`free_run_episode` runs both side by side from the same
initial state with a policy acting on each one's own observations (the episode returns then differ
by what the two simulations' round-off makes of the discontinuous observer term). Used by
``tests/test_jax_parity.py`` and ``benchmarks/jax_parity.py``.

Differences are reported relative to ``max(1, |compiled value|)`` (the largest over a quantity's
entries), so that they read as relative errors for large values and absolute ones near zero.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import core as _core
from . import faults as _faults
from .faults import FaultState
from .params import EnvState

__all__ = ["state_from_core", "advance_fn", "one_step_episode", "free_run_episode", "QUANTITIES"]

#: the quantities compared by :func:`one_step_episode`
QUANTITIES = ("t", "x", "x_r", "v", "z", "gamma", "gamma_s", "obs", "reward", "estimation_errors",
              "tracking_error", "task_error")
#: with faults: the fault state's real arrays (compared as :data:`QUANTITIES`, under ``"fault"``) and its draws
#: and counters (compared for equality, mismatches counted under ``"draws"`` with the received flags)
_FAULT_REAL = ("received", "snapshots", "noise", "co_sent", "co_held")
_FAULT_DISCRETE = ("seed", "period", "bad", "graph")


def state_from_core(core, c: int, dtype) -> EnvState:
    """Copy ``c`` of the compiled core as a JAX state (``dtype`` the float type)."""
    s = core.sim_state
    f = lambda a: jnp.asarray(np.asarray(a, dtype=np.float64), dtype=dtype)  # noqa: E731
    fault = None
    if core.faults is not None:
        fs = core.fault_state
        fault = FaultState(seed=jnp.asarray(fs.seed[c], jnp.uint64), period=jnp.asarray(fs.period[c], jnp.int64),
                           received=f(fs.received[c]), snapshots=f(fs.snapshots[c]), bad=jnp.asarray(fs.bad[c]),
                           graph=jnp.asarray(fs.graph[c], jnp.int64), noise=f(fs.noise[c]), co_sent=f(fs.co_sent[c]),
                           co_held=f(fs.co_held[c]))
    return EnvState(t=f(s.t[c]), x=f(s.x[c]), z=f(s.z[c]), gamma=f(s.gamma[c]), gamma_s=f(s.gamma_s[c]),
                    v=f(s.v[c]), x_r=f(s.x_r[c]), u=f(core.applied_inputs[c]),
                    time=jnp.asarray(int(core.cycles[c]), jnp.int32), sig=f(core._sig[:, c]), fault=fault)


_ADVANCE = {}


def advance_fn(structure):
    """``jit(advance)(state, u, params)`` of ``structure`` (one compilation per structure, params traced)."""
    fn = _ADVANCE.get(id(structure))
    if fn is None or fn[0] is not structure:
        fn = (structure, jax.jit(lambda s, u, p: _core.advance(s, u, p, structure)))
        _ADVANCE[id(structure)] = fn
    return fn[1]


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.size == 0:
        return 0.0
    fin = np.isfinite(b)
    if not np.array_equal(fin, np.isfinite(a)):
        return np.inf
    scale = max(1.0, float(np.max(np.abs(np.where(fin, b, 0.0)), initial=0.0)))
    return float(np.max(np.abs(np.where(fin, a - b, 0.0)), initial=0.0)) / scale


def one_step_episode(core, structure, params, inputs, *, seed: int, steps: int, dtype=jnp.float64,
                     max_z_diff=None) -> dict:
    """One episode of the batch-1 compiled ``core`` (reset with ``seed``) with the inputs ``inputs(core, k)
    -> u (m,)``; at each step the JAX form advances the core's state with the same input.

    Returns ``{quantity: largest difference}`` (module doc), with ``"steps"`` the steps run and
    ``"ends"`` the number of mismatched terminated / truncated / reason values (0 expected). With faults
    also ``"fault"`` (the fault state's held copies, snapshots, noise and C-O buffers) and ``"draws"`` (the
    steps whose graph, burst states, counters or received flags differ: 0 expected, the draws being the
    same counter-based generator).
    ``max_z_diff(state, structure, params) -> float``, if given, records under ``"z_band"`` the largest
    ratio of the observer states' difference to that bound (with faults also ``"fault_band"``: the held
    estimates', broadcast at instants inside the period).
    """
    adv = advance_fn(structure)
    core.reset(None, [seed])
    worst = dict.fromkeys(QUANTITIES, 0.0)
    worst.update(ends=0, z_band=0.0)
    if structure.faults is not None:
        worst.update(fault=0.0, draws=0, fault_band=0.0)
    k = 0
    for k in range(steps):
        u = np.asarray(inputs(core, k), dtype=np.float64)
        js = state_from_core(core, 0, dtype)
        ns, out = adv(js, jnp.asarray(u, dtype=dtype), params)
        res = core.advance(u[None])
        s = core.sim_state
        for q in ("t", "x", "x_r", "v", "z", "gamma", "gamma_s"):
            worst[q] = max(worst[q], _rel(getattr(ns, q), getattr(s, q)[0]))
        if max_z_diff is not None:
            band = max_z_diff(js, structure, params)
            dz = float(np.max(np.abs(np.asarray(ns.z) - s.z[0]), initial=0.0))
            worst["z_band"] = max(worst["z_band"], dz / band)
        worst["obs"] = max(worst["obs"], _rel(out.obs, core.observations[0]))
        worst["reward"] = max(worst["reward"], _rel(out.reward, res.reward[0]))
        worst["estimation_errors"] = max(worst["estimation_errors"],
                                         _rel(out.features.estimation_errors, core.estimation_errors[0]))
        worst["tracking_error"] = max(worst["tracking_error"], _rel(out.features.tracking_error,
                                                                   core.tracking_errors[0]))
        if structure.faults is not None:  # the fault state and what the agents received
            fs, rx = core.fault_state, out.features.received
            worst["fault"] = max([worst["fault"]] + [_rel(getattr(ns.fault, q), getattr(fs, q)[0]) for q in _FAULT_REAL])
            if max_z_diff is not None:  # held estimates: as close as the observers within the period
                df = max(float(np.max(np.abs(np.asarray(getattr(ns.fault, q)) - getattr(fs, q)[0]), initial=0.0))
                         for q in _FAULT_REAL)
                worst["fault_band"] = max(worst["fault_band"], df / band)
            worst["draws"] += sum(int(not np.array_equal(np.asarray(getattr(ns.fault, q)), getattr(fs, q)[0]))
                                  for q in _FAULT_DISCRETE)
            worst["draws"] += int(not np.array_equal(np.asarray(rx.co_rx), core.co_received[0]))
            worst["draws"] += int(not np.allclose(np.asarray(_faults.received_fraction(structure.faults, rx.oo_rx)),
                                                  core.oo_received_fraction[0], rtol=0.0, atol=1e-15))
        te = _core.task_error(ns, structure)
        if te is not None:
            worst["task_error"] = max(worst["task_error"], _rel(te, core.task_errors()[0]))
        worst["ends"] += int(bool(out.terminated) != bool(res.terminated[0])) \
            + int(bool(out.truncated) != bool(res.truncated[0])) + int(int(out.reason) != int(res.reason[0]))
        if res.terminated[0] or res.truncated[0]:
            break
    worst["steps"] = k + 1
    return worst


def free_run_episode(penv, structure, params, make_policy, *, seed: int, dtype=jnp.float64) -> tuple:
    """The returns of one episode of the PettingZoo env ``penv`` and of the JAX form from the same initial
    state (``penv.reset(seed=seed)``'s), each driven by its own ``make_policy(penv)`` (``policy.inputs(obs
    dict) -> u``) on its own observations. Returns ``(return_compiled, return_jax, steps)``."""
    obs, _ = penv.reset(seed=seed)
    core = penv.core
    s = core.sim_state
    seed = core.fault_state.seed[0] if core.faults is not None else None
    js = _core.initial_state(params, structure, s.x[0], v0=s.v[0], x_r0=s.x_r[0], sig=core._sig[:, 0],
                             fault_seed=seed)
    adv = advance_fn(structure)
    pa, pb = make_policy(penv), make_policy(penv)
    agents, widths = structure.agents, structure.obs_widths
    split = lambda o: {a: np.asarray(o[i, :w]) for i, (a, w) in enumerate(zip(agents, widths))}  # noqa: E731
    jobs = split(_core.observations(_core.features(js, params, structure), structure))
    ra = rb = 0.0
    k = 0
    for k in range(int(params.max_steps_in_episode)):
        ua, ub = pa.inputs(obs), pb.inputs(jobs)
        obs, r, te, tr, _ = penv.step(penv.actions_from_inputs(ua))
        js, out = adv(js, jnp.asarray(ub, dtype=dtype), params)
        jobs = split(out.obs)
        a0 = agents[0]
        ra += r[a0]
        rb += float(out.reward)
        if te[a0] or tr[a0]:
            break
    return ra, rb, k + 1

