"""The shared PettingZoo ``ParallelEnv`` of the suite: :class:`DObsParallelEnv` (a thin adapter).

One environment = a batch-size-1 :class:`~dobs_envs.envs.env_core.EnvCore` of one
:class:`~dobs_envs.scenarios.scenario.Scenario`. The agents are the paper's *controller
nodes* (Fig. ofdobc): agent ``"controller_k"`` chooses the input ``u^k`` of channel
``B^k`` (eq. Busplit) from what its linked observer node ``i = links[k]`` knows (see
:mod:`dobs_envs.envs.observation`); the observer nodes run the paper's distributed
observer (eqs. obidynamic, barEFGB, H_idefine, gammaiis / gagasbeta) inside the simulation.

The named environments (:mod:`dobs_envs.tracking_v0`, ...) are subclasses that fix the
options dataclass, the default scenario, the action bounds and the task error
(class-level hooks of :class:`~dobs_envs.envs.task_spec.TaskSpec`, read by ``make_core``, which
every adapter uses); the class docstrings are their specifications. :func:`make_parallel_env` builds the
same environment from any user :class:`Scenario` (or a YAML/JSON file).
"""
from __future__ import annotations

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from ..linalg.validation import check_seed
from .adapter import CoreAdapter, agent_spaces
from .distributions import DEFAULT_INIT_NOISE
from .options import RENDER_MODES, EnvOptions
from .rendering import LivePlot
from .task_spec import TaskSpec

__all__ = ["DObsParallelEnv", "make_parallel_env", "COMMON_OPTIONS", "agent_spaces"]

#: Options every environment accepts, with their defaults (the fields of :class:`~dobs_envs.envs.options.EnvOptions`).
COMMON_OPTIONS = EnvOptions.defaults()

#: read-only attributes of the core, exposed unchanged by the adapter
_CORE_ATTRS = frozenset({
    "scenario", "options", "params", "layout", "links", "channel_slices", "n_states", "n_nodes", "n_inputs",
    "n_unknown", "has_reference", "dt", "substeps", "control_period", "action_bound", "obs_dtype", "Q", "R",
    "state_bound", "termination_penalty", "reward_kind", "cost_scale", "disturbance", "disturbance_amplitude",
    "init_noise", "penalty_cycles"})


