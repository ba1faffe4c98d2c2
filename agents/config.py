"""Environment names and rl-zoo3-style hyperparameters (``agents/hyperparams/<algo>.yaml``).

Environment names
-----------------
``tracking``, ``disturbance_rejection``, ``hetero_mas``, ``random_network`` map to the
centralised Gymnasium ids ``dobs_envs/<Name>-v0`` and to the PettingZoo modules
``dobs_envs.<name>_v0`` (multi-agent). Any other Gymnasium id (e.g. ``Pendulum-v1``)
works for centralised training; ``"package.module:factory"`` names a ParallelEnv
factory for multi-agent training.

Hyperparameter files
--------------------
One YAML file per algorithm, keyed by environment name. Lookup (later entries
override earlier ones): ``default``, then ``default-ma`` (multi-agent only), then
``<env>``, then ``<env>-ma`` (multi-agent only); hybrids (``variant``) then add
``default-<variant>``, ``<env>-<variant>`` and ``<env>-ma-<variant>`` (multi-agent).
Keys besides the algorithm's
constructor arguments:

- ``n_envs``: environment copies (multi-agent: copies; each has one slot per agent)
- ``n_timesteps``: default training budget
- ``policy``: SB3 policy name (``MlpPolicy``)
- ``normalize``: ``false`` or a dict of ``VecNormalize`` arguments
  (``norm_obs``, ``norm_reward``, ``clip_obs``, ...; ``gamma`` defaults to the algorithm's)
- ``agent_id``: (multi-agent) append a one-hot agent id to observations
- ``env_kwargs``: training-only environment options of the recipe (e.g. a tighter
  ``state_bound``); evaluation always uses the task's own environment
- ``residual_scale`` (``-residual`` variants): residual authority, fraction of the action bound
- ``bc`` (``-bc`` variants): ``{episodes, noise, epochs, lr}`` of the warm start
- ``policy_kwargs.activation_fn``: a name (``tanh``, ``relu``, ``elu``)
- ``action_noise`` (TD3/SAC): ``{type: normal, sigma: 0.1}``
"""
from __future__ import annotations

import copy
import importlib
import os
from typing import Any, Callable

import yaml

__all__ = ["ENVS", "ALGOS", "HYPERPARAMS_DIR", "gym_id", "parallel_factory", "gym_factory",
           "load_hyperparams", "env_key", "check_env_name", "EnvNameError"]

HYPERPARAMS_DIR = os.path.join(os.path.dirname(__file__), "hyperparams")

from dobs_envs.registry import ENVIRONMENTS as _REGISTRY  # noqa: E402

#: benchmark environments: short name -> (Gymnasium id, PettingZoo module), from dobs_envs.registry
ENVS = {name: (e.gym_id, e.module) for name, e in _REGISTRY.items()}

ALGOS = ("ppo", "sac", "td3")
MULTI_AGENT_ALGOS = ("ppo", "sac")


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


def _load_yaml(algo: str) -> dict:
    path = os.path.join(HYPERPARAMS_DIR, f"{algo}.yaml")
    if not os.path.exists(path):
        raise ValueError(f"no hyperparameter file for algorithm {algo!r} ({path}); algorithms: {ALGOS}")
    with open(path) as fh:
        return yaml.safe_load(fh) or {}


def _merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in (over or {}).items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def load_hyperparams(algo: str, env: str, *, multi_agent: bool = False, overrides: dict | None = None,
                     variant: str | None = None) -> dict:
    """Merged hyperparameters of ``algo`` on ``env`` (see module doc for the lookup)."""
    algo = algo.lower()
    table = _load_yaml(algo)
    name = env_key(env) if isinstance(env, str) else "default"
    keys = ["default"] + (["default-ma"] if multi_agent else []) + [name] + ([f"{name}-ma"] if multi_agent else [])
    if variant:
        keys += [f"default-{variant}", f"{name}-{variant}"] + ([f"{name}-ma-{variant}"] if multi_agent else [])
    hp: dict = {}
    for k in keys:
        if k in table:
            hp = _merge(hp, table[k])
    return _merge(hp, overrides or {})
