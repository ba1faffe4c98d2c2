"""The shared PettingZoo ``ParallelEnv`` of the suite: :class:`DObsParallelEnv`.

One environment = one :class:`~dobs_envs.scenarios.base.Scenario` simulated by
:func:`dobs_envs.sim.step_env` (batch size 1) once per control step. The agents
are the paper's *controller nodes* (Fig. ofdobc): agent ``"controller_k"``
chooses the input ``u^k`` of channel ``B^k`` (eq. Busplit) from what its linked
observer node ``i = links[k]`` knows (see :mod:`dobs_envs.envs.observation`);
the observer nodes run the paper's distributed observer (eqs. obidynamic,
barEFGB, H_idefine, gammaiis / gagasbeta) inside the simulation.

The named environments (:mod:`dobs_envs.tracking_v0`, ...) are subclasses that
fix the default scenario, the action bounds and the task options; the class
docstrings are their specifications. :func:`make_parallel_env` builds the same
environment from any user :class:`Scenario` (or a YAML/JSON file).
"""
from __future__ import annotations

import math
import os
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv
from scipy.linalg import expm

from ..sim import SimParams, SimState, step_env
from .observation import FeatureLayout, clip_inplace, pack_static, resolve_components, write_features_packed

__all__ = ["DObsParallelEnv", "make_parallel_env", "COMMON_OPTIONS"]

#: Options every environment accepts, with their defaults (``None``: "see the env docstring").
COMMON_OPTIONS = {
    "scenario": None,
    "dt": 1e-3,
    "substeps": 50,
    "max_cycles": None,
    "horizon": None,
    "observation": "local",
    "obs_dtype": "float32",
    "Q": None,
    "R": None,
    "action_bound": None,
    "init_noise": None,
    "state_bound": 1e3,
    "termination_penalty": True,
    "reward": "quadratic",
    "cost_scale": 0.1,
    "render_mode": None,
}

#: reward shapes of the ``reward`` option (see :func:`make_parallel_env`)
REWARDS = ("quadratic", "log", "sqrt")

#: Options of systems with an unknown input ``v`` (``B_v != 0``).
DISTURBANCE_OPTIONS = {"disturbance": "exosystem", "disturbance_amplitude": 2.0}

_DISTURBANCES = ("exosystem", "random", "none")
_N_RANDOM_TERMS = 3  # sinusoids per component of the "random" disturbance


def _load_scenario(sc):
    if isinstance(sc, (str, os.PathLike)):
        from ..scenarios.io import load_scenario

        return load_scenario(sc)
    return sc


