"""Gymnasium view of the environments: one centralised agent.

:class:`CentralizedEnv` wraps a :class:`~dobs_envs.envs.base.DObsParallelEnv`
and shares its core (no per-step dict round trip):

- observation: the agents' local observations concatenated in agent order
  (``controller_0`` first), ``Box(float32)``; ``env.agent_observation_slices[k]``
  is agent ``k``'s part and ``env.observation_layout()`` names every component
  as ``"controller_k/<component>"``;
- action: all control inputs stacked, ``u = col(u^0, ..., u^{K-1})``,
  ``Box(-b, b, (m,), float32)`` with the parallel env's bounds
  (``env.agent_action_slices[k]`` is channel ``k``); out-of-range values are
  clipped, NaN/inf or a wrong shape raise ``ValueError`` (naming the agent
  whose channel holds the NaN);
- reward: the team reward; ``terminated`` as the parallel env; info:
  ``tracking_error``, ``estimation_errors`` (N,), ``gamma`` (N,), ``gamma_s`` (N,),
  and ``termination_reason`` when the episode terminated.

Registered ids (one per entry of :mod:`dobs_envs.registry`; ``gym.make`` adds a
``TimeLimit`` of ``max_episode_steps`` control steps, the default scenario's
``t_end`` over the default control period, and the wrapped environment then never
truncates by itself -- there is a single truncation mechanism):

=====================================  ============================  =================
id                                     parallel env                  max_episode_steps
=====================================  ============================  =================
``dobs_envs/Tracking-v0``              ``tracking_v0``               400 (20 s)
``dobs_envs/DisturbanceRejection-v0``  ``disturbance_rejection_v0``  400 (20 s)
``dobs_envs/HeteroMAS-v0``             ``hetero_mas_v0``             600 (30 s)
``dobs_envs/RandomNetwork-v0``         ``random_network_v0``         400 (20 s)
=====================================  ============================  =================

(seconds at the default control period 0.05 s; with other ``dt``/``substeps``
pass ``max_episode_steps=`` to ``gym.make``). ``max_cycles``/``horizon`` are
not accepted by ``gym.make``; :func:`make_gym_env` (any Scenario, no
``TimeLimit``) accepts them.
"""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .base import DObsParallelEnv
from .observation import clip_inplace

from ..registry import ENVIRONMENTS, GYM_IDS, EnvEntry

__all__ = ["CentralizedEnv", "make_gym_env", "GYM_IDS"] + [f"make_{name}" for name in ENVIRONMENTS]


class CentralizedEnv(gym.Env):
    """One centralised agent controlling every channel of a dobs_envs parallel environment (see module docstring)."""

    def __init__(self, parallel_env: DObsParallelEnv):
        if not isinstance(parallel_env, DObsParallelEnv):
            raise TypeError(f"CentralizedEnv wraps a DObsParallelEnv, got {type(parallel_env).__name__}")
        pe = parallel_env
        self.parallel_env = pe
        self.metadata = {"render_modes": list(pe.metadata["render_modes"]), "render_fps": pe.metadata["render_fps"],
                         "name": pe.metadata["name"]}
        self.render_mode = pe.render_mode
        self.agents = list(pe.possible_agents)
        lows, highs, sl, pos = [], [], [], 0
        for a in self.agents:
            sp = pe.observation_space(a)
            lows.append(sp.low); highs.append(sp.high)
            sl.append(slice(pos, pos + sp.shape[0])); pos += sp.shape[0]
        self.agent_observation_slices = tuple(sl)
        self.agent_action_slices = tuple(pe.channel_slices)
        self.observation_space = spaces.Box(np.concatenate(lows), np.concatenate(highs), dtype=pe.obs_dtype)
        b = pe.action_bound.astype(np.float32)
        self.action_space = spaces.Box(-b, b, dtype=np.float32)
        self._index = pe.layout.all_index
        self._m = pe.n_inputs

    # ------------------------------------------------------------------ API
    def observation_layout(self) -> dict:
        """``{"controller_k/<component>": slice}`` of the concatenated observation."""
        out = {}
        for a, s in zip(self.agents, self.agent_observation_slices):
            for c, cs in self.parallel_env.observation_layout(a).items():
                out[f"{a}/{c}"] = slice(s.start + cs.start, s.start + cs.stop)
        return out

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        pe = self.parallel_env
        pe._np_random = self.np_random  # one generator for the episode distribution
        if seed is not None:
            self.action_space.seed(int(seed))
        pe.reset(options=options)
        return pe._obs_all, self._info()

    def step(self, action):
        pe = self.parallel_env
        if pe._sim is None:
            raise RuntimeError("call reset() before step()")
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"action must be a numeric array of shape ({self._m},), got {action!r}") from None
        if a.shape != (self._m,):
            raise ValueError(f"action must have shape ({self._m},) (all agents' inputs stacked), got {a.shape}")
        u = pe._u0
        u[:] = a
        if not clip_inplace(u, pe._u_low, pe._u_high):
            bad = [ag for ag, s in zip(self.agents, self.agent_action_slices) if not np.isfinite(a[s]).all()]
            raise ValueError(f"action contains NaN or inf in the channel(s) of agent(s) {bad}")
        pe._advance()
        term = pe._terminated
        trunc = (not term) and pe.max_cycles is not None and pe._cycles >= pe.max_cycles
        info = self._info()
        if term:
            info["termination_reason"] = pe._reason
        return pe._obs_all, pe._reward, term, trunc, info

    def _info(self) -> dict:
        pe = self.parallel_env
        return {"tracking_error": pe._track_err, "estimation_errors": pe._est_err.copy(),
                "gamma": pe._sim.gamma[0].copy(), "gamma_s": pe._sim.gamma_s[0].copy(), **pe._shared_info()}

    def render(self):
        return self.parallel_env.render()

    def close(self):
        self.parallel_env.close()

    def state(self) -> np.ndarray:
        """The parallel env's global state (x, x_r, all estimates, v)."""
        return self.parallel_env.state()

    @property
    def scenario(self):
        return self.parallel_env.scenario

    @property
    def control_period(self) -> float:
        return self.parallel_env.control_period


def make_gym_env(scenario, **options) -> CentralizedEnv:
    """Centralised Gymnasium env for any Scenario (or YAML/JSON path); options as
    :func:`~dobs_envs.envs.base.make_parallel_env` (truncation by ``max_cycles``/``horizon``, no TimeLimit)."""
    return CentralizedEnv(DObsParallelEnv(scenario=scenario, **options))


def _gym_entry(entry: EnvEntry):
    """The Gymnasium entry point ``make_<name>`` of a registry entry (no own truncation: ``TimeLimit`` only)."""
    def make(**kwargs):
        for k in ("max_cycles", "horizon"):
            if k in kwargs:
                raise TypeError(
                    f"{k!r} is not an option of the registered Gymnasium environments: the episode length is "
                    f"gym.make(..., max_episode_steps=N) (a TimeLimit wrapper, in control steps)"
                )
        return CentralizedEnv(entry.load_class()(horizon=math.inf, **kwargs))

    make.__name__ = make.__qualname__ = f"make_{entry.name}"
    make.__doc__ = f"``gym.make({entry.gym_id!r})``: :class:`CentralizedEnv` over ``{entry.entry_point}``."
    return make


# make_tracking, make_disturbance_rejection, ...: the entry points of GYM_IDS
for _entry in ENVIRONMENTS.values():
    globals()[f"make_{_entry.name}"] = _gym_entry(_entry)
del _entry
