"""The environments of dobs_envs in JAX: pure functions that ``jax.jit``, ``jax.vmap`` and ``lax.scan``.

Needs the ``jax`` extra (``pip install 'dobs-envs[jax]'``); ``import dobs_envs`` never imports JAX.

- :func:`make` ``(env_id, **options) -> (env, params)``: the centralised view of a Gymnasium id with
  gymnax's interface (:mod:`dobs_envs.jax.env`).
- :func:`make_marl` ``(name, **options) -> env``: the multi-agent view of a PettingZoo environment with
  JaxMARL's interface (:mod:`dobs_envs.jax.marl`).
- :mod:`dobs_envs.jax.core`: the step and reset of one copy as pure functions; :mod:`dobs_envs.jax.dynamics`:
  the control period (the numpy reference :mod:`dobs_envs.sim.numpy_step` is the specification).

float64 needs ``jax.config.update("jax_enable_x64", True)`` before any array is created; without it
the environments run in float32 (``make(..., dtype=...)`` chooses explicitly). Communication faults
(``faults=``, ``dobs_envs/TrackingLossy-v0``; :mod:`dobs_envs.jax.faults`) need 64-bit JAX in any dtype.
"""
from .env import DObsEnv, make, registered_envs
from .marl import DObsMultiAgentEnv, make_marl
from .params import EnvParams, EnvState, Structure
from .spaces import Box

__all__ = ["make", "make_marl", "registered_envs", "DObsEnv", "DObsMultiAgentEnv", "EnvParams", "EnvState", "Structure", "Box"]
