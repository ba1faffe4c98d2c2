"""The JAX environment a jitted run trains on (the same for every algorithm)."""
from __future__ import annotations

__all__ = ["make_env"]


def make_env(cfg):
    """``(env, env_params)``: :func:`dobs_envs.jax.make` of the run's id with its training options; ``cfg`` any
    run configuration (:class:`~.ppo.PPOConfig`, :class:`~.sac.SACConfig`, :class:`~.td3.TD3Config`): its
    ``env_id``, ``normalize_actions``, ``dtype`` and ``env_kwargs``."""
    from dobs_envs.jax import make

    return make(cfg.env_id, normalized_actions=cfg.normalize_actions, dtype=cfg.dtype, **cfg.env_kwargs)
