"""Jitted trainers on the JAX environments (:mod:`dobs_envs.jax`; needs the ``jax`` extra).

- :mod:`.ppo`: PPO as one compiled function (PureJaxRL's structure, SB3's PPO + VecNormalize semantics);
- :mod:`.normalize`: VecNormalize's observation and reward normalisation as pure functions;
- :mod:`.policy`: SB3's MlpPolicy actor-critic in JAX and its numpy twin;
- :mod:`.export`: a trained policy as ``.npz`` + JSON and the plain numpy callable that loads it.
"""
from .ppo import HPARAMS, PPOConfig, make_env, make_train, ppo_config

__all__ = ["HPARAMS", "PPOConfig", "make_env", "make_train", "ppo_config"]
