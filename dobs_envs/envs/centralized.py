"""Gymnasium view of the environments: one centralised agent (a thin adapter).

:class:`CentralizedEnv` wraps a :class:`~dobs_envs.envs.parallel_env.DObsParallelEnv` and
drives its batch-size-1 :class:`~dobs_envs.envs.env_core.EnvCore` directly (no per-step
dict round trip); the parallel env's diagnostics (``state()``, ``estimation_errors()``,
``task_error()``, ``sim_state``, ``applied_input``) follow the Gymnasium episode:

- observation: the agents' local observations concatenated in agent order
  (``controller_0`` first), ``Box(float32)``; ``env.agent_observation_slices[k]``
  is agent ``k``'s part and ``env.observation_layout()`` names every component
  as ``"controller_k/<component>"``;
- action: all control inputs stacked, ``u = col(u^0, ..., u^{K-1})``,
  ``Box(-b, b, (m,), float32)`` with the parallel env's bounds
  (``env.agent_action_slices[k]`` is channel ``k``); out-of-range values are
  clipped, NaN/inf or a wrong shape raise ``ValueError`` (naming the agent
  whose channel holds the NaN); with ``normalized_actions=True`` the action is
  ``Box(-1, 1, (m,))`` and input ``j`` is ``a_j * b_j`` (no padding: one agent);
- ``padded_observations=True``: each agent's part is its observation as in the parallel env
  (padded and masked only where the agents' widths differ), so ``agent_observation_slices`` stay the agents' observations;
- reward: the team reward; ``terminated`` as the parallel env; info (the same keys from
  ``reset`` on, numeric only): ``tracking_error``, ``estimation_errors`` (N,), ``gamma`` (N,),
  ``gamma_s`` (N,), the task error if the task has one (e.g. ``disagreement``) and the integer
  ``termination_reason`` (codes of :data:`~dobs_envs.envs.env_core.REASONS`: 0 none,
  1 state_bound_exceeded, 2 non_finite_state, 3 horizon; ``gym.make``'s ``TimeLimit``
  truncates with code 0).

Registered ids (one per entry of :mod:`dobs_envs.registry`; ``gym.make`` adds a
``TimeLimit`` of ``max_episode_steps`` control steps, the default scenario's
``t_end`` over the default control period, and the wrapped environment then never
truncates by itself -- there is a single truncation mechanism):

=====================================  ============================  =================
id                                     parallel env                  max_episode_steps
=====================================  ============================  =================
``dobs_envs/Tracking-v0``              ``tracking_v0``               400 (20 s)
``dobs_envs/TrackingLossy-v0``         ``tracking_lossy_v0``         400 (20 s)
``dobs_envs/DisturbanceRejection-v0``  ``disturbance_rejection_v0``  400 (20 s)
``dobs_envs/HeteroMAS-v0``             ``hetero_mas_v0``             600 (30 s)
``dobs_envs/RandomNetwork-v0``         ``random_network_v0``         400 (20 s)
=====================================  ============================  =================

(seconds at the default control period 0.05 s; with other ``dt``/``substeps``
pass ``max_episode_steps=`` to ``gym.make``). ``max_cycles``/``horizon`` are
not accepted by ``gym.make``; :func:`make_gym_env` (any Scenario, no
``TimeLimit``) accepts them. ``gym.make_vec(id, num_envs=B)`` builds the native
vector env of the same id (:mod:`dobs_envs.envs.vector`).
"""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

from ..linalg.validation import as_numeric, check_seed
from ..registry import ENVIRONMENTS, GYM_IDS, EnvEntry
from .adapter import CoreAdapter, central_spaces
from .parallel_env import DObsParallelEnv

__all__ = ["CentralizedEnv", "make_gym_env", "GYM_IDS", "central_spaces", "reject_horizon_options"] + [f"make_{name}" for name in ENVIRONMENTS]


