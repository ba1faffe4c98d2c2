"""``disturbance_rejection_v0``: NE3 stabilisation under a matched unknown input."""
from __future__ import annotations

import numpy as np

from .parallel_env import DObsParallelEnv
from .options import RENDER_MODES

__all__ = ["DisturbanceRejectionEnv", "NE3_ACTION_BOUND"]

#: Per-input bounds on NE3: 1.5 x the largest |u^k| of the reference (adaptive
#: sliding-mode) policy over 20 seeded episodes of the default distribution
#: (measured 6.5, 12.1, 5.0, 37.5, 4.1 with the exosystem disturbance,
#: 5.7, 10.5, 5.0, 37.5, 3.1 with disturbance="random" and 5.2, 10.1, 5.0, 37.5, 3.1 with
#: "none", at the default control period), rounded up to a multiple of 5.
NE3_ACTION_BOUND = (10.0, 20.0, 10.0, 60.0, 10.0)


class DisturbanceRejectionEnv(DObsParallelEnv):
    """Distributed observer-based stabilisation under a matched unknown input (NE3; PettingZoo ``ParallelEnv``).

    ## Description

    The NE2 plant, channels, observer nodes, O-O ring graph and C-O links
    (see ``tracking_v0``) now with the matched unknown input of the paper's
    Section NE3: ``x' = A x + B u + B_v v`` (eq. LTIsys) with
    ``B_v = [B^1 B^2]`` (Assumption matchcondition). ``v`` is unknown to every
    node: the observer design treats it as an unavailable input (eq.
    splitinput, ``B_{-i}``), and the observer gains follow the leakage laws
    (gagasbeta) with NE3's constants. The team must drive ``x`` to the origin.
    The paper's solution (Theorem adsmthm) is the adaptive boundary-layer
    sliding-mode law ``u^k = K^k xhat_k - beta^k h_eps((B^k)^T P xhat_k)``
    (eqs. hepsfunc, adlawbeta; :class:`baselines.policies.SeparationPolicy`),
    which reaches a residual set around the origin (``||x||`` about 0.3 with
    ``epsilon = 0.2``).

    The unknown input (``disturbance=``):

    * ``"exosystem"`` (default): the paper's ``v' = S v``,
      ``S = [[0, 0.5], [-0.5, 0]]``, started from ``v(0) = expm(S tau) (-2, 2)``
      with a seeded random time shift ``tau ~ U[0, 4 pi]`` s (a uniformly random
      phase of the paper's signal, amplitude ``2 sqrt 2``);
      ``reset(options={"v0": (-2, 2)})`` gives the paper's.
    * ``"random"``: per component ``v_j(t) = sum_{l=1..3} a_jl sin(w_jl t + phi_jl)``,
      ``w_jl ~ U[0.1, 2]`` rad/s, ``phi_jl ~ U[0, 2 pi]``, ``a_jl >= 0`` random with
      ``sum_l a_jl = disturbance_amplitude`` (2.0), so ``|v_j(t)| <= disturbance_amplitude``
      (Assumption vbound); drawn at every reset, held over each control period.
    * ``"none"``: ``v = 0``.

    ## Action Space

    Agent ``controller_k``: ``Box(-b_k, b_k, (1,), float32)`` with
    ``b = (10, 20, 10, 60, 10)`` (:data:`NE3_ACTION_BOUND`); out-of-range actions
    are clipped; NaN/inf, wrong shapes, unknown agents raise ``ValueError``.

    ## Observation Space

    Agent ``controller_k`` (observer node ``k``): ``Box(-inf, inf, (30,), float32)``::

        [0:1]    y_k        measured output of its node
        [1:10]   xhat_k     its node's estimate
        [10:28]  neighbours estimates of node k's ring neighbours
        [28:30]  mask       1 per real neighbour slot

    (no reference). ``observation="full"`` adds the privileged ``x``, all
    estimates, gains, ``v`` and ``t``. ``state()``: ``(x, xhat_0..xhat_5, v)`` (65 values).

    ## Rewards

    ``-(x'Qx + sum_k u_k' R_k u_k) * T`` per control step (``x`` at the end of
    the step), ``Q = I_9``, ``R = I_5`` by default; shared by all agents.
    ``reward="log"`` replaces the stage cost ``c`` by ``log(1 + c / c0)``, ``c0 =
    lambda_max(Q) * cost_scale^2`` (``cost_scale=0.1``), and ``reward="sqrt"`` by
    ``sqrt(c)``, so that steady-state errors weigh more against the transient
    (benchmarks evaluate on the quadratic cost).

    ## Starting State

    ``x(0) = x0 + U[-1, 1]^9`` with the paper's ``x0 = (1, -1, 1, -1, 1, -1, 1, -1, 1)``;
    ``z_i(0) = 0``, ``gamma_i(0) = gamma_is(0) = 0.1``; ``v(0)`` as above.
    ``reset(options={"x0": ..., "v0": ...})`` sets them exactly.

    ## Episode End

    Terminated when ``||x|| > state_bound`` (1e3) or the simulated state is not
    finite (as ``tracking_v0``: ``termination_reason`` 2, cleaned terminal
    observations); truncated after ``max_cycles`` (default 400 control steps = 20 s).
    On termination the reward of that step also charges the cost of staying on the
    bound for the rest of the horizon, ``lambda_max(Q) * state_bound^2 * period`` per
    remaining control step (``termination_penalty=False`` disables it), so ending an
    episode early by diverging is never better than staying.

    ## Info

    Per agent: ``estimation_error`` of its node, ``tracking_error`` (= ``||x||``),
    ``gamma``, ``gamma_s`` of its node, ``termination_reason`` (integer code, as ``tracking_v0``).

    ## Arguments

    ``disturbance_rejection_v0.parallel_env(scenario=None, dt=1e-3, substeps=50,
    max_cycles=None, horizon=None, observation="local", obs_dtype="float32", Q=None,
    R=None, action_bound=None, init_noise=None, state_bound=1e3, termination_penalty=True,
    reward="quadratic", cost_scale=0.1, render_mode=None, disturbance="exosystem",
    disturbance_amplitude=2.0, normalized_actions=False, padded_observations=False, faults=None)``
    (:class:`~dobs_envs.envs.options.EnvOptions`; see
    ``tracking_v0`` for the shared ones). ``scenario=`` accepts any Scenario with an unknown
    input ``B_v``.

    ``faults=`` (communication faults and sensor noise) as in ``tracking_v0``.

    ## Version History

    * v0: initial release.
    * v0: ``padded_observations=True`` pads and adds ``obs_mask`` only where the agents'
      observation widths differ (before: always, doubling the width; the default spaces are
      unchanged).
    * v0: option ``faults`` added (default None: unchanged).
    """

    metadata = {"render_modes": list(RENDER_MODES), "name": "disturbance_rejection_v0", "is_parallelizable": True, "render_fps": 20}

    @classmethod
    def _default_scenario(cls, opts):
        from ..scenarios.paper import ne3

        return ne3()

    @classmethod
    def _check_scenario(cls, sc, opts, given):
        if sc.B_v.shape[1] == 0:
            raise ValueError(f"disturbance_rejection_v0 needs a scenario with an unknown input (Scenario.B_v); {sc.name!r} has none")

    @classmethod
    def _default_action_bound(cls, sc, opts, given):
        if opts.scenario is None:
            return np.array(NE3_ACTION_BOUND)
        return super()._default_action_bound(sc, opts, given)
