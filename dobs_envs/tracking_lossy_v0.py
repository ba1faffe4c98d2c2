"""``tracking_lossy_v0``: PettingZoo parallel environment (see :class:`dobs_envs.envs.tracking.TrackingLossyEnv`
for the spec): ``tracking_v0`` with communication faults and sensor noise on by default.

``parallel_env(**kwargs)`` builds the ParallelEnv (``raw_env`` is its class, the
entry point of ``dobs_envs.registry.ENVIRONMENTS["tracking_lossy"]``);
``env(**kwargs)`` is its AEC form (``pettingzoo.utils.parallel_to_aec``).
"""
from .envs.module_api import module_api

__all__ = ["parallel_env", "raw_env", "env"]

raw_env, parallel_env, env = module_api("tracking_lossy")
