"""Jitted trainers on the JAX environments (:mod:`dobs_envs.jax`; the ``jax`` extra).

- :mod:`.ppo`: PPO as one compiled function (PureJaxRL's structure, SB3's PPO + VecNormalize semantics):
  :func:`~.ppo.ppo_config` (a recipe's hyperparameters -> static config + vmappable float
  hyperparameters), :func:`~.ppo.make_train`;
- :mod:`.normalize`: VecNormalize's observation and reward normalisation as pure functions;
- :mod:`.policy`: SB3's MlpPolicy actor-critic in JAX;
- :mod:`.export`: a trained policy written as ``policy.npz`` + ``policy.json``;
- :mod:`.numpy_policy`: the plain numpy callable that loads it (numpy only: acting needs no JAX).

Importing this package imports nothing heavy; the names below load their module on first use.
"""
import importlib

_LAZY = {"HPARAMS": "ppo", "PPOConfig": "ppo", "make_env": "ppo", "make_train": "ppo", "ppo_config": "ppo",
         "save_policy": "export", "jax_act": "export", "select_run": "export", "NumpyPolicy": "numpy_policy"}

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
