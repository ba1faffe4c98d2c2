"""Adapters of the JAX environments to the interfaces of trainers written for older gymnax.

gymnax 1.0 (the interface of :class:`~dobs_envs.jax.env.DObsEnv`) returns ``(obs, state, reward,
terminated, truncated, info)`` from ``step``; gymnax 0.0.x, which PureJaxRL and rejax 0.1 are written
for, returns ``(obs, state, reward, done, info)``. :class:`DoneStepWrapper` gives the latter:
``done = terminated or truncated``, with ``info["terminated"]``, ``info["truncated"]`` and
``info["final_observation"]`` kept, so that a trainer can still bootstrap truncated episodes.
Everything else (``reset``, the spaces, ``default_params``, ``name``) is the wrapped environment's.
"""
from __future__ import annotations

from functools import partial

import jax

__all__ = ["DoneStepWrapper"]


class DoneStepWrapper:
    """``step -> (obs, state, reward, done, info)`` (gymnax 0.0.x) over a gymnax-1.0-style environment."""

    def __init__(self, env):
        self._env = env

    def __getattr__(self, name):
        if name.startswith("__") or name == "_env":  # copy/pickle probe the instance before __init__ ran
            raise AttributeError(name)
        return getattr(self._env, name)

    def __repr__(self) -> str:
        return f"DoneStepWrapper({self._env!r})"

    @property
    def unwrapped(self):
        return getattr(self._env, "unwrapped", self._env)

    @partial(jax.jit, static_argnames=("self",))
    def step(self, key, state, action, params=None):
        obs, state, reward, terminated, truncated, info = self._env.step(key, state, action, params)
        return obs, state, reward, terminated | truncated, info

    def reset(self, key, params=None):
        return self._env.reset(key, params)
