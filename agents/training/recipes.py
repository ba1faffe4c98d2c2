"""Recipes: what a training run is made of, resolved from the hyperparameter files.

:func:`resolve_recipe` reads ``agents/config/hyperparams/<algo>.yaml``
(:func:`agents.config.hyperparam_files.load_hyperparams`, overrides merged) and :func:`recipe_from_hyperparams` splits
the merged hyperparameters of a run (the files', or a run's ``config.json`` ``hyperparams`` on resume) into a
:class:`Recipe`: the algorithm's constructor arguments as written and the keys only ``agents/`` acts on (environment
copies, budget, normalisation, hybrids, action noise).

A recipe is plain data in the files' vocabulary (``lin_`` schedules as strings, activation
functions as names): turning it into the arguments of the library that implements the algorithm
is :meth:`agents.training.algos.AlgoBackend.constructor_kwargs`.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from typing import Any

from ..config.envs import env_key, gym_id
from ..config.hyperparam_files import OFF_POLICY_ALGOS, HyperparamsError, load_hyperparams, read_hyperparams_file

__all__ = ["Recipe", "resolve_recipe", "recipe_from_hyperparams", "recipe_file_section", "merge_overrides", "EXTRA_KEYS"]

#: hyperparameter keys that are not constructor arguments of the algorithm (``agents/`` acts on them)
EXTRA_KEYS = ("n_envs", "n_timesteps", "policy", "normalize", "agent_id", "env_kwargs", "noise_type", "noise_std",
              "normalize_actions", "residual_scale", "bc")


@dataclass(frozen=True)
class Recipe:
    """What :func:`agents.training.train.train` derives from the hyperparameter files (and overrides) for one run.

    ``algo_kwargs``: the algorithm's constructor arguments as written (``lin_`` schedules
    as strings, ``policy_kwargs.activation_fn`` a name); ``normalize``: ``False`` or the
    ``VecNormalize`` arguments (``gamma`` included); ``train_env_kwargs``: the recipe's
    training-only env options; ``bc``: the warm start's ``{episodes, noise, epochs, lr}``
    (``bc`` variant); ``action_noise_sigma`` and ``action_noise_type``: the off-policy algorithms'
    action noise (``noise_std``, ``noise_type``; :func:`agents.training.algos.make_action_noise`), None without.
    """

    policy: str
    algo_kwargs: dict
    n_envs: int
    n_timesteps: int
    normalize: Any
    normalize_actions: bool
    agent_id: bool
    train_env_kwargs: dict
    residual_scale: float | None
    bc: dict | None
    action_noise_sigma: float | None
    hyperparams: dict
    action_noise_type: str | None = None

    def as_dict(self) -> dict:
        """Everything but the merged ``hyperparams`` (plain data)."""
        return {k: v for k, v in self.__dict__.items() if k != "hyperparams"}


def resolve_recipe(algo: str, env_name: str, *, multi_agent: bool = False, hybrid: str | None = None,
                   overrides: dict | None = None, trainer: str = "sb3") -> Recipe:
    """The :class:`Recipe` of ``algo`` on ``env_name`` (see :func:`agents.config.hyperparam_files.load_hyperparams`;
    ``trainer="jax"``: with the jitted trainer's sections)."""
    algo = algo.lower()
    hp = load_hyperparams(algo, env_name, multi_agent=multi_agent, overrides=overrides, variant=hybrid,
                          trainer=trainer)
    return recipe_from_hyperparams(algo, env_name, hp, multi_agent=multi_agent, hybrid=hybrid)


def recipe_from_hyperparams(algo: str, env_name: str, hp: dict, *, multi_agent: bool = False,
                            hybrid: str | None = None) -> Recipe:
    """The :class:`Recipe` of the merged hyperparameters ``hp`` (a run's ``config.json``
    ``hyperparams``, or :func:`agents.config.hyperparam_files.load_hyperparams`)."""
    residual_scale = None
    if hybrid == "residual":
        residual_scale = hp.get("residual_scale")
        if residual_scale is None:
            raise ValueError(f"the residual recipe of {algo} on {env_name!r} needs 'residual_scale' in the "
                             f"hyperparameters")
    norm = hp.get("normalize") or False
    if norm:
        norm = dict(norm) if isinstance(norm, dict) else {}
        norm.setdefault("gamma", hp.get("gamma", 0.99))
    bc = None
    if hybrid == "bc":
        b = dict(hp.get("bc") or {})
        bc = {"episodes": int(b.get("episodes", 20)), "noise": float(b.get("noise", 0.1)),
              "epochs": int(b.get("epochs", 30)), "lr": float(b.get("lr", 1e-3))}
    sigma = noise_type = None
    if hp.get("noise_type") and algo in OFF_POLICY_ALGOS:
        sigma, noise_type = float(hp.get("noise_std", 0.1)), str(hp["noise_type"])
    algo_kw = {k: v for k, v in hp.items() if k not in EXTRA_KEYS}
    algo_kw["policy_kwargs"] = dict(algo_kw.get("policy_kwargs") or {})
    return Recipe(policy=hp.get("policy", "MlpPolicy"), algo_kwargs=algo_kw, n_envs=int(hp.get("n_envs", 1)),
                  n_timesteps=int(hp.get("n_timesteps", 100000)), normalize=norm,
                  normalize_actions=bool(hp.get("normalize_actions", False)) and residual_scale is None,
                  agent_id=bool(hp.get("agent_id", False)) and multi_agent,
                  train_env_kwargs=dict(hp.get("env_kwargs") or {}), residual_scale=residual_scale, bc=bc,
                  action_noise_sigma=sigma, hyperparams=hp, action_noise_type=noise_type)


def recipe_file_section(path: str, env_name: str, *, multi_agent: bool = False, trainer: str = "sb3") -> dict:
    """The section of the recipe file ``path`` (rl-zoo3 format, e.g. ``dobs-envs tune``'s or a sweep's ``best.yml``)
    for ``env_name``: the agents-only section of the run's kind if the file has one (``<env>-ma-jax`` then
    ``<env>-ma`` for the jitted shared policy, ``<env>-ma`` for SB3's, ``<env>-jax`` for the jitted centralised
    agent; what ``python -m agents.tune.sweep --multi-agent`` writes), else what rl-zoo3 would read: its Gymnasium
    id's section, else ``default``. In :mod:`agents.config.hyperparam_files`'s vocabulary, validated by
    :func:`agents.config.hyperparam_files.read_hyperparams_file` (nothing named in it is imported). Used as
    hyperparameter overrides: a complete section replaces the env's recipe key by key.
    :class:`agents.config.hyperparam_files.HyperparamsError` names the file when no section applies."""
    if not os.path.isfile(path):
        raise HyperparamsError(f"recipe file {path!r} does not exist")
    table = read_hyperparams_file(path)
    key = env_key(env_name)
    own = ([f"{key}-ma-jax"] if multi_agent and trainer == "jax" else []) + ([f"{key}-ma"] if multi_agent else []) \
        + ([f"{key}-jax"] if trainer == "jax" and not multi_agent else [])
    names = own + [gym_id(key), "default"]
    for name in names:
        if name in table:
            return table[name]
    raise HyperparamsError(f"{path} has no section {' or '.join(map(repr, names))} for env {env_name!r}"
                           f"{' (shared policy)' if multi_agent else ''}; its sections: {sorted(map(str, table))}")


def merge_overrides(base: dict | None, over: dict | None) -> dict:
    """``over`` merged into a copy of ``base`` (nested mappings merged key by key, as
    :func:`agents.config.hyperparam_files.load_hyperparams` merges overrides into a recipe)."""
    out = copy.deepcopy(dict(base or {}))
    for k, v in (over or {}).items():
        out[k] = merge_overrides(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) \
            else copy.deepcopy(v)
    return out