class DObsParallelEnv(ParallelEnv):
    """Distributed observer-based control of a linear plant (generic PettingZoo ParallelEnv).

    Built from any :class:`~dobs_envs.scenarios.base.Scenario`; the named
    environments document the paper-specific defaults. See
    :func:`make_parallel_env` for the options (they are the keys of
    :data:`COMMON_OPTIONS`, plus ``disturbance``/``disturbance_amplitude`` when
    the system has an unknown input).
    """

    metadata = {"render_modes": ["rgb_array"], "name": "dobs_envs_v0", "is_parallelizable": True, "render_fps": 20}

    #: default action bound (per input component) when the scenario gives none
    DEFAULT_ACTION_BOUND = 50.0
    #: default half-width of the uniform noise added to the scenario's x0 at reset
    DEFAULT_INIT_NOISE = 1.0
    #: extra options of the class (merged with COMMON_OPTIONS)
    EXTRA_OPTIONS: dict = {}

    # ------------------------------------------------------------------ construction
    @classmethod
    def valid_options(cls) -> dict:
        """Option name -> default of this environment class."""
        return {**COMMON_OPTIONS, **DISTURBANCE_OPTIONS, **cls.EXTRA_OPTIONS}

    def __init__(self, **kwargs):
        valid = self.valid_options()
        unknown = sorted(set(kwargs) - set(valid))
        if unknown:
            raise TypeError(
                f"{type(self).__name__} got unexpected keyword argument(s) {unknown}; "
                f"valid arguments are: {sorted(valid)}"
            )
        opts = {**valid, **kwargs}
        self.options = opts
        sc = _load_scenario(opts["scenario"])
        if sc is None:
            sc = self._default_scenario(opts)
        from ..scenarios.base import Scenario

        if not isinstance(sc, Scenario):
            raise TypeError(f"scenario must be a Scenario or a path to a YAML/JSON scenario file, got {type(sc).__name__}")
        self._check_scenario(sc, opts)
        self.scenario = sc
        self.render_mode = opts["render_mode"]
        if self.render_mode is not None and self.render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {self.render_mode!r}")

        # --- timing ------------------------------------------------------------------
        dt, substeps = opts["dt"], opts["substeps"]
        if not (isinstance(dt, (int, float, np.floating, np.integer)) and np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive finite number, got {dt!r}")
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
        self.dt, self.substeps = float(dt), int(substeps)
        self.control_period = self.dt * self.substeps
        self.max_cycles = self._resolve_horizon(opts, sc)
        # horizon charged by the termination penalty: the truncation horizon, or (no
        # truncation, e.g. under gym's TimeLimit) the scenario's t_end in control steps
        self._penalty_cycles = self.max_cycles if self.max_cycles is not None else \
            max(1, int(round(sc.t_end / self.control_period)))

        noise = opts["init_noise"]
        if noise is not None and not (np.isfinite(noise) and noise >= 0):
            raise ValueError(f"init_noise must be None or a finite number >= 0, got {noise!r}")
        self.init_noise = None if noise is None else float(noise)

        # --- unknown input -----------------------------------------------------------
        m_v = sc.B_v.shape[1]
        self.disturbance = opts["disturbance"]
        if m_v == 0:
            if kwargs.get("disturbance", "none") not in ("none", "exosystem") or "disturbance_amplitude" in kwargs:
                raise ValueError("disturbance options need a system with an unknown input (Scenario.B_v)")
            self.disturbance = "none"
        elif self.disturbance not in _DISTURBANCES:
            raise ValueError(f"disturbance must be one of {_DISTURBANCES}, got {self.disturbance!r}")
        amp = opts["disturbance_amplitude"]
        if not (np.isfinite(amp) and amp >= 0):
            raise ValueError(f"disturbance_amplitude must be finite and >= 0, got {amp!r}")
        self.disturbance_amplitude = float(amp)

        # --- simulation parameters (the design raises AssumptionError here) ------------
        design = sc.design
        K_ref = sc.K if sc.reference is not None else None
        self.params = SimParams.from_design(
            design, phi=sc.phi, phi_s=sc.phi_s, sigma=sc.sigma, sigma_s=sc.sigma_s, dt=self.dt,
            substeps=self.substeps, exosystem=sc.exosystem if self.disturbance == "exosystem" else None, K_ref=K_ref,
        )
        p = self.params
        n, N, m = p.n_states, p.n_nodes, p.n_inputs
        self.n_states, self.n_nodes, self.n_inputs, self.n_unknown = n, N, m, m_v
        self.has_reference = sc.reference is not None

        # --- agents ------------------------------------------------------------------
        Kc = sc.n_controllers
        self.possible_agents = [f"controller_{k}" for k in range(Kc)]
        self.agents = []
        self._agent_id = {a: k for k, a in enumerate(self.possible_agents)}
        self.channel_slices = sc.channel_slices
        self.links = tuple(sc.links)
        self._widths = tuple(s.stop - s.start for s in self.channel_slices)
        self._shapes = [(w,) for w in self._widths]
        self._agent_keys = set(self.possible_agents)
        self._agent_links = tuple(zip(self.possible_agents, self.links))

        # --- actions -----------------------------------------------------------------
        bound = opts["action_bound"]
        if bound is None:
            bound = self._default_action_bound(sc)
        if isinstance(bound, str):
            if bound != "auto":
                raise ValueError(f"action_bound must be a number, an array of shape ({m},) or 'auto', got {bound!r}")
            bound = self._auto_action_bound()
        bound = np.asarray(bound, dtype=np.float64)
        if bound.ndim == 0:
            bound = np.full(m, float(bound))
        if bound.shape != (m,) or not np.all(np.isfinite(bound)) or np.any(bound <= 0):
            raise ValueError(f"action_bound must be a positive finite scalar or have shape ({m},) (one per input component), got {opts['action_bound']!r}")
        self.action_bound = bound
        self._u_low = -bound
        self._u_high = bound.copy()
        self._action_spaces = {
            a: spaces.Box(low=-bound[sl].astype(np.float32), high=bound[sl].astype(np.float32), dtype=np.float32)
            for a, sl in zip(self.possible_agents, self.channel_slices)
        }

        # --- observations ------------------------------------------------------------
        self.obs_dtype = np.dtype(opts["obs_dtype"])
        if self.obs_dtype not in (np.float32, np.float64):
            raise ValueError(f"obs_dtype must be 'float32' or 'float64', got {opts['obs_dtype']!r}")
        comps = resolve_components(opts["observation"], has_reference=self.has_reference, has_unknown_input=m_v > 0)
        neighbors = [sc.graph.neighbors(i) for i in range(N)]
        p_i = [c.shape[0] for c in sc.C]
        self.layout = FeatureLayout(p_i, n, m, m_v, neighbors, self.links, self.channel_slices, comps)
        L = self.layout
        self._obs_spaces = {}
        for k, a in enumerate(self.possible_agents):
            lo, hi = L.bounds(k, self.obs_dtype)
            self._obs_spaces[a] = spaces.Box(low=lo, high=hi, dtype=self.obs_dtype)
        # state(): x, x_r (tracking), all estimates, v (unknown input)
        st = [np.arange(L.x.start, L.x.stop)]
        self._state_layout, pos = {"x": slice(0, n)}, n
        if self.has_reference:
            st.append(np.arange(L.x_r.start, L.x_r.stop))
            self._state_layout["x_r"] = slice(pos, pos + n); pos += n
        st.append(np.arange(L.xhat.start, L.xhat.stop))
        self._state_layout["estimates"] = slice(pos, pos + N * n); pos += N * n
        if m_v:
            st.append(np.arange(L.v.start, L.v.stop))
            self._state_layout["v"] = slice(pos, pos + m_v); pos += m_v
        self._state_index = np.concatenate(st)
        self.state_space = spaces.Box(-np.inf, np.inf, shape=(pos,), dtype=self.obs_dtype)

        # --- reward ------------------------------------------------------------------
        self.Q = np.ascontiguousarray(self._matrix(opts["Q"], sc.Q, n, "Q"))
        self.R = np.ascontiguousarray(self._matrix(opts["R"], sc.R, m, "R"))
        sb = opts["state_bound"]
        if isinstance(sb, bool) or not isinstance(sb, (int, float, np.integer, np.floating)) \
                or not (np.isfinite(sb) and 0 < sb <= 1e150):
            raise ValueError(f"state_bound must be a positive number <= 1e150 (its square enters the termination "
                             f"penalty), got {sb!r}")
        self.state_bound = float(sb)
        # Cost of sitting on the bound for one control step: lambda_max(Q) * state_bound^2 * T.
        # With a cost-type (negative) reward, ending the episode early would otherwise be
        # *rewarded* (fewer negative steps): on termination the agents are charged this
        # per-step cost for every remaining step of the horizon, so diverging is never
        # better than staying inside the bound.
        self.termination_penalty = bool(opts["termination_penalty"])
        lam_q = float(np.linalg.eigvalsh(0.5 * (self.Q + self.Q.T))[-1])
        # reward shape: the LQ stage cost c = e'Qe + u'Ru itself, or log(1 + c / c0) with
        # c0 = lambda_max(Q) * cost_scale^2 (steady-state tracking errors matter: see make_parallel_env)
        self.reward_kind = opts["reward"]
        if self.reward_kind not in REWARDS:
            raise ValueError(f"reward must be one of {REWARDS}, got {self.reward_kind!r}")
        cs = opts["cost_scale"]
        if isinstance(cs, bool) or not isinstance(cs, (int, float, np.integer, np.floating)) \
                or not (np.isfinite(cs) and cs > 0):
            raise ValueError(f"cost_scale must be a positive finite number (an error norm), got {cs!r}")
        self.cost_scale = float(cs)
        self._log_c0 = max(lam_q, np.finfo(float).tiny) * self.cost_scale ** 2
        self._bound_step_cost = self._shaped_cost(lam_q * self.state_bound ** 2) * self.control_period

        # --- preallocated step buffers ------------------------------------------------
        # work buffer W = [f (feature vector) | estimation errors (N) | u (m)], see write_features_packed
        self._W = np.zeros(L.size + N + m)
        self._f = self._W[:L.size]
        self._f[L.one] = 1.0
        self._est_err = self._W[L.size:L.size + N]
        self._u = self._W[L.size + N:].reshape(1, m)
        self._u0 = self._u[0]
        self._r = self._f[L.r.start:L.r.stop].reshape(1, m)  # view (see _advance)
        self._ref = np.zeros((3, m))
        if self.has_reference:
            ref = sc.reference
            self._ref[0], self._ref[1], self._ref[2] = ref.amplitude, ref.frequency, ref.phase
        self._off = np.array([L.y.start, L.xhat.start, L.x.start, L.x_r.start, L.gamma.start, L.gamma_s.start,
                              L.v.start, L.r.start, L.time.start, L.e.start] + p_i, dtype=np.int64)
        self._all_index = np.ascontiguousarray(L.all_index, dtype=np.int64)
        self._obs_len = int(self._all_index.size)
        self._SF, self._SI = pack_static(p.C, p.G_bar, self._ref, self.Q, self.R, self._off, self._all_index, L.size)
        sl, pos = [], 0
        for a, ix in zip(self.possible_agents, L.agent_index):
            sl.append((a, slice(pos, pos + ix.size))); pos += ix.size
        self._agent_obs_slices = tuple(sl)
        self._np_random = None
        self._np_random_seed = None
        self._sim = None
        self._cycles = 0
        self._history = None
        self._v_signal = None

    # ------------------------------------------------------------------ hooks for subclasses
    def _default_scenario(self, opts):
        raise TypeError(f"{type(self).__name__} needs a scenario= (a Scenario or a YAML/JSON path)")

    def _check_scenario(self, sc, opts) -> None:
        """Subclasses reject scenarios their task does not fit."""

    def _default_action_bound(self, sc):
        return sc.metadata.get("action_bound", "auto")

    def _auto_action_bound(self, episodes: int = 8, max_seconds: float = 10.0, margin: float = 2.0):
        """Calibrated bounds: ``margin`` x the largest ``|u_j|`` of the scenario's paper controller
        (:mod:`dobs_envs.control.laws`, at this env's control period) over ``episodes`` initial states of the
        default distribution (fixed calibration seed 12345), simulated for ``min(horizon, max_seconds)``;
        at least 1 per component. Deterministic for a given scenario and options."""
        from ..control import paper_policy

        sc, p = self.scenario, self.params
        rng = np.random.default_rng(12345)
        x0 = np.stack([self._sample_x0(rng) for _ in range(episodes)])
        v0 = np.stack([self._initial_v(rng, None) for _ in range(episodes)]) if self.n_unknown else None
        self._v_signal = None  # calibration holds a random disturbance at its initial value
        x_r0 = sc.x_r0 if sc.x_r0 is not None else np.zeros(self.n_states)
        state = p.initial_state(x0, gamma0=sc.gamma0, gamma_s0=sc.gamma_s0, v0=v0, x_r0=x_r0)
        ctrl = paper_policy(sc)
        cs = ctrl.initial_state(episodes)
        steps = int(np.ceil(min(max_seconds, (self.max_cycles or np.inf) * self.control_period) / self.control_period))
        umax = np.zeros(self.n_inputs)
        from ..sim import estimates

        for _ in range(max(1, steps)):
            u, cs = ctrl.act(estimates(state, p), state.t, cs, self.control_period)
            if not np.all(np.isfinite(u)):
                break
            umax = np.maximum(umax, np.abs(u).max(axis=0))
            r = sc.reference(state.t) if sc.reference is not None else None
            state = step_env(state, u, p, r, validate=False)
        return np.maximum(1.0, margin * umax)

    # ------------------------------------------------------------------ helpers
    def _shaped_cost(self, c: float) -> float:
        """Stage cost of the reward: ``c`` (quadratic) or ``log(1 + c / c0)`` (log)."""
        if self.reward_kind == "log":
            return math.log1p(c / self._log_c0) if c < math.inf else math.inf
        if self.reward_kind == "sqrt":
            return math.sqrt(c) if c >= 0.0 else math.nan
        return c

    @staticmethod
    def _matrix(val, default, size, name):
        M = np.array(default if val is None else val, dtype=np.float64)
        if M.ndim == 0 and size == 1:
            M = M.reshape(1, 1)
        if M.shape != (size, size) or not np.all(np.isfinite(M)):
            raise ValueError(f"{name} must be a finite ({size}, {size}) matrix, got shape {M.shape}")
        return M

    def _resolve_horizon(self, opts, sc):
        mc, hz = opts["max_cycles"], opts["horizon"]
        if mc is not None and hz is not None:
            raise ValueError("give either max_cycles (control steps) or horizon (seconds), not both")
        if mc is not None:
            if isinstance(mc, bool) or not isinstance(mc, (int, np.integer)) or mc < 1:
                raise ValueError(f"max_cycles must be a positive integer, got {mc!r}")
            return int(mc)
        hz = sc.t_end if hz is None else hz
        if not (isinstance(hz, (int, float, np.floating, np.integer)) and hz > 0):
            raise ValueError(f"horizon must be a positive number of seconds (math.inf: never truncate), got {hz!r}")
        if math.isinf(hz):
            return None
        return max(1, int(round(float(hz) / self.control_period)))

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent):
        try:
            return self._obs_spaces[agent]
        except KeyError:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}") from None

    def action_space(self, agent):
        try:
            return self._action_spaces[agent]
        except KeyError:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}") from None

    def observation_layout(self, agent) -> dict:
        """``{component: slice}`` of ``agent``'s observation vector (see :mod:`dobs_envs.envs.observation`)."""
        k = self._agent_id.get(agent)
        if k is None:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}")
        return dict(self.layout.agent_layout[k])

    def state_layout(self) -> dict:
        """``{component: slice}`` of :meth:`state` (``x``, ``x_r`` if tracking, ``estimates`` (N n, node-major), ``v`` if B_v)."""
        return dict(self._state_layout)

    @property
    def num_agents(self) -> int:
        return len(self.agents)

    @property
    def max_num_agents(self) -> int:
        return len(self.possible_agents)

    @property
    def np_random(self) -> np.random.Generator:
        if self._np_random is None:
            self._np_random, self._np_random_seed = seeding.np_random()
        return self._np_random

    @property
    def sim_state(self) -> SimState:
        """Current :class:`~dobs_envs.sim.SimState` (batch size 1)."""
        return self._sim

    # ------------------------------------------------------------------ reset
    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode.

        ``seed`` reseeds the environment's generator (initial state, disturbance)
        and the action spaces. ``options`` may hold ``"x0"`` (exact plant initial
        state, shape (n,)), ``"v0"`` (exact initial unknown input for the
        exosystem/constant disturbance) and ``"x_r0"`` (reference-model initial
        state); other keys are ignored.
        """
        if seed is not None:
            self._np_random, self._np_random_seed = seeding.np_random(seed)
            for k, a in enumerate(self.possible_agents):
                self._action_spaces[a].seed(int(seed) + k)
                self._obs_spaces[a].seed(int(seed) + k)
        rng = self.np_random
        options = options or {}
        sc, p = self.scenario, self.params
        n = self.n_states
        x0 = self._sample_x0(rng) if options.get("x0") is None else options["x0"]
        x0 = np.asarray(x0, dtype=np.float64)
        if x0.shape != (n,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"options['x0'] must be a finite array of shape ({n},), got shape {x0.shape}")
        v0 = self._initial_v(rng, options.get("v0"))
        x_r0 = sc.x_r0 if sc.x_r0 is not None else np.zeros(n)
        if options.get("x_r0") is not None:
            x_r0 = np.asarray(options["x_r0"], dtype=np.float64)
            if x_r0.shape != (n,) or not np.all(np.isfinite(x_r0)):
                raise ValueError(f"options['x_r0'] must be a finite array of shape ({n},)")
        self._sim = p.initial_state(x0, gamma0=sc.gamma0, gamma_s0=sc.gamma_s0, v0=v0, x_r0=x_r0)
        self._cycles = 0
        self.agents = list(self.possible_agents)
        self._terminated = False
        self._features()
        if self.render_mode is not None:
            self._history = ([float(self._sim.t[0])], [self.task_error()], [self._est_err.copy()])
        obs = self._observations()
        infos = self._infos(None)
        return obs, infos

    def _sample_x0(self, rng):
        sc = self.scenario
        if self.init_noise is None and sc.x0_scale is not None:
            return sc.sample_x0(rng)
        a = self.DEFAULT_INIT_NOISE if self.init_noise is None else self.init_noise
        return sc.x0 + rng.uniform(-a, a, size=self.n_states)

    def _initial_v(self, rng, v0):
        m_v = self.n_unknown
        if m_v == 0:
            return np.zeros(0)
        if self.disturbance == "none":
            self._v_signal = None
            return np.zeros(m_v)
        if self.disturbance == "random":
            A = self.disturbance_amplitude
            w = rng.uniform(0.1, 2.0, size=(m_v, _N_RANDOM_TERMS))
            ph = rng.uniform(0.0, 2 * np.pi, size=(m_v, _N_RANDOM_TERMS))
            a = rng.uniform(0.0, 1.0, size=(m_v, _N_RANDOM_TERMS))
            a = A * a / a.sum(axis=1, keepdims=True)  # sum_l |a_jl| = A  =>  |v_j(t)| <= A
            self._v_signal = (a, w, ph)
            if v0 is not None:
                raise ValueError("options['v0'] is not used with disturbance='random' (v(t) is a random signal)")
            return self._v_of_t(0.0)
        # exosystem (or constant v when the scenario has no exosystem)
        self._v_signal = None
        if v0 is not None:
            v0 = np.asarray(v0, dtype=np.float64)
            if v0.shape != (m_v,) or not np.all(np.isfinite(v0)):
                raise ValueError(f"options['v0'] must be a finite array of shape ({m_v},)")
            return v0
        S = self.scenario.exosystem
        if S is None or not np.any(S):
            return np.array(self.scenario.v0)
        tau = rng.uniform(0.0, 4 * np.pi)  # random time shift of the exosystem trajectory
        return expm(S * tau) @ self.scenario.v0

    def _v_of_t(self, t):
        a, w, ph = self._v_signal
        return (a * np.sin(w * t + ph)).sum(axis=1)

    # ------------------------------------------------------------------ step
    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished episode (no live agents); call reset() first")
        u = self._u0
        # fast path: exactly the live agents, right shapes, numeric -> one concatenate into u
        try:
            vals = [actions[a] for a in self.possible_agents]
            ok = actions.keys() == self._agent_keys and [v.shape for v in vals] == self._shapes
            if ok:
                np.concatenate(vals, out=u, casting="same_kind")
        except (KeyError, TypeError, ValueError, AttributeError):
            ok = False
        if not ok:
            self._parse_actions_slow(actions)
        if not clip_inplace(u, self._u_low, self._u_high):
            bad = [a for a, sl in zip(self.possible_agents, self.channel_slices) if not np.isfinite(u[sl]).all()]
            raise ValueError(f"action of agent(s) {bad} contains NaN or inf")
        self._advance()
        return self._step_outputs()

    def _parse_actions_slow(self, actions):
        """Validate ``actions`` agent by agent (errors name the agent) and write them into ``u``."""
        if not isinstance(actions, dict):
            raise ValueError(f"actions must be a dict agent -> action, got {type(actions).__name__}")
        u, agent_id, widths = self._u0, self._agent_id, self._widths
        for agent, a in actions.items():
            k = agent_id.get(agent)
            if k is None:
                raise ValueError(f"unknown agent {agent!r} in actions; agents are {self.possible_agents}")
            try:
                arr = np.asarray(a, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"action of agent {agent!r} is not a numeric array: {a!r}") from None
            if arr.shape != (widths[k],):
                raise ValueError(f"action of agent {agent!r} must have shape ({widths[k]},), got {arr.shape}")
            u[self.channel_slices[k]] = arr
        missing = [a for a in self.possible_agents if a not in actions]
        if missing:
            raise ValueError(f"missing action(s) for agent(s) {missing}")

    def _advance(self):
        """Simulate one control period with the (validated, clipped) ``self._u0``; update
        features/reward/termination. ``self._r`` is a view of the feature vector's ``r``
        block, written at the current time ``t``: the command r^k(t) of eq. (refxdy) held over
        the period (zeros without a reference)."""
        sim = self._sim
        if self._v_signal is not None:
            sim = SimState(sim.t, sim.x, sim.z, sim.gamma, sim.gamma_s, self._v_of_t(sim.t[0])[None], sim.x_r)
        self._sim = step_env(sim, self._u, self.params, self._r, validate=False)
        self._cycles += 1
        self._features()
        self._reward = -self._shaped_cost(self._cost) * self.control_period
        nx = self._x_norm
        if not self._finite:  # some entry of x, x_r, z, gamma, gamma_s or v is NaN/inf (kernel flag)
            self._terminated, self._reason = True, "non_finite_state"
        elif nx > self.state_bound:
            self._terminated, self._reason = True, "state_bound_exceeded"
        else:
            self._terminated, self._reason = False, None
        if self._terminated:
            # clean terminal observations/state(): NaN -> 0, +-inf -> +-largest finite of the dtype
            np.nan_to_num(self._obs_all, copy=False)
            np.nan_to_num(self._f, copy=False)
            if not math.isfinite(self._reward):
                self._reward = -self._bound_step_cost
            if self.termination_penalty:
                self._reward -= self._bound_step_cost * max(0, self._penalty_cycles - self._cycles)
        if self._history is not None:
            h = self._history
            h[0].append(float(self._sim.t[0])); h[1].append(self.task_error()); h[2].append(self._est_err.copy())

    def _features(self):
        """Write the feature vector ``f`` (see :mod:`.observation`), the estimation errors,
        the step cost, the norms and all agents' observations (``self._obs_all``, a fresh array)
        from the current state in one compiled call."""
        s = self._sim
        out = np.empty(self._obs_len, self.obs_dtype)
        cost, self._track_err, self._x_norm, self._finite = write_features_packed(
            s.x, s.z, s.x_r, s.gamma, s.gamma_s, s.v, float(s.t[0]), self._W, self._SF, self._SI,
            self.has_reference, out)
        self._cost = cost
        self._obs_all = out

    def _observations(self):
        """Per-agent observations: views into this step's fresh concatenated array."""
        o = self._obs_all
        return {a: o[sl] for a, sl in self._agent_obs_slices}

    def _infos(self, reason):
        ee, te = self._est_err.tolist(), self._track_err
        g, gs = self._sim.gamma[0].tolist(), self._sim.gamma_s[0].tolist()
        extra = self._shared_info()
        if reason is not None:
            extra = {**extra, "termination_reason": reason}
        if extra:
            return {a: {"estimation_error": ee[i], "tracking_error": te, "gamma": g[i], "gamma_s": gs[i], **extra}
                    for a, i in self._agent_links}
        return {a: {"estimation_error": ee[i], "tracking_error": te, "gamma": g[i], "gamma_s": gs[i]}
                for a, i in self._agent_links}

    def _shared_info(self) -> dict:
        """Task-specific info entries shared by all agents (subclasses)."""
        return {}

    def _step_outputs(self):
        agents = self.possible_agents
        obs = self._observations()
        rew = dict.fromkeys(agents, self._reward)
        term = self._terminated
        trunc = (not term) and self.max_cycles is not None and self._cycles >= self.max_cycles
        reason = self._reason if term else ("horizon" if trunc else None)
        terms = dict.fromkeys(agents, term)
        truncs = dict.fromkeys(agents, trunc)
        infos = self._infos(reason)
        if term or trunc:
            self.agents = []
        return obs, rew, terms, truncs, infos

    # ------------------------------------------------------------------ state / render
    def state(self) -> np.ndarray:
        """Global state for centralised critics: ``(x, x_r, xhat_0..xhat_{N-1}, v)`` flattened (see :meth:`state_layout`)."""
        if self._sim is None:
            raise RuntimeError("call reset() before state()")
        with np.errstate(over="ignore"):  # a cleaned +-1.8e308 becomes +-inf in float32: cleaned again below
            out = self._f[self._state_index].astype(self.obs_dtype)
        if self._terminated:
            np.nan_to_num(out, copy=False)
        return out

    def estimation_errors(self) -> np.ndarray:
        """``||xhat_i - x||`` for every observer node (copy)."""
        return self._est_err.copy()

    @property
    def applied_input(self) -> np.ndarray:
        """The input ``u (m,)`` held over the last control step, after clipping (copy)."""
        return self._u0.copy()

    @property
    def tracking_error(self) -> float:
        """``||x - x_r||`` (tracking) or ``||x||`` at the current step."""
        return self._track_err

    def render(self):
        if self.render_mode is None:
            import gymnasium

            gymnasium.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array' to the constructor")
            return None
        if self._history is None:
            raise RuntimeError("call reset() before render()")
        from .rendering import error_plot

        t, te, ee = self._history
        return error_plot(np.asarray(t), np.asarray(te), np.asarray(ee), title=self.metadata["name"],
                          tracking_label=self.TASK_ERROR_LABEL or (r"$\|x - x_r\|$" if self.has_reference else r"$\|x\|$"))

    #: label of the task error in render(); None: ||x - x_r|| or ||x||
    TASK_ERROR_LABEL = None

    def task_error(self) -> float:
        """The task's error now: ``||x - x_r||`` (or ``||x||``) by default, the rendezvous
        disagreement for hetero_mas. It is what render() plots and what the benchmark reports."""
        return self._track_err

    def close(self):
        self._history = None