class CentralizedEnv(gym.Env):
    """One centralised agent controlling every channel of a dobs_envs parallel environment (see module docstring)."""

    def __init__(self, parallel_env: DObsParallelEnv):
        if not isinstance(parallel_env, DObsParallelEnv):
            raise TypeError(f"CentralizedEnv wraps a DObsParallelEnv, got {type(parallel_env).__name__}")
        self.parallel_env = pe = parallel_env
        self.core = c = pe.core
        self.metadata = {"render_modes": list(pe.metadata["render_modes"]), "render_fps": pe.metadata["render_fps"],
                         "name": pe.metadata["name"]}
        self.render_mode = pe.render_mode
        self.agents = list(pe.possible_agents)
        self.observation_space, self.action_space, self.agent_observation_slices = central_spaces(c)
        self.agent_action_slices = tuple(c.channel_slices)
        #: the core's outputs as the centralised agent's, its actions as inputs
        self._adapter = CoreAdapter(c)
        self._u = np.zeros((1, c.n_inputs))

    # ------------------------------------------------------------------ API
    def observation_layout(self) -> dict:
        """``{"controller_k/<component>": slice}`` of the concatenated observation."""
        out = {}
        for a, s in zip(self.agents, self.agent_observation_slices):
            for c, cs in self.parallel_env.observation_layout(a).items():
                out[f"{a}/{c}"] = slice(s.start + cs.start, s.start + cs.stop)
        return out

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=check_seed(seed, "seed"))
        self.core.set_generator(0, self.np_random)  # one generator for the episode distribution
        if seed is not None:
            self.action_space.seed(int(seed))
        self.core.reset(None, None, options)
        if self.render_mode == "human":
            self.parallel_env.show(force=True)
        return self._obs(), self._info(0)

    def step(self, action):
        if not self.core.started:
            raise RuntimeError("call reset() before step()")
        a = as_numeric(action, "action")
        if a.shape != self._u.shape[1:]:
            raise ValueError(f"action must have shape {self._u.shape[1:]} (all agents' inputs stacked), got {a.shape}")
        self._u[0] = self._adapter.central_inputs(a)
        res = self.core.advance(self._u)
        term, trunc = bool(res.terminated[0]), bool(res.truncated[0])
        if self.render_mode == "human":
            self.parallel_env.show(force=term or trunc)
        return self._obs(), float(res.reward[0]), term, trunc, self._info(int(res.reason[0]))

    def _obs(self) -> np.ndarray:
        return self._adapter.central_observations(0)  # a new array

    def _info(self, reason: int) -> dict:
        return self._adapter.central_info(0, termination_reason=reason)

    def render(self):
        return self.parallel_env.render()

    def close(self):
        self.parallel_env.close()

    def state(self) -> np.ndarray:
        """The parallel env's global state (x, x_r, all estimates, v)."""
        return self.parallel_env.state()

    @property
    def scenario(self):
        return self.core.scenario

    @property
    def control_period(self) -> float:
        return self.core.control_period


def make_gym_env(scenario, **options) -> CentralizedEnv:
    """Centralised Gymnasium env for any Scenario (or YAML/JSON path); options as
    :func:`~dobs_envs.envs.parallel_env.make_parallel_env` (truncation by ``max_cycles``/``horizon``, no TimeLimit)."""
    return CentralizedEnv(DObsParallelEnv(scenario=scenario, **options))


def reject_horizon_options(kwargs: dict) -> None:
    """``TypeError`` for ``max_cycles``/``horizon`` (the registered ids take ``max_episode_steps``)."""
    for k in ("max_cycles", "horizon"):
        if k in kwargs:
            raise TypeError(
                f"{k!r} is not an option of the registered Gymnasium environments: the episode length is "
                f"gym.make(..., max_episode_steps=N) (a TimeLimit wrapper, in control steps)"
            )


def _gym_entry(entry: EnvEntry):
    """The Gymnasium entry point ``make_<name>`` of a registry entry (no own truncation: ``TimeLimit`` only)."""
    def make(**kwargs):
        reject_horizon_options(kwargs)
        return CentralizedEnv(entry.load_class()(horizon=math.inf, **kwargs))

    make.__name__ = make.__qualname__ = f"make_{entry.name}"
    make.__doc__ = f"``gym.make({entry.gym_id!r})``: :class:`CentralizedEnv` over ``{entry.entry_point}``."
    return make


# make_tracking, make_disturbance_rejection, ...: the entry points of GYM_IDS
for _entry in ENVIRONMENTS.values():
    globals()[f"make_{_entry.name}"] = _gym_entry(_entry)
del _entry
