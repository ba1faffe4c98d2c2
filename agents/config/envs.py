"""Environment names and their constructors: the benchmark's short names, Gymnasium ids and PettingZoo
modules (:mod:`dobs_envs.registry`), name validation, and the env factories training and evaluation use.

``tracking``, ``tracking_lossy``, ``disturbance_rejection``, ``hetero_mas``, ``random_network`` (the
registry) map to the centralised Gymnasium ids ``dobs_envs/<Name>-v0`` and to the
PettingZoo modules ``dobs_envs.<name>_v0`` (multi-agent); ``tracking_lossy`` is ``tracking`` with communication
faults (:data:`FAULT_FREE`). Any other Gymnasium id (e.g. ``Pendulum-v1``)
works for centralised training; ``"package.module:factory"`` names a ParallelEnv
factory for multi-agent training (accepted only when asked for, :func:`check_env_name`).
"""
from __future__ import annotations

import importlib
from typing import Any, Callable

from dobs_envs.registry import ENVIRONMENTS as _REGISTRY

__all__ = ["ENVS", "FAULT_FREE", "TASKS", "env_key", "check_env_name", "EnvNameError", "gym_id", "gym_factory",
           "parallel_factory"]

#: benchmark environments: short name -> (Gymnasium id, PettingZoo module), from dobs_envs.registry
ENVS = {name: (e.gym_id, e.module) for name, e in _REGISTRY.items()}
#: environments with communication faults on by default -> their fault-free counterpart (the same task with
#: ``faults=None``; :attr:`dobs_envs.registry.EnvEntry.fault_free`), e.g. ``{"tracking_lossy": "tracking"}``
FAULT_FREE = {name: e.fault_free for name, e in _REGISTRY.items() if e.fault_free is not None}
#: the fault-free tasks, in registry order: what the benchmark's ``--env all`` runs (a faulted variant is the
#: same task again, run by its name; :mod:`agents.benchmark`)
TASKS = tuple(name for name in ENVS if name not in FAULT_FREE)


def env_key(env: str) -> str:
    """Normalised short name (``hetero-mas`` -> ``hetero_mas``) or the name unchanged."""
    k = env.replace("-", "_").lower()
    return k if k in ENVS else env


class EnvNameError(ValueError):
    """An environment name that is neither registered nor explicitly allowed."""


def check_env_name(env, *, multi_agent: bool = False, allow_custom: bool = False, what: str = "env") -> str:
    """Validate an environment name *before* anything is imported or built.

    Accepted: a benchmark name (:data:`ENVS`), or (centralised) an id already registered in
    Gymnasium's registry without a module prefix. ``"package.module:factory"`` (or a
    Gymnasium ``"module:Env-v0"`` id, which ``gym.make`` imports) names code to import: it
    is accepted only with ``allow_custom=True`` (the CLI's ``--allow-custom-env``), never
    implicitly from a file such as a run directory's ``config.json``.
    """
    if not isinstance(env, str) or not env:
        raise EnvNameError(f"{what} must be a non-empty string, got {env!r}")
    if env_key(env) in ENVS:
        return env_key(env)
    if ":" in env:
        if allow_custom:
            return env
        raise EnvNameError(f"{what} {env!r} names code to import; only the registered environments {sorted(ENVS)} "
                           f"are accepted unless you pass --allow-custom-env (allow_custom=True)")
    if not multi_agent:
        import gymnasium as gym

        import dobs_envs  # noqa: F401  (registers dobs_envs/* ids)

        if env in gym.registry:
            return env
    raise EnvNameError(f"unknown {what} {env!r}; choose from {sorted(ENVS)}"
                       + ("" if multi_agent else " or a registered Gymnasium id (e.g. Pendulum-v1)"))


def gym_id(env: str) -> str:
    k = env_key(env)
    if k in ENVS:
        return ENVS[k][0]
    return env


def gym_factory(env: str, env_kwargs: dict | None = None) -> Callable[[], Any]:
    """Factory of the centralised Gymnasium env (registers dobs_envs' ids first)."""
    import gymnasium as gym

    import dobs_envs  # noqa: F401  (registers dobs_envs/* ids)

    gid = gym_id(env)
    kw = dict(env_kwargs or {})
    if gid.startswith("dobs_envs/"):
        # the registered ids take the episode length as a TimeLimit (max_episode_steps);
        # translate the parallel envs' max_cycles / horizon so both views have the same episodes
        mc, hz = kw.pop("max_cycles", None), kw.pop("horizon", None)
        if hz is not None:
            period = float(kw.get("dt", 1e-3)) * int(kw.get("substeps", 50))
            mc = max(1, int(round(float(hz) / period)))
        if mc is not None:
            kw["max_episode_steps"] = int(mc)
    return lambda: gym.make(gid, **kw)


def _parallel_ctor(env: str) -> Callable[..., Any]:
    k = env_key(env)
    if k in ENVS:
        mod = importlib.import_module(ENVS[k][1])
        for name in ("parallel_env", "env"):
            fn = getattr(mod, name, None)
            if callable(fn):
                return fn
        raise AttributeError(f"{ENVS[k][1]} has no parallel_env() constructor")
    if ":" in env:
        mod_name, attr = env.split(":", 1)
        return getattr(importlib.import_module(mod_name), attr)
    raise ValueError(f"no PettingZoo environment named {env!r}; choose from {sorted(ENVS)} or 'module:factory'")


def parallel_factory(env: str | Callable[..., Any], env_kwargs: dict | None = None) -> Callable[[], Any]:
    """Factory of the PettingZoo parallel env ``env`` (name or constructor)."""
    ctor = env if callable(env) else _parallel_ctor(env)
    kw = dict(env_kwargs or {})
    return lambda: ctor(**kw)
