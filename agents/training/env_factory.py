"""The VecEnv a training run steps: :func:`build_vec_env` (and :func:`core_of`, the batched core
of a dobs_envs environment).

The dobs_envs environments train on :class:`agents.vecenv.batched_core.CoreVecEnv` (all copies in one
batched core, centralised or one slot per (copy, agent)); foreign Gymnasium ids, environment
constructors and the residual environments of :mod:`agents.training.hybrid` on SB3's ``DummyVecEnv``
(centralised) or :class:`agents.vecenv.parallel.ParallelVecEnv` (multi-agent). Normalisation
(``VecNormalize``) is added by :func:`agents.training.train.train`, not here.
"""
from __future__ import annotations

import math

import numpy as np

from dobs_envs.registry import get as registry_entry

from ..config.envs import ENVS, env_key, gym_factory, parallel_factory
from ..vecenv.batched_core import CoreVecEnv
from ..vecenv.parallel import ParallelVecEnv

__all__ = ["build_vec_env", "core_of"]


def build_vec_env(env, *, multi_agent: bool = False, n_envs: int = 1, seed: int | None = None,
                  env_kwargs: dict | None = None, agent_id: bool = False, normalize_actions: bool = False,
                  residual_scale: float | None = None):
    """Monitored VecEnv for training (not normalised).

    ``env`` is a name (see :mod:`agents.config.hyperparam_files`) or a constructor. The dobs_envs
    environments (by name) run as one batched core, :class:`agents.vecenv.batched_core.CoreVecEnv`
    + ``VecMonitor``: centralised (one slot per copy, episodes of the Gymnasium id's
    ``max_episode_steps`` unless ``max_cycles``/``horizon`` are given) or parameter-shared
    (one slot per (copy, agent)). Foreign Gymnasium ids and residual envs use ``DummyVecEnv``
    + ``Monitor`` (centralised) or :class:`ParallelVecEnv` + ``VecMonitor`` (multi-agent).
    ``normalize_actions``: the agent acts in ``[-1, 1]`` (Gymnasium's ``RescaleAction`` / the
    adapters' ``rescale_actions``). ``residual_scale``: the agent's action is a residual
    correction (:mod:`agents.training.hybrid`), already in ``[-1, 1]``.
    """
    from .hybrid import residual_factory

    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    core = core_of(env, n_envs, env_kwargs, multi_agent) if residual_scale is None else None
    if core is not None:
        venv = VecMonitor(CoreVecEnv(core, shared=multi_agent, agent_id=agent_id and multi_agent,
                                     rescale_actions=normalize_actions))
        if seed is not None:
            venv.seed(seed)
        return venv
    if multi_agent:
        fac = parallel_factory(env, env_kwargs)
        if residual_scale is not None:
            fac, normalize_actions = residual_factory(fac, residual_scale, parallel=True), False
        venv = VecMonitor(ParallelVecEnv([fac for _ in range(n_envs)], agent_id=agent_id,
                                         rescale_actions=normalize_actions))
        if seed is not None:
            venv.seed(seed)
        return venv
    if callable(env):
        fac = lambda: env(**(env_kwargs or {}))  # noqa: E731
    else:
        fac = gym_factory(env, env_kwargs)
    if residual_scale is not None:
        fac, normalize_actions = residual_factory(fac, residual_scale, parallel=False), False
    if normalize_actions:
        from gymnasium.wrappers import RescaleAction

        inner = fac
        fac = lambda: RescaleAction(inner(), np.float32(-1.0), np.float32(1.0))  # noqa: E731
    return make_vec_env(fac, n_envs=n_envs, seed=seed, vec_env_cls=DummyVecEnv)


def core_of(env, n_envs: int, env_kwargs: dict | None, multi_agent: bool):
    """The batched core of ``n_envs`` copies of the dobs_envs environment named ``env``
    (None for constructors and foreign ids). Centralised training keeps the registered
    Gymnasium id's episodes: truncation after ``max_episode_steps`` (or the given
    ``max_cycles``/``horizon``), the termination penalty charging the scenario's ``t_end``."""
    if not isinstance(env, str):
        return None
    names = {gid: name for name, (gid, _) in ENVS.items()}
    name = env_key(env) if env_key(env) in ENVS else names.get(env)
    if name is None:
        return None
    entry = registry_entry(name)
    kw = dict(env_kwargs or {})
    if multi_agent:
        return entry.load_class().make_core(n_envs, **kw)
    mc, hz = kw.pop("max_cycles", None), kw.pop("horizon", None)
    core = entry.load_class().make_core(n_envs, horizon=math.inf, **kw)
    if hz is not None:
        mc = max(1, int(round(float(hz) / core.control_period)))
    core.max_cycles = entry.max_episode_steps if mc is None else int(mc)
    return core
