"""``action_bound="auto"``: action bounds calibrated with the scenario's paper controller."""
from __future__ import annotations

import numpy as np

from ..control import paper_policy
from ..sim import estimates, step_env

__all__ = ["auto_action_bound"]


def auto_action_bound(scenario, params, dist, max_cycles, *, episodes: int = 8, max_seconds: float = 10.0,
                      margin: float = 2.0, seed: int = 12345) -> np.ndarray:
    """``margin`` x the largest ``|u_j|`` of the scenario's paper controller
    (:func:`dobs_envs.control.paper_policy`, at the control period of ``params``) over
    ``episodes`` initial states of the reset distribution ``dist``
    (:class:`~dobs_envs.envs.distributions.ResetDistribution`, fixed seed), simulated for
    ``min(horizon, max_seconds)``; at least 1 per component. A "random" disturbance is held
    at its initial value. Deterministic for a given scenario and options.

    Returns
    -------
    ndarray (m,)
    """
    period = params.control_period
    rng = np.random.default_rng(seed)
    x0 = np.stack([dist.x0(rng) for _ in range(episodes)])
    v0 = np.stack([dist.disturbance_params(rng)[0] for _ in range(episodes)]) if dist.m_v else None
    x_r0 = scenario.x_r0 if scenario.x_r0 is not None else np.zeros(scenario.n_states)
    state = params.initial_state(x0, gamma0=scenario.gamma0, gamma_s0=scenario.gamma_s0, v0=v0, x_r0=x_r0)
    ctrl = paper_policy(scenario)
    cs = ctrl.initial_state(episodes)
    steps = int(np.ceil(min(max_seconds, (max_cycles or np.inf) * period) / period))
    umax = np.zeros(params.n_inputs)
    for _ in range(max(1, steps)):
        u, cs = ctrl.act(estimates(state, params), state.t, cs, period)
        if not np.all(np.isfinite(u)):
            break
        umax = np.maximum(umax, np.abs(u).max(axis=0))
        r = scenario.reference(state.t) if scenario.reference is not None else None
        state = step_env(state, u, params, r, validate=False)
    return np.maximum(1.0, margin * umax)
