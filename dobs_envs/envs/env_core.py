"""The batched environment core: ``B`` copies of one scenario advanced together.

Every adapter -- the PettingZoo ``ParallelEnv`` and its AEC form
(:mod:`dobs_envs.envs.parallel_env`), the centralised Gymnasium ``Env``
(:mod:`dobs_envs.envs.centralized`), the Gymnasium ``VectorEnv``
(:mod:`dobs_envs.envs.vector`) and the SB3 ``VecEnv`` (``agents.vecenv.batched_core``) -- drives an
:class:`EnvCore` through this public API only.

Conventions: batch dimension first; ``K`` agents (controller nodes), ``N`` observer
nodes, ``m`` inputs, ``D`` the widest agent observation.

=================================  ==========================================================
``reset(indices, seeds, options)``  reset all copies or a subset, per-copy seeds and options
``advance(u)``                      one control step of every copy; ``u (B, m)``; returns
                                    :class:`StepResult` ``(reward, terminated, truncated, reason)``
``observations``                    ``(B, K, D)`` padded observations (``obs_widths[k]`` true widths;
                                    ``padded_observations``: every agent ``D`` wide, mask included where widths differ)
``agent_inputs(a)``                 the agents' actions concatenated ``(B, sum(agent_action_widths))``
                                    -> inputs ``(B, m)`` (``normalized_actions``: gathered from the
                                    padded actions and scaled by ``action_scale``)
``estimation_errors``               ``(B, N)`` ``||xhat_i - x||``
``tracking_errors``                 ``(B,)`` ``||x - x_r||`` (or ``||x||``)
``task_errors()``                   ``(B,)`` the task's error (tracking error, or e.g. the
                                    rendezvous disagreement)
``applied_inputs``                  ``(B, m)`` inputs held over the last step (after clipping)
``gamma``, ``gamma_s``              ``(B, N)`` adaptive gains of eq. (gammaiis)
``states()``                        ``(B, state_dim)`` global state (x, x_r, estimates, v)
``sim_state`` / ``set_sim_state``   snapshot of / overwrite the simulation state
=================================  ==========================================================

Reason codes (``StepResult.reason``, int8; :data:`REASONS` maps them to their names). Every
adapter reports the code as the integer info ``termination_reason``, present from ``reset`` on
(0 there and on every step that does not end the episode):

====  ========================  ============================================================
code  name                      meaning
====  ========================  ============================================================
0     ``none``                  the episode goes on (or was cut by an outer time limit,
                                e.g. ``gym.make``'s ``TimeLimit``)
1     ``state_bound_exceeded``  terminated: ``||x|| > state_bound``, every entry of x finite
                                (takes precedence over code 2)
2     ``non_finite_state``      terminated: some entry of x, x_r, z, gamma, gamma_s, v is NaN/inf
                                (and not code 1)
3     ``horizon``               truncated: ``max_cycles`` control steps
====  ========================  ============================================================

Buffers returned by the API (``observations``, the :class:`StepResult` arrays, the error
arrays) are read-only views of preallocated arrays that the next ``reset``/``advance``
overwrites; copy them to keep them.
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping
from functools import partial
from typing import Callable, NamedTuple

import numpy as np

from ..linalg.validation import NUMERIC_KINDS, as_array, as_symmetric, check_seed
from ..sim import SimParams, SimState
from ..packing import pack
from ..sim.fault_kernel import period_draws_compiled
from ..sim.fault_state import NO_FAULT, fault_args, init_fault_state
from ..sim.kernel_args import StateArrays
from .calibration import auto_action_bound
from .distributions import N_RANDOM_TERMS, ResetDistribution
from .features import fault_features, pack_static, write_features
from .observation import FeatureLayout, resolve_components
from .options import EnvOptions, check_state_bound, state_bound_limit
from ..sim.period_kernel import TILE
from .step_kernel import (REASON_HORIZON, REASON_NON_FINITE, REASON_NONE, REASON_STATE_BOUND, StepConsts,
                          advance_range, first_non_finite)


#: reward shape -> code passed to the compiled step (0 quadratic, 1 log, 2 sqrt)
REWARD_CODES = {"quadratic": 0, "log": 1, "sqrt": 2}

__all__ = ["EnvCore", "StepResult", "REASONS", "resolve_scenario"]

#: reason code (the integer ``info["termination_reason"]`` of every adapter) -> name
REASONS = {REASON_NONE: "none", REASON_STATE_BOUND: "state_bound_exceeded", REASON_NON_FINITE: "non_finite_state",
           REASON_HORIZON: "horizon"}


class StepResult(NamedTuple):
    """Outputs of :meth:`EnvCore.advance`, each ``(B,)`` (read-only views, overwritten by the next step)."""

    reward: np.ndarray  # float64
    terminated: np.ndarray  # bool
    truncated: np.ndarray  # bool
    reason: np.ndarray  # int8, see REASONS


def resolve_scenario(sc):
    """The ``scenario`` option as given (a Scenario, or None), or the Scenario read from a YAML/JSON file path
    (:func:`dobs_envs.scenarios.io.load_scenario`)."""
    if isinstance(sc, (str, os.PathLike)):
        from ..scenarios.io import load_scenario

        return load_scenario(sc)
    return sc


def _ranges(B: int, threads: int) -> tuple:
    """``threads`` (at most) contiguous ranges of copies, each a whole number of tiles but the last."""
    tiles = -(-B // TILE)
    k = max(1, min(threads, tiles))
    bounds = [min(B, (tiles * j // k) * TILE) for j in range(k + 1)]
    bounds[-1] = B
    return tuple((lo, hi) for lo, hi in zip(bounds[:-1], bounds[1:]) if hi > lo)


def _ro(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


class EnvCore:
    """``num_envs`` copies of one scenario (see module docstring).

    Parameters
    ----------
    scenario : Scenario (or YAML/JSON path)
    options : EnvOptions (validated; ``options.scenario`` is ignored here)
    num_envs : int, number of copies ``B``
    default_action_bound : used when ``options.action_bound`` is None (a number, ``(m,)``
        or ``"auto"``; None: ``"auto"``)
    task_error : optional ``x (B, n) -> (B,)`` task error (default: the tracking error)
    task_error_key : info key of ``task_error`` (e.g. ``"disagreement"``)
    threads : threads advancing disjoint ranges of at least :data:`~dobs_envs.sim.period_kernel.TILE` copies
        concurrently (the compiled step releases the GIL); None: one per CPU core, 1: serial.
        Results do not depend on it (every copy's arithmetic is independent of the chunking).
    env_name : the environment named in errors (a :class:`~dobs_envs.envs.options.StateBoundError` when
        ``options.state_bound`` exceeds :attr:`state_bound_limit`); default: the scenario's name

    Raises the design layer's :class:`~dobs_envs.assumptions.AssumptionError` when the
    system does not satisfy the paper's assumptions, ``ValueError`` naming the option
    for options that do not fit the system.
    """

    def __init__(self, scenario, options: EnvOptions, num_envs: int = 1, *, default_action_bound=None,
                 task_error: Callable | None = None, task_error_key: str | None = None, threads: int | None = 1,
                 env_name: str | None = None):
        from ..scenarios.scenario import Scenario

        sc = resolve_scenario(scenario)
        if not isinstance(sc, Scenario):
            raise TypeError(f"scenario must be a Scenario or a path to a YAML/JSON scenario file, "
                            f"got {type(sc).__name__}")
        if not isinstance(options, EnvOptions):
            raise TypeError(f"options must be an EnvOptions, got {type(options).__name__}")
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        o = options
        self.scenario, self.options, self.num_envs = sc, o, int(num_envs)
        if threads is None:
            threads = os.cpu_count() or 1
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
            raise ValueError(f"threads must be None or a positive integer, got {threads!r}")
        #: ranges of copies advanced concurrently (aligned to tiles; one range: serial)
        self.ranges = _ranges(self.num_envs, int(threads))
        self._pool = None
        self.task_error_key = task_error_key
        self._task_error = task_error
        # --- timing -----------------------------------------------------------------------
        self.dt, self.substeps = o.dt, o.substeps
        self.control_period = self.dt * self.substeps
        if o.max_cycles is not None:
            mc = o.max_cycles
        else:
            hz = sc.t_end if o.horizon is None else o.horizon
            mc = None if math.isinf(hz) else max(1, int(round(float(hz) / self.control_period)))
        self._max_cycles = mc
        #: horizon charged by the termination penalty: the truncation horizon, or (no truncation,
        #: e.g. under gym's TimeLimit) the scenario's t_end in control steps
        self.penalty_cycles = mc if mc is not None else max(1, int(round(sc.t_end / self.control_period)))
        # --- unknown input --------------------------------------------------------------------
        m_v = sc.B_v.shape[1]
        self.disturbance, self.disturbance_amplitude = o.disturbance, o.disturbance_amplitude
        if m_v == 0:
            if o.disturbance not in ("none", "exosystem") or o.disturbance_amplitude != 2.0:
                raise ValueError("disturbance options need a system with an unknown input (Scenario.B_v)")
            self.disturbance = "none"
        self.init_noise = o.init_noise
        self.distribution = ResetDistribution(sc, o.init_noise, self.disturbance, self.disturbance_amplitude)
        # --- simulation parameters (the design raises AssumptionError here) --------------------
        self.params = p = SimParams.from_design(
            sc.design, phi=sc.phi, phi_s=sc.phi_s, sigma=sc.sigma, sigma_s=sc.sigma_s, dt=self.dt,
            substeps=self.substeps, exosystem=sc.exosystem if self.disturbance == "exosystem" else None,
            K_ref=sc.K if sc.reference is not None else None)
        n, N, m = p.n_states, p.n_nodes, p.n_inputs
        self.n_states, self.n_nodes, self.n_inputs, self.n_unknown = n, N, m, m_v
        # --- communication faults (issue 23; None: no fault code runs) -----------------------------
        #: the ``faults`` option (a :class:`~dobs_envs.sim.faults.Faults`) or None
        self.faults = o.faults
        #: its constants for this system (:func:`~dobs_envs.sim.fault_state.fault_args`; ValueError naming
        #: ``faults: oo_period`` / ``faults: switching`` where they do not fit ``dt`` or the network)
        self._fa = fault_args(o.faults, p) if o.faults is not None else None
        self.has_reference = sc.reference is not None
        # --- agents and actions ---------------------------------------------------------------
        self.agents = tuple(f"controller_{k}" for k in range(sc.n_controllers))
        self.n_agents = len(self.agents)
        self.links = tuple(sc.links)
        self.channel_slices = tuple(sc.channel_slices)
        self.action_widths = np.array([s.stop - s.start for s in self.channel_slices], dtype=np.intp)
        bound = o.action_bound if o.action_bound is not None else default_action_bound
        if bound is None or (isinstance(bound, str) and bound == "auto"):
            bound = auto_action_bound(sc, p, self.distribution, self._max_cycles)
        bound = np.asarray(bound, dtype=np.float64)
        if bound.ndim == 0:
            bound = np.full(m, float(bound))
        if bound.shape != (m,) or not np.all(np.isfinite(bound)) or np.any(bound <= 0):
            raise ValueError(f"action_bound must be a positive finite scalar or have shape ({m},) (one per input "
                             f"component), got {o.action_bound!r}")
        self.action_bound = _ro(bound)
        #: the largest state_bound with a finite simulation shown for these inputs (options.state_bound_limit)
        self.state_bound_limit = state_bound_limit(p, sc.gamma0, bound)
        check_state_bound(o.state_bound, self.state_bound_limit, env_name or f"scenario {sc.name!r}")
        #: option normalized_actions: agents act in [-1, 1]^M (M = max channel width, extra entries ignored)
        self.normalized_actions = o.normalized_actions
        M = int(self.action_widths.max())
        #: width of each agent's action (normalized_actions: the common width M)
        self.agent_action_widths = _ro(np.full(self.n_agents, M, dtype=np.intp) if o.normalized_actions
                                       else self.action_widths.copy())
        starts = np.concatenate([[0], np.cumsum(self.agent_action_widths)[:-1]])
        #: (m,) position of input j in the agents' actions concatenated (agent-major)
        self.action_gather = _ro(np.concatenate([starts[k] + np.arange(s.stop - s.start)
                                                 for k, s in enumerate(self.channel_slices)]).astype(np.intp))
        #: (m,) action unit -> input: the bound (normalized_actions) or 1
        self.action_scale = _ro(bound.copy() if o.normalized_actions else np.ones(m))
        # --- observations -------------------------------------------------------------------
        self.obs_dtype = np.dtype(o.obs_dtype)
        comps = resolve_components(o.observation, has_reference=self.has_reference, has_unknown_input=m_v > 0,
                                   has_faults=self.faults is not None)
        p_i = [c.shape[0] for c in sc.C]
        #: option padded_observations: identical agent spaces (padding and a 0/1 mask where widths differ)
        self.padded_observations = o.padded_observations
        self.layout = L = FeatureLayout(p_i, n, m, m_v, [sc.graph.neighbors(i) for i in range(N)], self.links,
                                        self.channel_slices, comps, padded=o.padded_observations,
                                        fault_links=None if self._fa is None else (self._fa.sender, self._fa.receiver))
        self.obs_widths, self.obs_dim = _ro(L.widths), L.obs_dim
        self._state_index, self.state_layout = L.state_index(self.has_reference)
        self.state_dim = int(self._state_index.size)
        # --- reward -------------------------------------------------------------------------
        self.Q = _ro(self._weight(o.Q, sc.Q, n, "Q", definite=False))
        self.R = _ro(self._weight(o.R, sc.R, m, "R", definite=True))
        self.state_bound, self.termination_penalty = o.state_bound, o.termination_penalty
        self.reward_kind, self.cost_scale = o.reward, o.cost_scale
        # Cost of sitting on the bound for one control step: lambda_max(Q) * state_bound^2 * T
        # (charged on termination for every remaining step: diverging early never pays).
        lam_q = float(np.linalg.eigvalsh(0.5 * (self.Q + self.Q.T))[-1])
        self._log_c0 = max(lam_q, np.finfo(float).tiny) * self.cost_scale ** 2
        self.bound_step_cost = self._shaped(lam_q * self.state_bound ** 2) * self.control_period
        # --- buffers and kernel arguments -----------------------------------------------------------
        self._alloc(self.num_envs)
        ref = np.zeros((3, m))
        if self.has_reference:
            ref[0], ref[1], ref[2] = sc.reference.amplitude, sc.reference.frequency, sc.reference.phase
        self._ka = p.kernel_packed
        self._SF, self._SI = pack_static(p.C, p.G_bar, ref, self.Q, self.R, L.offsets(p_i), L.padded_index, L.size)
        if self.faults is not None:
            self._FP = pack(self._fa)  # (FF, FI): the FaultArgs packed once
            co_nodes = np.asarray(self.links, dtype=np.int64)
            self._fconsts = (co_nodes, L.fault_offsets())
            self._alloc_faults(self.num_envs)
            inc = (self._fa.receiver[None, :] == co_nodes[:, None]).astype(np.float64)  # (K, E): links into node k
            self._oo_incidence = inc / np.maximum(inc.sum(axis=1, keepdims=True), 1.0)
            self._oo_none = inc.sum(axis=1) == 0  # nodes without links: nothing to receive (fraction 1)
        #: the step's constants by name (the compiled step gets them as the plain tuple ``_consts``)
        self._step_consts = StepConsts(
            # both contiguous and read-only whatever the caller's bound was: a writable and a read-only array (or
            # a strided one) are distinct numba types, and each would compile the whole step again (minutes, cold)
            u_lo=_ro(np.ascontiguousarray(-bound)), u_hi=_ro(np.ascontiguousarray(bound)), period=self.control_period,
            state_bound=self.state_bound, bound_step_cost=self.bound_step_cost, log_c0=self._log_c0,
            big_obs=float(np.finfo(self.obs_dtype).max), max_cycles=-1 if mc is None else int(mc),
            penalty_cycles=int(self.penalty_cycles), has_ref=self.has_reference,
            reward_code=REWARD_CODES[self.reward_kind], termination_penalty=self.termination_penalty,
            random_v=self.disturbance == "random")
        self._consts = tuple(self._step_consts)
        self._rngs: list = [None] * self.num_envs
        #: True once some copy has been reset
        self.started = False
        self.history = None  # render history of copy 0 (render_mode set): (t, task error, estimation errors)
        self._record = o.render_mode is not None

    # ------------------------------------------------------------------ construction helpers
    @staticmethod
    def _weight(val, default, size, name, *, definite):
        """The cost weight option ``name`` (``None``: the scenario's), checked as the Scenario checks its
        own: ``Q`` symmetric positive semidefinite, ``R`` symmetric positive definite."""
        if val is None:
            return np.ascontiguousarray(default)
        if size == 1 and np.ndim(val) == 1:
            val = np.reshape(val, (1, 1))
        return np.ascontiguousarray(as_symmetric(val, size, name, definite=definite))

    def _shaped(self, c: float) -> float:
        """Stage cost of the reward: ``c`` (quadratic), ``log(1 + c / c0)`` (log) or ``sqrt(c)`` (sqrt)."""
        if self.reward_kind == "log":
            return math.log1p(c / self._log_c0) if c < math.inf else math.inf
        if self.reward_kind == "sqrt":
            return math.sqrt(c)
        return c

    def _alloc(self, B: int) -> None:
        n, N, m, m_v, L = self.n_states, self.n_nodes, self.n_inputs, self.n_unknown, self.layout
        self._t = np.zeros(B)
        self._x, self._z = np.zeros((B, n)), np.zeros((B, N, n))
        self._g, self._gs = np.zeros((B, N)), np.zeros((B, N))
        self._v, self._xr = np.zeros((B, m_v)), np.zeros((B, n))
        self._W = np.zeros((B, L.size + N + m))
        self._W[:, L.one] = 1.0
        self._obs = np.zeros((B, self.n_agents, self.obs_dim), dtype=self.obs_dtype)
        outf, outb = np.zeros((4, B)), np.zeros((3, B), dtype=bool)
        outb[0] = True  # finite
        self._reason, self._cycles = np.zeros(B, np.int8), np.zeros(B, np.int64)
        self._sig = np.zeros((3, B, m_v, N_RANDOM_TERMS))
        self._state = tuple(StateArrays(t=self._t, x=self._x, z=self._z, gamma=self._g, gamma_s=self._gs, v=self._v,
                                        x_r=self._xr))
        self._outs = (outf, outb, self._reason, self._cycles)
        self._views()

    def _alloc_faults(self, B: int) -> None:
        """The fault state of ``B`` copies (batch first, :class:`~dobs_envs.sim.fault_state.FaultState` as a
        plain tuple, filled at reset) and the received masks ``(co_rx (B, K), oo_rx (B, E))``."""
        p, fa = self.params, self._fa
        fs = init_fault_state(p, fa, np.zeros((B, self.n_states)), np.zeros((B, self.n_nodes, self.n_states)),
                              np.zeros(B, dtype=np.uint64), co_nodes=self._fconsts[0])
        self._fs = tuple(np.array(a, copy=True, order="C") for a in fs)
        self._rx = (np.ones((B, self.n_agents), dtype=bool), np.ones((B, fa.sender.shape[0]), dtype=bool))

    #: attributes that are views of the buffers (rebuilt by _views, not pickled)
    _VIEWS = ("_rew", "_cost", "_err", "_xn", "_fin", "_term", "_trunc", "observations", "estimation_errors",
              "applied_inputs", "tracking_errors", "features", "cycles", "gamma", "gamma_s", "_result", "_all_rows")

    def _views(self) -> None:
        """The named views of the buffers (the kernels write the buffers; these read them)."""
        B, N, L = self.num_envs, self.n_nodes, self.layout
        outf, outb = self._outs[0], self._outs[1]
        self._rew, self._cost, self._err, self._xn = outf
        self._fin, self._term, self._trunc = outb
        F = L.size
        self.observations = _ro(self._obs)
        self.estimation_errors = _ro(self._W[:, F:F + N])
        self.applied_inputs = _ro(self._W[:, F + N:])
        self.tracking_errors = _ro(self._err)
        self.features = _ro(self._W[:, :F])
        self.cycles = _ro(self._cycles)
        self.gamma, self.gamma_s = _ro(self._g), _ro(self._gs)
        self._result = StepResult(_ro(self._rew), _ro(self._term), _ro(self._trunc), _ro(self._reason))
        self._all_rows = np.arange(B, dtype=np.int64)

    # ------------------------------------------------------------------ pickling (copy.deepcopy, cloudpickle)
    def __getstate__(self) -> dict:
        # pickle keeps shared *objects* but not views sharing memory: the views are rebuilt on load,
        # the worker threads are not copied
        return {k: v for k, v in self.__dict__.items() if k not in self._VIEWS and k != "_pool"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._pool = None
        self._views()
        for a in self._ka + (self._SF, self._SI) + (self._FP if self.faults is not None else ()):
            a.flags.writeable = False  # read-only as built: the compiled step is specialised on it (no recompilation)

    # ------------------------------------------------------------------ properties
    @property
    def max_cycles(self) -> int | None:
        """Truncation horizon in control steps (None: never truncate); settable."""
        return self._max_cycles

    @max_cycles.setter
    def max_cycles(self, value) -> None:
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1):
            raise ValueError(f"max_cycles must be None or a positive integer, got {value!r}")
        self._max_cycles = None if value is None else int(value)
        self._step_consts = self._step_consts._replace(max_cycles=-1 if value is None else int(value))
        self._consts = tuple(self._step_consts)

    def agent_inputs(self, actions, out: np.ndarray | None = None) -> np.ndarray:
        """Inputs ``u (B, m)`` (for :meth:`advance`) from the agents' actions concatenated in agent
        order, ``(B, sum(agent_action_widths))``: with ``normalized_actions`` each agent's first
        ``m_k`` entries scaled by their bounds (the rest ignored), else the actions themselves."""
        a = np.asarray(actions, dtype=np.float64)
        if not self.normalized_actions:
            if out is None:
                return a
            out[...] = a
            return out
        return np.multiply(a[..., self.action_gather], self.action_scale, out=out)

    def observation_bounds(self, k: int):
        """``(low, high)`` of agent ``k``'s observation (true width ``obs_widths[k]``)."""
        return self.layout.bounds(k, self.obs_dtype)

    def generator(self, c: int) -> np.random.Generator:
        """The random generator of copy ``c`` (created unseeded on first use)."""
        if self._rngs[c] is None:
            self._rngs[c] = np.random.default_rng()
        return self._rngs[c]

    def set_generator(self, c: int, rng: np.random.Generator) -> None:
        """Let copy ``c`` draw its resets from ``rng`` (e.g. a Gymnasium env's ``np_random``)."""
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy Generator, got {type(rng).__name__}")
        self._rngs[c] = rng

    # ------------------------------------------------------------------ reset
    def _rows(self, indices) -> np.ndarray:
        if indices is None:
            return self._all_rows
        idx = np.asarray(indices)
        if idx.dtype == bool:
            if idx.shape != (self.num_envs,):
                raise ValueError(f"indices as a mask must have shape ({self.num_envs},), got {idx.shape}")
            return np.flatnonzero(idx).astype(np.int64)
        if idx.ndim != 1 or (idx.size and (not np.issubdtype(idx.dtype, np.integer) or idx.min() < 0
                                           or idx.max() >= self.num_envs)):
            raise ValueError(f"indices must be copy indices in [0, {self.num_envs}) or a boolean mask, got {indices!r}")
        return idx.astype(np.int64)

    def _per_copy(self, options: dict, key: str, k: int, width: int):
        val = options.get(key)
        if val is None:
            return None
        a = as_array(val, f"options[{key!r}]")
        if a.shape == (width,):
            return np.broadcast_to(a, (k, width))
        if a.shape != (k, width):
            raise ValueError(f"options[{key!r}] must have shape ({width},) or ({k}, {width}) (one per reset copy), "
                             f"got shape {a.shape}")
        return a

    def reset(self, indices=None, seeds=None, options: dict | None = None) -> np.ndarray:
        """Start new episodes in copies ``indices`` (None: all; ints or a boolean mask).

        ``seeds``: None or one entry (int or None) per reset copy: an int reseeds that
        copy's generator (``numpy.random.default_rng(seed)``). ``options`` may hold
        ``"x0"`` (exact plant initial state), ``"v0"`` (exact initial unknown input, exosystem
        or constant disturbance) and ``"x_r0"`` (reference-model initial state), each of shape
        ``(n,)`` (every reset copy) or ``(k, n)`` (one row per reset copy); other keys are ignored.
        Returns :attr:`observations`.
        """
        rows = self._rows(indices)
        k = rows.size
        if options is None:
            options = {}
        elif not isinstance(options, Mapping):
            raise ValueError(f"options must be None or a dict (keys 'x0', 'v0', 'x_r0'), got "
                             f"{type(options).__name__} {options!r}")
        if seeds is not None:
            try:
                seeds = list(seeds)
            except TypeError:
                raise ValueError(f"seeds must be None or one seed (int or None) per reset copy, got {seeds!r}") from None
            if len(seeds) != k:
                raise ValueError(f"seeds must have one entry per reset copy ({k}), got {len(seeds)}")
            seeds = [check_seed(s, "seed") for s in seeds]  # all checked before any copy is reset
        n, m_v, sc = self.n_states, self.n_unknown, self.scenario
        x0s = self._per_copy(options, "x0", k, n)
        v0s = self._per_copy(options, "v0", k, m_v) if m_v else None
        xr0 = self._per_copy(options, "x_r0", k, n)
        if xr0 is None:
            xr0 = np.broadcast_to(sc.x_r0 if sc.x_r0 is not None else np.zeros(n), (k, n))
        X0, V0 = np.empty((k, n)), np.empty((k, m_v))
        dist, random_v = self.distribution, self.disturbance == "random"
        faulty = self.faults is not None
        fseeds = np.zeros(k, dtype=np.uint64)
        for j, c in enumerate(rows):
            if seeds is not None and seeds[j] is not None:
                self._rngs[c] = np.random.default_rng(seeds[j])
            rng = self.generator(c)
            X0[j] = dist.x0(rng) if x0s is None else x0s[j]
            V0[j], sig = dist.disturbance_params(rng, None if v0s is None else v0s[j])
            if random_v:
                self._sig[:, c] = sig
            if faulty:  # the copy's fault seed, drawn last (faults=None draws exactly what it drew before)
                fseeds[j] = rng.integers(0, 2**64, dtype=np.uint64)
        self._x[rows], self._xr[rows], self._v[rows] = X0, xr0, V0
        self._z[rows], self._g[rows], self._gs[rows], self._t[rows] = 0.0, sc.gamma0, sc.gamma_s0, 0.0
        if faulty:
            fs = init_fault_state(self.params, self._fa, X0, self._z[rows], fseeds, co_nodes=self._fconsts[0],
                                  draws=partial(period_draws_compiled, packed=self._FP))
            for dst, src in zip(self._fs, fs):
                dst[rows] = src
        self._cycles[rows] = 0
        self._term[rows] = self._trunc[rows] = False
        self._reason[rows] = REASON_NONE
        self._rew[rows] = 0.0
        self._W[rows, self.layout.size + self.n_nodes:] = 0.0  # no input applied yet
        self._write_features(rows)
        self.started = True
        if self._record and bool((rows == 0).any()):
            self.history = ([0.0], [float(self.task_errors()[0])], [self.estimation_errors[0].copy()])
        return self.observations

    def _write_features(self, rows) -> None:
        write_features(rows, self._state, self._W, self._obs, self._SF, self._SI, self.has_reference,
                       (self._cost, self._err, self._xn, self._fin))
        if self.faults is not None:
            fault_features(rows, self._state, self._W, self._obs, self._SF, self._SI, self.has_reference,
                           (self._FP, self._fs, self._rx, self._fconsts))

    # ------------------------------------------------------------------ step
    def advance(self, u) -> StepResult:
        """One control step of every copy with the inputs ``u (B, m)`` (float or integer dtype; clipped to
        ``[-action_bound, action_bound]``, the clipped input is simulated and charged).

        Returns the :class:`StepResult` views ``(reward, terminated, truncated, reason)``. A copy
        that ended must be reset before it is advanced again (its results are then meaningless).
        Raises ``ValueError`` (naming the copy and the agents) and simulates nothing when some
        input is NaN/inf, or when ``u`` is boolean or complex.
        """
        u = np.asarray(u)
        if u.dtype != np.float64 or not u.flags.c_contiguous:
            if u.dtype.kind not in NUMERIC_KINDS:  # bool would act as 0/1, complex lose its imaginary part
                raise ValueError(f"u must be real numbers (float or integer) of shape ({self.num_envs}, "
                                 f"{self.n_inputs}), got dtype {u.dtype.name}")
            u = np.ascontiguousarray(u, dtype=np.float64)
        if u.shape != (self.num_envs, self.n_inputs):
            raise ValueError(f"u must have shape ({self.num_envs}, {self.n_inputs}) (copies, inputs), got {u.shape}")
        fault = NO_FAULT if self.faults is None else (self._FP, self._fs, self._rx, self._fconsts)
        args = (self._state, self._W, self._obs, self._outs, self._sig, self._ka, self._SF, self._SI, self._consts)
        if len(self.ranges) == 1:
            bad = advance_range(0, self.num_envs, u, args, fault)
        else:
            bad = first_non_finite(u)
            if bad < 0:
                if self._pool is None:
                    from concurrent.futures import ThreadPoolExecutor

                    self._pool = ThreadPoolExecutor(len(self.ranges) - 1, thread_name_prefix="dobs_envs_core")
                futures = [self._pool.submit(advance_range, lo, hi, u, args, fault) for lo, hi in self.ranges[1:]]
                advance_range(*self.ranges[0], u, args, fault)
                for f in futures:
                    f.result()
        if bad >= 0:
            agents = [a for a, s in zip(self.agents, self.channel_slices) if not np.isfinite(u[bad, s]).all()]
            raise ValueError(f"input of copy {bad} contains NaN or inf in the channel(s) of agent(s) {agents}")
        if self.history is not None:
            h = self.history
            h[0].append(float(self._t[0]))
            h[1].append(float(self.task_errors()[0]))
            h[2].append(self.estimation_errors[0].copy())
        return self._result

    def close(self) -> None:
        """Stop the worker threads (if any) and drop the render history."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        self.history = None

    def kernel_arguments(self) -> dict:
        """Copies of the arguments of the step kernel except ``u`` (keywords of
        :func:`~dobs_envs.envs.step_kernel.advance_batch`: ``state, W, obs, outs, sig, ka, SF, SI,
        consts``), e.g. to run a kernel and its numpy reference from the core's current state. The
        constants (``ka``, ``SF``, ``SI``, ``fp``, ``fconsts``) are the core's own read-only arrays, not copies:
        the kernels are specialised on read-only constants, and a writable copy would compile them again."""
        cp = lambda arrs: tuple(a.copy() for a in arrs)  # noqa: E731
        out = {"state": cp(self._state), "W": self._W.copy(), "obs": self._obs.copy(), "outs": cp(self._outs),
               "sig": self._sig.copy(), "ka": self._ka, "SF": self._SF, "SI": self._SI,
               "consts": self._consts, "fault": NO_FAULT}
        if self.faults is not None:  # advance_batch's / advance_reference's fault=(fp, fs, rx, fconsts)
            out.update(fault=(self._FP, cp(self._fs), cp(self._rx), self._fconsts))
        return out

    # ------------------------------------------------------------------ communication faults
    @property
    def fault_state(self):
        """A snapshot (copies) of the copies' :class:`~dobs_envs.sim.fault_state.FaultState` (faults only)."""
        if self.faults is None:
            raise AttributeError("fault_state: this core has no communication faults (option faults=None)")
        from ..sim.fault_state import FaultState

        return FaultState(*(a.copy() for a in self._fs))

    @property
    def co_received(self) -> np.ndarray:
        """``(B, K)`` bool: whether each agent's C-O packet arrived at the last boundary (faults only; else
        its ``xhat`` is the held, stale estimate). A new array."""
        if self.faults is None:
            raise AttributeError("co_received: this core has no communication faults (option faults=None)")
        return self._rx[0].copy()

    @property
    def oo_received_fraction(self) -> np.ndarray:
        """``(B, K)``: the fraction of the O-O links into each agent's node whose value was received at the last
        boundary (1 for a node without links; faults only). A new array."""
        if self.faults is None:
            raise AttributeError("oo_received_fraction: this core has no communication faults (option faults=None)")
        frac = self._rx[1].astype(np.float64) @ self._oo_incidence.T
        frac[:, self._oo_none] = 1.0
        return frac

    # ------------------------------------------------------------------ read-out
    def task_errors(self) -> np.ndarray:
        """``(B,)`` the task's error now (the tracking error ``||x - x_r||``/``||x||`` by default)."""
        if self._task_error is None:
            return self.tracking_errors
        return self._task_error(self._x)

    def states(self, indices=None) -> np.ndarray:
        """Global states ``(x, x_r if tracking, xhat_0..xhat_{N-1}, v)`` of the copies, ``(k, state_dim)``
        in ``obs_dtype`` (a new array; terminal states cleaned like the observations)."""
        rows = self._rows(indices)
        with np.errstate(over="ignore"):  # a terminal +-1.8e308 becomes +-inf in float32, then cleaned
            out = self._W[rows[:, None], self._state_index].astype(self.obs_dtype)
        if self._term[rows].any():
            np.nan_to_num(out, copy=False)
        return out

    @property
    def sim_state(self) -> SimState:
        """A snapshot (copies) of the batched :class:`~dobs_envs.sim.SimState`."""
        return SimState(*(a.copy() for a in self._state))

    def set_sim_state(self, state: SimState, indices=None) -> None:
        """Overwrite the simulation state of copies ``indices`` (None: all) with ``state`` (batch size =
        number of copies) and recompute their features; for tests, warm starts and injected faults."""
        rows = self._rows(indices)
        if not isinstance(state, SimState):
            raise TypeError(f"state must be a SimState, got {type(state).__name__}")
        for dst, name in zip(self._state, StateArrays._fields):
            src = np.asarray(getattr(state, name), dtype=np.float64)
            if src.shape != (rows.size,) + dst.shape[1:]:
                raise ValueError(f"state.{name} must have shape {(rows.size,) + dst.shape[1:]}, got {src.shape}")
            dst[rows] = src
        self._write_features(rows)
