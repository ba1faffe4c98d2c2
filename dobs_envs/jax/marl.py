"""The multi-agent view in JAX, with JaxMARL's ``MultiAgentEnv`` interface: the PettingZoo environments.

``dobs_envs.jax.make_marl("tracking_v0")`` is the JAX form of ``dobs_envs.tracking_v0.parallel_env()``:
the agents are the controller nodes ``controller_k``, each acting on its channel ``u^k`` from its
local observation (the paper's information pattern). The interface is JaxMARL's:

======================================================  ==============================================
``env.reset(key)``                                      ``(obs, state)``, ``obs = {agent: (w_k,)}``
``env.step(key, state, actions)``                       ``(obs, state, rewards, dones, infos)``,
                                                        ``dones["__all__"]``; auto-reset when it is set
``env.agents``, ``env.num_agents``                      the agents' names and number
``env.observation_space(agent)``, ``action_space(agent)``  per-agent ``Box`` (as the PettingZoo env's)
======================================================  ==============================================

Every agent receives the team reward. ``dones[agent]`` is ``terminated or truncated`` (truncation
after ``max_steps_in_episode`` control steps). The infos are arrays over the agents, agent-major
(JaxMARL's scripts reshape them to one row per actor): ``estimation_error`` (of the agent's linked
observer node), ``tracking_error``, ``gamma``, ``gamma_s``, the task error if the task has one, and
``termination_reason``. The environment holds its parameters (JaxMARL's convention);
``env.params`` is the :class:`~dobs_envs.jax.params.EnvParams`, and the pure functions of
:mod:`dobs_envs.jax.core` take others.
"""
from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..envs.adapter import agent_spaces
from ..registry import ENVIRONMENTS
from . import core as _core
from .env import _build
from .faults import received_fraction
from .params import EnvParams, EnvState, Structure
from .spaces import Box

__all__ = ["DObsMultiAgentEnv", "make_marl"]