class DObsParallelEnv(TaskSpec, ParallelEnv):
    """Distributed observer-based control of a linear plant (generic PettingZoo ParallelEnv).

    Built from any :class:`~dobs_envs.scenarios.scenario.Scenario`; the named environments
    document the paper-specific defaults. The options are the fields of
    :class:`~dobs_envs.envs.options.EnvOptions` (see :func:`make_parallel_env`); the
    class-level task hooks and :meth:`make_core` come from :class:`~dobs_envs.envs.task_spec.TaskSpec`.
    """

    metadata = {"render_modes": list(RENDER_MODES), "name": "dobs_envs_v0", "is_parallelizable": True,
                "render_fps": 20}
    DEFAULT_INIT_NOISE = DEFAULT_INIT_NOISE
    #: label of the task error in render(); None: ||x - x_r|| or ||x||
    TASK_ERROR_LABEL = None

    # ------------------------------------------------------------------ construction
    def __init__(self, **kwargs):
        self.core = c = self.make_core(1, **kwargs)
        self.render_mode = c.options.render_mode
        self._live = None  # render_mode="human": the live window (created on first use)
        self.possible_agents = list(c.agents)
        self.agents = []
        self._agent_id = {a: k for k, a in enumerate(self.possible_agents)}
        #: the core's outputs as agent dicts, the agents' actions as inputs
        self._adapter = CoreAdapter(c)
        obs_spaces, act_spaces = agent_spaces(c)
        self._action_spaces = dict(zip(self.possible_agents, act_spaces))
        self._obs_spaces = dict(zip(self.possible_agents, obs_spaces))
        self.state_space = spaces.Box(-np.inf, np.inf, shape=(c.state_dim,), dtype=c.obs_dtype)
        self._u = np.zeros((1, c.n_inputs))
        # normalized_actions: the agents' actions concatenated, mapped to u by core.agent_inputs
        self._a = np.zeros((1, int(c.agent_action_widths.sum()))) if c.normalized_actions else None

    def __getattr__(self, name):
        core = self.__dict__.get("core")
        if core is not None and name in _CORE_ATTRS:
            return getattr(core, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def max_cycles(self) -> int | None:
        """Truncation horizon in control steps (None: never); settable."""
        return self.core.max_cycles

    @max_cycles.setter
    def max_cycles(self, value) -> None:
        self.core.max_cycles = value

    # ------------------------------------------------------------------ spaces and layouts
    def _agent(self, agent) -> int:
        k = self._agent_id.get(agent)
        if k is None:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}")
        return k

    def observation_space(self, agent):
        return self._obs_spaces[self.possible_agents[self._agent(agent)]]

    def action_space(self, agent):
        return self._action_spaces[self.possible_agents[self._agent(agent)]]

    def observation_layout(self, agent) -> dict:
        """``{component: slice}`` of ``agent``'s observation vector (see :mod:`dobs_envs.envs.observation`)."""
        return dict(self.core.layout.agent_layout[self._agent(agent)])

    def state_layout(self) -> dict:
        """``{component: slice}`` of :meth:`state` (``x``, ``x_r`` if tracking, ``estimates`` (N n, node-major), ``v`` if B_v)."""
        return dict(self.core.state_layout)

    @property
    def num_agents(self) -> int:
        return len(self.agents)

    @property
    def max_num_agents(self) -> int:
        return len(self.possible_agents)

    @property
    def np_random(self) -> np.random.Generator:
        return self.core.generator(0)

    # ------------------------------------------------------------------ reset / step
    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode. ``seed`` reseeds the environment's generator (initial state,
        disturbance) and the spaces (agent ``k``: ``seed + k``). ``options`` may hold ``"x0"``,
        ``"v0"`` and ``"x_r0"`` (exact initial plant state, unknown input, reference-model state).
        A ``seed`` that is not None or a non-negative int, or ``options`` that are not a dict, raise
        ``ValueError`` naming them (nothing is reset)."""
        seed = check_seed(seed, "seed")
        if seed is not None:
            for k, a in enumerate(self.possible_agents):
                self._action_spaces[a].seed(int(seed) + k)
                self._obs_spaces[a].seed(int(seed) + k)
        self.core.reset(None, None if seed is None else [seed], options)
        self.agents = list(self.possible_agents)
        if self.render_mode == "human":
            self.show(force=True)
        return self._observations(), self._infos(0)

    def step(self, actions: dict):
        if not self.agents:
            raise RuntimeError("step() called on a finished episode (no live agents); call reset() first")
        buf = self._u if self._a is None else self._a
        self._adapter.write_agent_actions(actions, buf[0])
        if self._a is not None:
            self._adapter.agent_inputs(self._a, out=self._u)
        res = self.core.advance(self._u)
        term, trunc = bool(res.terminated[0]), bool(res.truncated[0])
        agents = self.possible_agents
        out = (self._observations(), dict.fromkeys(agents, float(res.reward[0])), dict.fromkeys(agents, term),
               dict.fromkeys(agents, trunc), self._infos(int(res.reason[0])))
        if term or trunc:
            self.agents = []
        if self.render_mode == "human":
            self.show(force=term or trunc)
        return out

    def actions_from_inputs(self, u) -> dict:
        """``{agent: action}`` that applies the inputs ``u (m,)``: the channels' parts of ``u``, or with
        ``normalized_actions`` divided by their bounds and zero-padded (for controllers that compute
        inputs, e.g. :mod:`baselines.policies`)."""
        return self._adapter.actions_from_inputs(u)

    def _observations(self) -> dict:
        """Per-agent observations: views into this step's fresh copy of the core's (K, D) row."""
        return self._adapter.agent_observations(0)

    def _infos(self, reason: int) -> dict:
        """Per-agent infos: the same numeric keys from ``reset`` on (see :mod:`dobs_envs.envs.adapter`)."""
        return dict(zip(self.possible_agents, self._adapter.agent_infos(termination_reason=reason)))

    # ------------------------------------------------------------------ state / diagnostics / render
    def state(self) -> np.ndarray:
        """Global state for centralised critics: ``(x, x_r, xhat_0..xhat_{N-1}, v)`` flattened (see :meth:`state_layout`)."""
        if not self.core.started:
            raise RuntimeError("call reset() before state()")
        return self.core.states()[0]

    def estimation_errors(self) -> np.ndarray:
        """``||xhat_i - x||`` for every observer node (copy)."""
        return self.core.estimation_errors[0].copy()

    def task_error(self) -> float:
        """The task's error now: ``||x - x_r||`` (or ``||x||``) by default, the rendezvous
        disagreement for hetero_mas. It is what render() plots and what the benchmark reports."""
        return float(self.core.task_errors()[0])

    @property
    def tracking_error(self) -> float:
        """``||x - x_r||`` (tracking) or ``||x||`` at the current step."""
        return float(self.core.tracking_errors[0])

    @property
    def applied_input(self) -> np.ndarray:
        """The input ``u (m,)`` held over the last control step, after clipping (copy)."""
        return self.core.applied_inputs[0].copy()

    @property
    def sim_state(self):
        """Current :class:`~dobs_envs.sim.SimState` (batch size 1; a snapshot), None before reset()."""
        return self.core.sim_state if self.core.started else None

    def _task_label(self) -> str:
        return self.TASK_ERROR_LABEL or (r"$\|x - x_r\|$" if self.core.has_reference else r"$\|x\|$")

    def render(self):
        """``render_mode="rgb_array"``: the error plot as an RGB image ``(H, W, 3)`` uint8;
        ``"human"``: redraw the live window (``reset``/``step`` redraw it too) and return None."""
        if self.render_mode is None:
            import gymnasium

            gymnasium.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array' "
                                  "(images) or 'human' (a live window) to the constructor")
            return None
        if self.core.history is None:
            raise RuntimeError("call reset() before render()")
        if self.render_mode == "human":
            self.show(force=True)
            return None
        from .rendering import error_plot

        t, te, ee = self.core.history
        return error_plot(np.asarray(t), np.asarray(te), np.asarray(ee), title=self.metadata["name"],
                          tracking_label=self._task_label())

    def show(self, force: bool = False) -> None:
        """``render_mode="human"``: redraw the live window of the error plot (at most ``render_fps``
        times a second unless ``force``; headless machines: one warning, nothing shown)."""
        if self.core.history is None:
            return
        if self._live is None:
            self._live = LivePlot(self.metadata["name"], self._task_label(), self.metadata["render_fps"])
        self._live.update(*self.core.history, force=force)

    def close(self):
        if self._live is not None:
            self._live.close()
        self.core.close()


def make_parallel_env(scenario, **options) -> DObsParallelEnv:
    """A :class:`DObsParallelEnv` for any :class:`Scenario` (or a YAML/JSON scenario file path).

    Options (the fields of :class:`~dobs_envs.envs.options.EnvOptions`; defaults in
    parentheses; unknown names raise ``TypeError``):

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
      (``cost_scale``, 0.1, is an error norm); "sqrt" is ``-sqrt(c) * period`` (about the
      error norm: linear rather than quadratic growth). Both weigh steady-state errors
      more against the transient (with the quadratic cost, the paper controller's 20 s
      tracking episode spends 90 % of its cost in the first 2 s): the log cost weighs a
      steady-state error of 3 -> 0.03 as much as a transient of 30 -> 1. The termination
      penalty uses the same shape. Benchmarks evaluate every policy on the quadratic cost.
    - ``action_bound`` (``scenario.metadata['action_bound']`` or "auto"): per input component;
      "auto" calibrates it with the scenario's paper controller (:mod:`dobs_envs.envs.calibration`).
    - ``init_noise`` (None): half-width of the uniform noise added to ``x0`` at reset
      (None: the scenario's ``x0_scale`` distribution if it has one, else 1.0).
    - ``state_bound`` (1e3): episode terminates when ``||x|| > state_bound``;
      ``termination_penalty`` (True): the terminating step's reward also charges
      ``lambda_max(Q) * state_bound^2 * period`` per remaining step of the horizon
      (staying on the bound until the end; without truncation, until the scenario's
      ``t_end``), so that diverging early never pays.
    - ``disturbance`` ("exosystem" | "random" | "none") and ``disturbance_amplitude`` (2.0)
      for systems with an unknown input (:mod:`dobs_envs.envs.distributions`).
    - ``render_mode`` (None | "rgb_array" | "human": a live matplotlib window; headless: a warning).
    - ``normalized_actions`` (False): every agent acts in ``Box(-1, 1, (M,))`` (``M`` the largest
      channel width; entries beyond the agent's own channels are ignored), mapped onto the
      channels' bounds; ``padded_observations`` (False): where the agents' widths differ, every
      agent observes its observation zero-padded to the widest agent's width plus a 0/1 mask of
      the same width (equal widths: unchanged), with common bounds. Together they
      give all agents identical spaces (parameter sharing without wrappers).

    Raises the design layer's :class:`~dobs_envs.assumptions.AssumptionError` when the
    system does not satisfy the paper's assumptions.
    """
    return DObsParallelEnv(scenario=scenario, **options)
