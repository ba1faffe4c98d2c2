"""``hetero_mas_v0``: rendezvous of NE1's heterogeneous agents through distributed observers."""
from __future__ import annotations

import numpy as np

from .parallel_env import DObsParallelEnv
from .options import RENDER_MODES, HeteroMASOptions

__all__ = ["HeteroMASEnv", "NE1_ACTION_BOUND", "Disagreement"]

#: Per-agent input bounds of hetero_mas_v0: 1.5 x the largest |u_i| of the reference
#: (rendezvous LQR on the own estimate) policy over 20 seeded episodes of the default
#: initial-state distribution at the default control period, rounded up to a multiple of 5
#: (measured 1.26, 1.85, 5.78, 5.64, 7.16).
NE1_ACTION_BOUND = (5.0, 5.0, 10.0, 10.0, 15.0)


class HeteroMASEnv(DObsParallelEnv):
    """Rendezvous of heterogeneous agents with distributed estimation (NE1 agents; PettingZoo ``ParallelEnv``).

    ## Description

    The five agents of the paper's Section NE1 (eq. HMAS): two integrators,
    two double integrators and a triple integrator, ``x = col(breve x_i)``
    (``n = 9``). Agent ``controller_i`` controls its own scalar input ``u_i``
    and is co-located with observer node ``i``, which measures the agent's
    position ``y_i = breve C_i breve x_i``, knows only ``u_i`` and runs the
    MAS form of the distributed observer (eq. obidynamicMAS with NE1's
    ``breve L_i`` and adaptive-law constants) over the ring O-O graph
    0-1-2-3-4-0; by Theorem HMASthm every agent reconstructs the state of
    *all* agents. Task: **rendezvous** -- the positions (first state component
    of each agent) agree while velocities/accelerations settle. The reference
    policy applies the rendezvous LQR gain to the agent's own estimate,
    ``u_i = K_i xhat_i`` (:func:`dobs_envs.scenarios.mas_tasks.rendezvous_lqr`,
    ``rho = 1e-3`` keeps ``A + B K`` Hurwitz so Theorem lfthm applies; the
    meeting point drifts slowly, time constant ~21 s, towards the origin).

    ## Action Space

    Agent ``controller_i``: ``Box(-b_i, b_i, (1,), float32)``,
    ``b = (5, 5, 10, 10, 15)`` (:data:`NE1_ACTION_BOUND`); clipped; NaN/inf,
    wrong shapes and unknown agents raise ``ValueError``.

    ## Observation Space

    Agent ``controller_i`` (node ``i``): ``Box(-inf, inf, (30,), float32)``::

        [0:1]    y_i        its own position
        [1:10]   xhat_i     its estimate of all agents' states
        [10:28]  neighbours the estimates of its two ring neighbours
        [28:30]  mask       1 per real neighbour slot

    ``observation="full"`` adds the privileged ``x``, all estimates, gains and
    ``t``. ``state()``: ``(x, xhat_0..xhat_4)`` (54 values).

    ## Rewards

    Shared ``-(x'Qx + sum_i r u_i^2) * T`` with the rendezvous weight
    ``Q = S^T Pi S + 0.1 (I - S^T S)`` (``x'Qx = sum_i (p_i - pbar)^2 + 0.1 ||rest||^2``,
    :func:`~dobs_envs.scenarios.mas_tasks.rendezvous_cost`) and ``r = 1``.
    ``reward="log"`` replaces the stage cost ``c`` by ``log(1 + c / c0)``, ``c0 =
    lambda_max(Q) * cost_scale^2`` (``cost_scale=0.1``), and ``reward="sqrt"`` by
    ``sqrt(c)``, so that steady-state errors weigh more against the transient
    (benchmarks evaluate on the quadratic cost).

    ## Starting State

    ``x(0) = x0 + U[-1, 1]^9`` around NE1's ``x0 = (-1, -2, -3, -4, 5, 4, 3, 2, 1)``;
    ``xhat_i(0) = 0``, ``gamma_i(0) = gamma_is(0) = 0.1``.

    ## Episode End

    Terminated when ``||x|| > state_bound`` (1e3) or the simulated state is not
    finite (as ``tracking_v0``: ``termination_reason`` 2, cleaned terminal
    observations); truncated after ``max_cycles``
    (default 600 control steps = NE1's 30 s).
    On termination the reward of that step also charges the cost of staying on the
    bound for the rest of the horizon, ``lambda_max(Q) * state_bound^2 * period`` per
    remaining control step (``termination_penalty=False`` disables it), so ending an
    episode early by diverging is never better than staying.

    ## Info

    Per agent: ``estimation_error`` of its node, ``tracking_error`` (``||x||``),
    ``disagreement`` (``||p - pbar 1||``, the rendezvous error, also plotted by
    ``render()``), ``gamma``, ``gamma_s``, ``termination_reason`` (integer code, as
    ``tracking_v0``).

    ## Arguments

    ``hetero_mas_v0.parallel_env(scenario=None, dt=1e-3, substeps=50, max_cycles=None,
    horizon=None, observation="local", obs_dtype="float32", Q=None, R=None,
    action_bound=None, init_noise=None, state_bound=1e3, termination_penalty=True,
    reward="quadratic", cost_scale=0.1, render_mode=None, disturbance="exosystem",
    disturbance_amplitude=2.0, normalized_actions=False, padded_observations=False, faults=None, q_rest=0.1,
    r=1.0, rho=1e-3)``
    (:class:`~dobs_envs.envs.options.HeteroMASOptions`; the disturbance options do not
    apply: NE1 has no unknown input); ``q_rest``, ``r``, ``rho`` parametrise the task
    (:func:`~dobs_envs.scenarios.mas_tasks.rendezvous_scenario`); ``scenario=``
    takes any multi-agent Scenario (``mas_agents``). ``normalized_actions`` /
    ``padded_observations``: identical agent spaces for parameter sharing (see ``tracking_v0``).

    ``faults=`` (communication faults and sensor noise) as in ``tracking_v0``.

    ## Version History

    * v0: initial release.
    * v0: ``padded_observations=True`` pads and adds ``obs_mask`` only where the agents'
      observation widths differ (before: always, doubling the width; the default spaces are
      unchanged).
    * v0: option ``faults`` added (default None: unchanged).
    """

    metadata = {"render_modes": list(RENDER_MODES), "name": "hetero_mas_v0", "is_parallelizable": True, "render_fps": 20}
    Options = HeteroMASOptions
    TASK_ERROR_LABEL = r"$\|p - \bar p\,1\|$"
    _TASK_KEYS = ("q_rest", "r", "rho")

    @classmethod
    def _default_scenario(cls, opts):
        from ..scenarios.mas_tasks import rendezvous_scenario

        return rendezvous_scenario(q_rest=opts.q_rest, r=opts.r, rho=opts.rho)

    @classmethod
    def _check_scenario(cls, sc, opts, given):
        if sc.mas_agents is None:
            raise ValueError(f"hetero_mas_v0 needs a multi-agent scenario (Scenario.mas_agents); {sc.name!r} is not one")
        if opts.scenario is not None and any(k in given for k in cls._TASK_KEYS):
            raise ValueError("q_rest, r and rho parametrise the default rendezvous scenario; they cannot be combined with scenario=")

    @classmethod
    def _default_action_bound(cls, sc, opts, given):
        if opts.scenario is None and all(k not in given for k in cls._TASK_KEYS):
            return np.array(NE1_ACTION_BOUND)
        return super()._default_action_bound(sc, opts, given)

    @classmethod
    def _task_error(cls, sc, opts):
        from ..scenarios.mas_tasks import position_indices

        return Disagreement(sc.metadata.get("positions", position_indices(sc))), "disagreement"


class Disagreement:
    """Rendezvous error ``||p - pbar 1||`` of the positions ``p = x[:, positions]``, per copy ``(B,)``."""

    def __init__(self, positions):
        self.positions = np.asarray(positions, dtype=np.intp)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        p = x[:, self.positions]
        d = p - p.mean(axis=1, keepdims=True)
        return np.sqrt(np.einsum("bk,bk->b", d, d))
