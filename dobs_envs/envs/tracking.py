"""``tracking_v0``: the NE2 plant tracking the reference model (refxdy) through distributed observers."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .parallel_env import DObsParallelEnv
from .options import RENDER_MODES, EnvOptions

__all__ = ["TrackingEnv", "TrackingLossyEnv", "TrackingLossyOptions", "TRACKING_LOSSY_FAULTS", "NE2_ACTION_BOUND"]

#: Per-input bounds of tracking_v0 on NE2: 1.5 x the largest |u^k| the reference
#: policy used over 20 seeded episodes of the default initial-state distribution
#: (measured 9.3, 18.7, 14.9, 80.9, 5.4 at the default control period 0.05 s;
#: 8.4, 16.3, 14.1, 78.9, 4.6 over 4 seeds at control period 1e-3 s), rounded up to a multiple of 5.
NE2_ACTION_BOUND = (15.0, 30.0, 25.0, 125.0, 10.0)


class TrackingEnv(DObsParallelEnv):
    """Distributed observer-based reference tracking of the NE2 plant (PettingZoo ``ParallelEnv``).

    ## Description

    The plant of the paper's Section NE2 (eq. LTIsys with ``v = 0``; ``n = 9``
    states) is driven by five controller nodes (the agents ``controller_0`` ...
    ``controller_4``), each choosing the scalar input ``u^k`` of its channel
    ``B^k`` (eq. Busplit). Six observer nodes measure ``y_i = C_i x`` (eq.
    localmeasure; ``C_i`` picks states 1, 3, 5, 7, 2, 4), receive the inputs of
    the channels they know (``u_i = u^i``, ``u_6 = u^5``) and run the paper's
    distributed observer (eqs. obidynamic, barEFGB, H_idefine, gammaiis) over a
    ring O-O graph; controller ``k`` receives the estimate ``xhat_k`` of
    observer node ``k`` over its C-O link. The team must make the plant track
    the reference model (eq. refxdy) ``x_r' = (A + B K) x_r + B r`` with
    ``r^k(t) = sin(t + k)`` (``k = 1..5``) and ``K^k = -(B^k)^T X`` from the
    shifted ARE of NE2. The paper's solution (Theorem reftrackthm) is
    ``u^k = K^k xhat_k + r^k`` (:class:`baselines.policies.SeparationPolicy`).

    ## Action Space

    Agent ``controller_k``: ``Box(-b_k, b_k, (1,), float32)`` with
    ``b = (15, 30, 25, 125, 10)`` (:data:`NE2_ACTION_BOUND`, 1.5x the largest
    input the reference policy needs under the default initial-state
    distribution; ``action_bound=`` overrides). Out-of-range actions are
    **clipped** to the box (the clipped value is simulated and enters the
    reward); NaN/inf, wrong shapes and unknown agents raise ``ValueError``
    naming the agent. Any float dtype is accepted and used in float64.

    ## Observation Space

    Agent ``controller_k`` (linked observer node ``i = k``) observes a flat
    ``Box(-inf, inf, (31,), float32)`` (``observation="local"``)::

        [0:1]    y_i        its node's measured output (eq. localmeasure)
        [1:10]   xhat_i     its node's estimate (eq. hatxieq)
        [10:28]  neighbours the estimates of node i's two ring neighbours (sorted by index)
        [28:30]  mask       1 per real neighbour slot (0 = padding; the ring has none)
        [30:31]  r^k        its reference command sin(t + k + 1) (0-based k)

    ``env.observation_layout(agent)`` returns these slices. ``observation="full"``
    appends the privileged ``x``, ``x_r``, all estimates, ``gamma``, ``gamma_s`` and
    ``t`` (debugging); a sequence of component names selects any subset
    (:mod:`dobs_envs.envs.observation`). ``state()`` returns
    ``(x, x_r, xhat_0..xhat_5)`` (72 values, ``env.state_layout()``).

    ## Rewards

    Shared team reward ``-(e'Qe + sum_k u_k' R_k u_k) * T`` per control step with
    ``e = x - x_r`` evaluated at the end of the step, ``u`` the applied (clipped)
    input, ``T`` the control period; ``Q = I_9``, ``R = I_5`` by default
    (``Q=``, ``R=`` options).
    ``reward="log"`` replaces the stage cost ``c`` by ``log(1 + c / c0)``, ``c0 =
    lambda_max(Q) * cost_scale^2`` (``cost_scale=0.1``), and ``reward="sqrt"`` by
    ``sqrt(c)``, so that steady-state errors weigh more against the transient
    (benchmarks evaluate on the quadratic cost).

    ## Starting State

    ``x(0) = x0 + U[-1, 1]^9`` with the paper's ``x0 = (-1, -2, -3, -4, 5, 4, 3, 2, 1)``
    (``init_noise=`` sets the half-width, 0 gives the paper's run);
    ``x_r(0) = 0``, observer states ``z_i(0) = 0`` and ``gamma_i(0) = gamma_is(0) = 0.1``
    as in the paper. ``reset(options={"x0": ...})`` sets an exact initial state.

    ## Episode End

    Terminated when ``||x|| > state_bound`` (1e3) or any simulated quantity
    (``x``, ``x_r``, the observer states ``z``, ``gamma``, ``gamma_s``, ``v``) is
    not finite (``info[agent]["termination_reason"]`` = 1 ``state_bound_exceeded`` /
    2 ``non_finite_state``; a finite ``x`` beyond the bound is always reason 1). The
    simulation stays finite from every state inside the bound with any inputs inside the
    action bound: ``state_bound`` may not exceed the system's limit (``core.state_bound_limit``,
    computed from the system, ``dt`` and the action bound by
    :func:`dobs_envs.envs.options.state_bound_limit`; about 2.7e5 here, a larger bound raises
    ``StateBoundError``), and Euler steps are shortened where the adaptive gains would make them
    unstable (:mod:`dobs_envs.sim.period_kernel` "Stable steps"), so reason 2 means the state was
    already non-finite or absurdly large (e.g. an ``x0`` of 1e308). The terminal step's observations and ``state()`` are
    cleaned (NaN -> 0, +-inf -> +-largest finite value of ``obs_dtype``), a non-finite
    step cost is replaced by the cost of one step on the bound, and ``info`` keeps the
    raw diagnostics (errors and gains may be NaN/inf).
    Truncated after ``max_cycles`` control steps (default 400 = the paper's 20 s
    at the default 0.05 s control period; ``horizon=`` in seconds instead).
    On termination the reward of that step also charges the cost of staying on the
    bound for the rest of the horizon, ``lambda_max(Q) * state_bound^2 * period`` per
    remaining control step (``termination_penalty=False`` disables it), so ending an
    episode early by diverging is never better than staying.

    ## Info

    Per agent, the same numeric keys from ``reset`` on: ``estimation_error``
    ``||xhat_i - x||`` of its linked node, ``tracking_error`` ``||x - x_r||``, that node's
    ``gamma``, ``gamma_s``, and the integer ``termination_reason``: 0 none (the episode goes
    on), 1 state_bound_exceeded, 2 non_finite_state, 3 horizon (truncated after
    ``max_cycles``) (:data:`dobs_envs.envs.env_core.REASONS`).

    ## Arguments

    ``tracking_v0.parallel_env(scenario=None, dt=1e-3, substeps=50, max_cycles=None,
    horizon=None, observation="local", obs_dtype="float32", Q=None, R=None,
    action_bound=None, init_noise=None, state_bound=1e3, termination_penalty=True,
    reward="quadratic", cost_scale=0.1, render_mode=None, disturbance="exosystem",
    disturbance_amplitude=2.0, normalized_actions=False, padded_observations=False, faults=None)``
    (the fields of :class:`~dobs_envs.envs.options.EnvOptions`,
    which validates them; the same keywords for ``gym.make``/``gym.make_vec`` of
    ``dobs_envs/Tracking-v0`` except ``max_cycles``/``horizon``, there
    ``max_episode_steps``).
    ``dt`` is the Euler step of the simulation and ``substeps`` the number of
    Euler steps per control step (inputs held, ZOH): control period
    ``dt * substeps`` = 0.05 s by default; ``substeps=1`` is the paper's
    continuous-time law up to O(dt) (the reference policy then reproduces
    ``dobs_envs.reproduce.simulate(ne2())`` to float round-off).
    ``scenario=`` replaces NE2 by any Scenario with a reference signal.
    ``disturbance``/``disturbance_amplitude`` apply to systems with an unknown input only
    (NE2 has none: other values raise ``ValueError``).
    ``normalized_actions=True`` gives every agent the action space ``Box(-1, 1, (M,), float32)``,
    ``M`` the largest number of input channels of any agent (here 1): entry ``j < m_k`` is
    mapped onto channel ``k``'s bound (``u = a * b``), entries ``j >= m_k`` are ignored
    (the centralised ``gym.make`` view then takes ``Box(-1, 1, (m,))``).
    ``padded_observations=True`` gives every agent the same observation space: where the agents'
    widths differ, the observation ``[o_k, 0...0 | mask]`` (its own observation zero-padded to
    the widest agent's width ``W``, then ``W`` mask entries, 1 = real, 0 = padding; component
    ``"obs_mask"`` of ``observation_layout``); where every agent already has width ``W`` (here:
    31), the observation itself, unpadded and without a mask. Either way the bounds are the same
    for every agent (the union of theirs). Use both when one policy is shared by all agents
    (parameter sharing in SuperSuit, RLlib, BenchMARL MAPPO/IPPO, TorchRL): every agent then
    has identical spaces, which these libraries require, and ``[-1, 1]`` actions suit their
    Gaussian policies. Leave them off for per-agent policies that know their own bounds
    and widths (the defaults are the agents' true spaces).
    ``faults=`` adds communication faults and sensor noise to the observer network (a dict with
    the keys ``oo_period``, ``oo_loss``, ``oo_burst``, ``oo_delay``, ``co_loss``, ``co_delay``,
    ``switching``, ``measurement_noise``, or a :class:`~dobs_envs.sim.faults.Faults`; semantics
    in :mod:`dobs_envs.sim.faults`; ``None``, the default, is the paper's ideal network and runs
    no fault code). Each agent then observes only what reached it: ``y`` with the held
    measurement noise, ``xhat`` the estimate its C-O link delivered (stale when a packet is lost
    or delayed), ``neighbors`` the copies its node holds, and the extra component ``received``
    (``1 + D`` entries: 1 if the C-O packet arrived at this step, then one flag per neighbour
    slot: 1 if that value arrived at this step, 0 if it is held from before); the infos add
    ``co_received`` (bool) and ``oo_received_fraction`` (float)
    (:mod:`dobs_envs.envs.observation`, :func:`dobs_envs.envs.features.fault_rows`). The fault
    processes of a copy are drawn from a seed taken from the environment's generator at reset
    (``reset(seed=...)`` reproduces them). ``tracking_lossy_v0`` is this environment with a
    default fault setting.
    Unknown arguments raise ``TypeError`` listing the valid ones.

    ## Version History

    * v0: initial release.
    * v0: ``padded_observations=True`` pads and adds ``obs_mask`` only where the agents'
      observation widths differ (before: always, doubling the width; the default spaces are
      unchanged).
    * v0: option ``faults`` added (default None: unchanged).
    """

    metadata = {"render_modes": list(RENDER_MODES), "name": "tracking_v0", "is_parallelizable": True, "render_fps": 20}

    @classmethod
    def _default_scenario(cls, opts):
        from ..scenarios.paper import ne2

        return ne2()

    @classmethod
    def _check_scenario(cls, sc, opts, given):
        if sc.reference is None:
            raise ValueError(f"tracking_v0 needs a scenario with a reference signal r (Scenario.reference); {sc.name!r} has none")

    @classmethod
    def _default_action_bound(cls, sc, opts, given):
        if opts.scenario is None:
            return np.array(NE2_ACTION_BOUND)
        return super()._default_action_bound(sc, opts, given)


#: The default fault setting of ``tracking_lossy_v0`` (the ``faults`` keys of :mod:`dobs_envs.sim.faults`).
TRACKING_LOSSY_FAULTS = {"oo_period": 0.01, "oo_loss": 0.1, "co_loss": 0.05, "measurement_noise": 0.01}


@dataclass(frozen=True, eq=False)
class TrackingLossyOptions(EnvOptions):
    """:class:`~dobs_envs.envs.options.EnvOptions` with the default ``faults`` of ``tracking_lossy_v0``
    (:data:`TRACKING_LOSSY_FAULTS`)."""

    faults: Any = field(default_factory=lambda: dict(TRACKING_LOSSY_FAULTS))


class TrackingLossyEnv(TrackingEnv):
    """``tracking_v0`` over a lossy, sampled observer network with noisy sensors (PettingZoo ``ParallelEnv``).

    ## Description

    The task, agents, actions, rewards, starting state and episode end of ``tracking_v0``
    (:class:`TrackingEnv`: NE2 tracking its reference model through the paper's distributed
    observers), with communication faults and sensor noise on by default (``faults=``,
    :mod:`dobs_envs.sim.faults`)::

        faults = {"oo_period": 0.01, "oo_loss": 0.1, "co_loss": 0.05, "measurement_noise": 0.01}

    - ``oo_period = 0.01`` s: the observer nodes exchange estimates every 10 ms (10 Euler steps,
      5 exchanges per control period) and hold the received copies in between: a realistic
      network rate. (Holding them for a whole control period of 0.05 s dominated every other
      fault in a first estimate; 10 ms keeps the task about the faults below.)
    - ``oo_loss = 0.1``: each directed O-O link loses all its packets of a control period with
      probability 0.1 (the receiver keeps the last value it got);
    - ``co_loss = 0.05``: each controller's C-O packet is lost with probability 0.05 per step
      (it then acts on the estimate it held, one step stale or more);
    - ``measurement_noise = 0.01``: Gaussian noise of standard deviation 0.01 on every measured
      output ``y_i``, held over each control period (about 1% of NE2's initial outputs; it enters
      the observers and the agents' ``y``).

    No delays and a fixed ring graph: the paper's Assumption ooconnected holds at every instant,
    so the paper's controller (``baselines.policies.SeparationPolicy``) still tracks, with a
    larger error floor (RMS tracking error over the last 5 s of the 20 s episode: 0.13 here
    against 0.03 in ``tracking_v0``, and 0.49 with ``oo_period = 0.05``; seeds 0 and 1);
    learning policies may exploit the ``received`` mask.

    ## Observation Space

    Agent ``controller_k`` observes ``Box(-inf, inf, (34,), float32)``: the 31 entries of
    ``tracking_v0`` (``y_i`` with its noise, the estimate its C-O link delivered, the copies its
    node holds of its two neighbours' estimates, the mask, ``r^k``), then ``received`` (3 entries:
    1 if the C-O packet arrived at this step, then per neighbour 1 if its value arrived at this
    step, 0 if held). ``env.observation_layout(agent)`` returns the slices.

    ## Info

    The keys of ``tracking_v0`` plus ``co_received`` (bool) and ``oo_received_fraction`` (float)
    per agent (``(K,)`` arrays in the centralised views).

    ## Arguments

    ``tracking_lossy_v0.parallel_env(scenario=None, dt=1e-3, substeps=50, max_cycles=None,
    horizon=None, observation="local", obs_dtype="float32", Q=None, R=None,
    action_bound=None, init_noise=None, state_bound=1e3, termination_penalty=True,
    reward="quadratic", cost_scale=0.1, render_mode=None, disturbance="exosystem",
    disturbance_amplitude=2.0, normalized_actions=False, padded_observations=False,
    faults={"oo_period": 0.01, "oo_loss": 0.1, "co_loss": 0.05, "measurement_noise": 0.01})``
    (:class:`TrackingLossyOptions`; the options of ``tracking_v0``; the same keywords for
    ``gym.make``/``gym.make_vec`` of ``dobs_envs/TrackingLossy-v0`` except
    ``max_cycles``/``horizon``). ``faults=`` replaces the whole fault setting (a dict or a
    :class:`~dobs_envs.sim.faults.Faults`; ``faults=None`` gives ``tracking_v0``). The fault
    processes are drawn per episode from the environment's generator: ``reset(seed=...)``
    reproduces them.

    ## Version History

    * v0: initial release.
    """

    Options = TrackingLossyOptions
    metadata = {**TrackingEnv.metadata, "name": "tracking_lossy_v0"}
