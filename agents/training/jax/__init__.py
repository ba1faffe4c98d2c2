"""Jitted trainers on the JAX environments (:mod:`dobs_envs.jax`; the ``jax`` extra).

- :mod:`.ppo`: PPO as one compiled function (PureJaxRL's structure, SB3's PPO + VecNormalize semantics):
  :func:`~.ppo.ppo_config` (a recipe's hyperparameters -> static config + vmappable float
  hyperparameters), :func:`~.ppo.make_train`;
- :mod:`.sac`: SAC as one compiled function (SBX's SAC + SB3's off-policy loop + VecNormalize):
  :func:`~.sac.sac_config`, :func:`~.sac.make_train` (replay ring buffer in the scan carry);
- :mod:`.td3`: TD3 (SBX's) in the same off-policy loop: :func:`~.td3.td3_config`, :func:`~.td3.make_train`;
- :mod:`.validate`: the recipe readers' validators (plain Python);
- :mod:`.envs`: the JAX environment of a run's configuration (:func:`~.envs.make_env`, every algorithm's);
- :mod:`.normalize`: VecNormalize's observation and reward normalisation as pure functions;
- :mod:`.policy`: SB3's MlpPolicy actor-critic in JAX (PPO);
- :mod:`.export`: a trained policy written as ``policy.npz`` + ``policy.json``;
- :mod:`.numpy_policy`: the plain numpy callable that loads it (numpy only: acting needs no JAX);
- :mod:`.run`: ``dobs-envs train --trainer jax [--algo ppo | sac | td3]``: a run directory of a jitted run
  (:func:`~.run.train_jax`).
- :mod:`.ippo`: PPO with one policy shared by the controller nodes on the multi-agent view (IPPO, parameter
  sharing: :func:`~.ippo.make_train` over :mod:`.ppo`'s trainer, one slot per (copy, agent));
- :mod:`.run_marl`: ``dobs-envs train --trainer jax --multi-agent`` (:func:`~.run_marl.train_jax_marl`).

Importing this package imports nothing heavy; the names below load their module on first use. If JAX has not
started yet, it adds ``--xla_cpu_enable_concurrency_optimized_scheduler=false`` to ``XLA_FLAGS``
(:func:`agents.training.xla.xla_safe_flags`: without it a vmapped trainer deadlocks in most runs on a
multi-threaded XLA CPU client with jaxlib 0.10; the module :mod:`agents.training.xla` says how that was measured).
"""
import importlib

from ..xla import xla_safe_flags

xla_safe_flags()

#: ``config.json`` ``trainer`` of a jitted run (``dobs-envs train --trainer jax``; SB3 runs record none)
TRAINER = "jax"
#: ``config.json`` ``library`` of a jitted run: the trainer's package
LIBRARY = "agents.training.jax"
#: the algorithms the jitted trainer implements
ALGOS = ("ppo", "sac", "td3")
#: the exported policy's files in a run directory (:mod:`.export`, :mod:`.numpy_policy`)
POLICY_FILES = ("policy.npz", "policy.json")

_LAZY = {"HPARAMS": "ppo", "PPOConfig": "ppo", "make_env": "ppo", "make_train": "ppo", "ppo_config": "ppo",
         "SACConfig": "sac", "sac_config": "sac", "TD3Config": "td3", "td3_config": "td3",
         "save_policy": "export", "jax_act": "export", "select_run": "export", "policy_arrays": "export",
         "NumpyPolicy": "numpy_policy", "train_jax": "run", "IPPOConfig": "ippo", "ippo_config": "ippo",
         "train_jax_marl": "run_marl"}

__all__ = sorted(_LAZY) + ["TRAINER", "LIBRARY", "ALGOS", "POLICY_FILES"]


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
