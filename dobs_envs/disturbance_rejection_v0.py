"""``disturbance_rejection_v0``: PettingZoo parallel environment (see :class:`dobs_envs.envs.DisturbanceRejectionEnv` for the spec).

``parallel_env(**kwargs)`` builds the ParallelEnv (``raw_env`` is its class, the
entry point of ``dobs_envs.registry.ENVIRONMENTS["disturbance_rejection"]``);
``env(**kwargs)`` is its AEC form (``pettingzoo.utils.parallel_to_aec``).
"""
from .envs.module_api import module_api

__all__ = ["parallel_env", "raw_env", "env"]

raw_env, parallel_env, env = module_api("disturbance_rejection")