def make_parallel_env(scenario, **options) -> DObsParallelEnv:
    """A :class:`DObsParallelEnv` for any :class:`Scenario` (or a YAML/JSON scenario file path).

    Options (defaults in parentheses; unknown names raise ``TypeError``):

    - ``dt`` (1e-3) Euler step; ``substeps`` (50) Euler steps per control step
      (control period ``dt * substeps``).
    - ``max_cycles`` or ``horizon`` (the scenario's ``t_end`` in seconds;
      ``horizon=math.inf`` never truncates).
    - ``observation`` ("local"): "local", "full" or a sequence of component names
      (:mod:`dobs_envs.envs.observation`); ``obs_dtype`` ("float32").
    - ``Q``, ``R`` (the scenario's): team reward ``-c * period`` with the LQ stage cost
      ``c = e'Qe + u'Ru``.
    - ``reward`` ("quadratic"): "quadratic" is ``-c * period``; "log" is
      ``-log(1 + c / c0) * period`` with ``c0 = lambda_max(Q) * cost_scale^2``
      (``cost_scale``, 0.1, is an error norm); "sqrt" is ``-sqrt(c) * period`` (about
      the error norm: linear rather than quadratic growth). Both reshape the cost so that
      steady-state errors weigh more against the transient (with the quadratic cost, the
      paper controller's 20 s tracking episode spends 90 % of its cost in the first 2 s):
      the log cost weighs a steady-state error of 3 -> 0.03 as much as a transient of
      30 -> 1. The termination penalty uses the same shape. Benchmarks evaluate every
      policy on the quadratic cost.
    - ``action_bound`` (``scenario.metadata['action_bound']`` or 50): per input component.
    - ``init_noise`` (None): half-width of the uniform noise added to ``x0`` at reset
      (None: the scenario's ``x0_scale`` distribution if it has one, else 1.0).
    - ``state_bound`` (1e3): episode terminates when ``||x|| > state_bound``;
      ``termination_penalty`` (True): the terminating step's reward also charges
      ``lambda_max(Q) * state_bound^2 * period`` per remaining step of the horizon
      (staying on the bound until the end; without truncation, until the scenario's
      ``t_end``), so that diverging early never pays.
    - ``disturbance`` ("exosystem" | "random" | "none") and ``disturbance_amplitude`` (2.0)
      for systems with an unknown input.
    - ``render_mode`` (None | "rgb_array").

    Raises the design layer's :class:`~dobs_envs.assumptions.AssumptionError`
    when the system does not satisfy the paper's assumptions.
    """
    return DObsParallelEnv(scenario=scenario, **options)
