"""``random_network_v0``: a seeded random system from :mod:`dobs_envs.scenarios.random`."""
from __future__ import annotations

from .parallel_env import DObsParallelEnv
from .options import RENDER_MODES, RandomNetworkOptions

__all__ = ["RandomNetworkEnv"]


class RandomNetworkEnv(DObsParallelEnv):
    """Distributed observer-based control of a seeded random system (PettingZoo ``ParallelEnv``).

    ## Description

    The system is drawn once, at construction, by the scenario layer's
    seeded generator (:mod:`dobs_envs.scenarios.random`; same options and
    ``system_seed`` give the bit-identical system; every draw is verified
    against Assumptions 3-6 and the observer design is built):

    * ``kind="plant"`` (default, :func:`~dobs_envs.scenarios.random.random_plant_scenario`):
      ``n_states`` (6) states, ``A = Q M Q^T`` with ``M`` in real Schur form whose
      modes are drawn as: with probability 0.3 a complex pair
      ``a +- ib``, ``a ~ U[-1, 0.5]``, ``b ~ U[0.2, 2]``; else a real eigenvalue,
      exactly 0 with probability 0.25, else ``~ U[-1, 0.5]`` (at least one mode
      with ``Re >= 0``); ``N(0, 0.5^2)`` couplings above the diagonal blocks;
      ``Q`` Haar orthogonal. ``n_controllers`` (3) channels ``B^k`` with one
      ``N(0, 1)`` column each; ``n_observers`` (4) nodes, each measuring a
      random subset of the states (the subsets cover all states, so Assumption
      6 holds) and knowing 1-2 random channels; the C-O link of channel ``k``
      goes to a node that knows it. With ``unknown_input=True`` a matched
      ``B_v = B X_v`` (``X_v`` ``m x 2`` Gaussian) driven by a harmonic exosystem
      ``w ~ U[0.2, 1]`` rad/s, ``v0 ~ U[-1, 1]^2``. Reference controller:
      ``"feedback"`` ``K = -B^T X`` from the ARE shifted by 0.2 (NE2's), or with an
      unknown input ``"adaptive_sliding_mode"`` with NE3's constants.
    * ``kind="mas"`` (:func:`~dobs_envs.scenarios.random.random_mas_scenario`):
      ``n_agents`` (4) agents in companion form with state dimensions
      ``U{1..3}``, one input and one output each, spectra as above, MAS observer
      (eq. obidynamicMAS); agent ``i`` controls its own input; ``"feedback"``.

    The O-O graph is ``graph`` (``"random"``: connected Erdos-Renyi with
    ``edge_prob`` 0.3, seeded from the same stream; or ``"ring"``, ``"path"``,
    ``"star"``, ``"complete"``). ``generator_kwargs`` passes any other generator
    argument (e.g. ``{"measurement": "gaussian"}``).

    ## Action Space

    Agent ``controller_k``: ``Box(-b, b, (m_k,), float32)``; by default the
    bounds are *calibrated* (``action_bound="auto"``): twice the largest
    ``|u_j|`` the reference controller uses over 8 initial states of the
    default distribution (first 10 s, fixed calibration seed), at least 1.
    Clipped; NaN/inf, wrong shapes, unknown agents raise ``ValueError``.

    ## Observation Space

    As every dobs_envs env (``observation="local"``): ``[y_i, xhat_i,
    neighbours (D n), mask (D), r^k if tracking]`` with ``i = links[k]`` and
    ``D`` the largest number of O-O neighbours; the slices are given by
    ``env.observation_layout(agent)``.

    ## Rewards

    ``-(e'Qe + u'Ru) * T`` with ``e = x`` (``x - x_r`` for a tracking
    controller), ``Q = I``, ``R = I`` unless given.
    ``reward="log"`` replaces the stage cost ``c`` by ``log(1 + c / c0)``, ``c0 =
    lambda_max(Q) * cost_scale^2`` (``cost_scale=0.1``), and ``reward="sqrt"`` by
    ``sqrt(c)``, so that steady-state errors weigh more against the transient
    (benchmarks evaluate on the quadratic cost).

    ## Starting State

    ``x(0) ~ U[-1, 1]^n`` (the generator's ``x0_scale``; ``init_noise=a`` instead
    gives ``x0 + U[-a, a]^n`` around the generator's drawn ``x0``); ``z_i(0) = 0``,
    ``gamma_i(0) = gamma_is(0) = 0.1``.

    ## Episode End

    Terminated when ``||x|| > state_bound`` (1e3) or the simulated state is not
    finite (as ``tracking_v0``: ``termination_reason`` 2 ``non_finite_state``, cleaned
    terminal observations); truncated after ``max_cycles`` (default 400 control steps = 20 s).
    Infos as ``tracking_v0`` (numeric, the same keys from ``reset`` on).
    On termination the reward of that step also charges the cost of staying on the
    bound for the rest of the horizon, ``lambda_max(Q) * state_bound^2 * period`` per
    remaining control step (``termination_penalty=False`` disables it), so ending an
    episode early by diverging is never better than staying.

    ## Arguments

    ``random_network_v0.parallel_env(dt=1e-3, substeps=50, max_cycles=None, horizon=None,
    observation="local", obs_dtype="float32", Q=None, R=None, action_bound=None,
    init_noise=None, state_bound=1e3, termination_penalty=True, reward="quadratic",
    cost_scale=0.1, render_mode=None, disturbance="exosystem", disturbance_amplitude=2.0,
    normalized_actions=False, padded_observations=False, faults=None, kind="plant", system_seed=0, n_states=6, n_controllers=3, n_observers=4, n_agents=4,
    graph="random", edge_prob=0.3, unknown_input=False, controller=None,
    generator_kwargs=None)`` (:class:`~dobs_envs.envs.options.RandomNetworkOptions`;
    common options as ``tracking_v0``, the disturbance options with ``unknown_input=True``;
    ``scenario=`` is not accepted here: use ``dobs_envs.envs.make_parallel_env(scenario)``).
    The agents' observation widths differ (their nodes measure different outputs; with
    ``generator_kwargs={"inputs_per_controller": (1, 2)}`` their channel widths too):
    ``normalized_actions=True, padded_observations=True`` give them identical spaces for a
    shared policy (see ``tracking_v0``).

    ``faults=`` (communication faults and sensor noise) as in ``tracking_v0``.

    ## Version History

    * v0: initial release.
    * v0: ``padded_observations=True`` pads and adds ``obs_mask`` only where the agents'
      observation widths differ (before: always, doubling the width; the default spaces are
      unchanged).
    * v0: option ``faults`` added (default None: unchanged).
    """

    metadata = {"render_modes": list(RENDER_MODES), "name": "random_network_v0", "is_parallelizable": True, "render_fps": 20}
    Options = RandomNetworkOptions
    REJECT_OPTIONS = ("scenario",)

    @classmethod
    def _default_scenario(cls, opts):
        from ..scenarios.random import random_mas_scenario, random_plant_scenario

        gk = dict(opts.generator_kwargs or {})
        common = dict(graph=opts.graph, edge_prob=opts.edge_prob, **gk)
        if opts.controller is not None:
            common["controller"] = opts.controller
        if opts.kind == "plant":
            return random_plant_scenario(opts.n_states, opts.n_controllers, opts.n_observers,
                                         seed=opts.system_seed, unknown_input=opts.unknown_input, **common)
        return random_mas_scenario(opts.n_agents, seed=opts.system_seed, **common)

    @classmethod
    def make_core(cls, num_envs: int = 1, *, threads: int | None = 1, **kwargs):
        kind = kwargs.get("kind", "plant")
        wrong = ("n_agents",) if kind == "plant" else ("n_states", "n_controllers", "n_observers", "unknown_input")
        bad = [k for k in wrong if k in kwargs]
        if bad:
            raise TypeError(f"{bad} only apply to kind='mas'" if kind == "plant"
                            else f"{bad} only apply to kind='plant' (kind='mas' takes n_agents)")
        return super().make_core(num_envs, threads=threads, **kwargs)