class DObsMultiAgentEnv:
    """A dobs_envs PettingZoo environment as a JaxMARL ``MultiAgentEnv`` (module doc). Build it with
    :func:`make_marl`."""

    def __init__(self, name: str, structure: Structure, params: EnvParams, core):
        self._name = name
        self.structure = st = structure
        self.params = params
        self.core = core
        self.agents = list(st.agents)
        self.num_agents = len(self.agents)
        obs_sp, act_sp = agent_spaces(core)
        self.observation_spaces = {a: Box(s.low, s.high, s.shape, s.dtype) for a, s in zip(self.agents, obs_sp)}
        self.action_spaces = {a: Box(s.low, s.high, s.shape, jnp.float32) for a, s in zip(self.agents, act_sp)}
        self._links = np.asarray(st.links, dtype=np.intp)

    @property
    def name(self) -> str:
        return self._name

    def __repr__(self) -> str:
        return f"DObsMultiAgentEnv({self._name!r}, dtype={self.structure.dtype.name})"

    def observation_space(self, agent: str) -> Box:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> Box:
        return self.action_spaces[agent]

    @property
    def agent_classes(self) -> dict:
        """One class: every agent is a controller node."""
        return {"controller": list(self.agents)}

    # ------------------------------------------------------------------ JaxMARL interface
    @partial(jax.jit, static_argnums=(0,))
    def reset(self, key: jax.Array):
        state = _core.reset(key, self.params, self.structure)
        return self.get_obs(state), state

    @partial(jax.jit, static_argnums=(0,))
    def step(self, key: jax.Array, state: EnvState, actions: dict, reset_state: EnvState | None = None):
        """One control step with auto-reset (to ``reset_state`` if given, else a new draw)."""
        key, key_reset = jax.random.split(key)
        obs_st, state_st, rewards, dones, infos = self.step_env(key, state, actions)
        if reset_state is None:
            obs_re, state_re = self.reset(key_reset)
        else:
            state_re, obs_re = reset_state, self.get_obs(reset_state)
        done = dones["__all__"]
        state = jax.tree.map(lambda r, s: jax.lax.select(done, r, s), state_re, state_st)
        obs = jax.tree.map(lambda r, s: jax.lax.select(done, r, s), obs_re, obs_st)
        return obs, state, rewards, dones, infos

    def step_env(self, key: jax.Array, state: EnvState, actions: dict):
        """The step without auto-reset: ``(obs, state, rewards, dones, infos)``."""
        del key
        u = self.inputs(actions)
        state, out = _core.advance(state, u, self.params, self.structure)
        obs = self._split(out.obs)
        done = out.terminated | out.truncated
        rewards = {a: out.reward for a in self.agents}
        dones = {a: done for a in self.agents}
        dones["__all__"] = done
        return obs, state, rewards, dones, self._infos(state, out.features, out.reason)

    def get_obs(self, state: EnvState) -> dict:
        return self._split(_core.observations(_core.features(state, self.params, self.structure), self.structure))

    # ------------------------------------------------------------------ conversions
    def inputs(self, actions: dict) -> jax.Array:
        """The inputs ``u (m,)`` of the agents' actions (each ``(w_k,)``; ``normalized_actions``: scaled by
        the bounds, the padding entries ignored)."""
        st = self.structure
        if not isinstance(actions, dict) or set(actions) != set(self.agents):
            got = sorted(actions) if isinstance(actions, dict) else type(actions).__name__
            raise ValueError(f"actions must be a dict with one action per agent {self.agents}, got {got}")
        parts = []
        for a, w in zip(self.agents, st.action_widths):
            x = jnp.asarray(actions[a])
            if x.shape != (w,):
                raise ValueError(f"action of agent {a!r} must have shape ({w},), got {x.shape}")
            parts.append(x.astype(st.dtype))
        flat = jnp.concatenate(parts)
        if st.normalized_actions:
            return flat[st.action_gather] * self.params.action_scale
        return flat

    def _split(self, padded: jax.Array) -> dict:
        return {a: padded[k, :w] for k, (a, w) in enumerate(zip(self.agents, self.structure.obs_widths))}

    def _infos(self, state: EnvState, feat, reason) -> dict:
        st, K = self.structure, self.num_agents
        info = {"estimation_error": feat.estimation_errors[self._links],
                "tracking_error": jnp.broadcast_to(feat.tracking_error, (K,)),
                "gamma": state.gamma[self._links], "gamma_s": state.gamma_s[self._links]}
        if st.task_positions is not None:
            info[st.task_error_key] = jnp.broadcast_to(_core.task_error(state, st), (K,))
        if st.faults is not None:  # as the PettingZoo env's co_received / oo_received_fraction
            info["co_received"] = feat.received.co_rx
            info["oo_received_fraction"] = received_fraction(st.faults, feat.received.oo_rx)
        info["termination_reason"] = jnp.broadcast_to(reason, (K,))
        return info


def make_marl(env_name: str, **options) -> DObsMultiAgentEnv:
    """The multi-agent view of a registered environment, as ``jaxmarl.make``.

    ``env_name``: a PettingZoo module name (``"tracking_v0"``, ...) or a short name (``"tracking"``);
    ``options``: those of :func:`dobs_envs.jax.make` (the environment's options, ``max_episode_steps``,
    ``dtype``, ``sparse``).
    """
    entries = {e.module.rsplit(".", 1)[-1]: e for e in ENVIRONMENTS.values()}
    entries.update(ENVIRONMENTS)
    if not isinstance(env_name, str) or env_name not in entries:
        raise ValueError(f"unknown environment {env_name!r}; registered names are "
                         f"{sorted(e.module.rsplit('.', 1)[-1] for e in ENVIRONMENTS.values())}")
    entry = entries[env_name]
    structure, params, core = _build(entry, dict(options))
    return DObsMultiAgentEnv(entry.module.rsplit(".", 1)[-1], structure, params, core)
