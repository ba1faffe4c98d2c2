"""Analytic policies acting through the environment API.

- :mod:`baselines.paper`: the paper's separation-based controllers on batched simulation states
  (re-exported from :mod:`dobs_envs.control`, where the environments use them too).
- :mod:`baselines.policies`: those controllers as ``policy(observations) -> actions``.
- :mod:`baselines.references`: the full-state oracle, decentralised control without
  communication, zero input (same calling convention).
- :mod:`baselines.pooled`: the centralised agent's information (every controller node's local
  observation pooled): Kalman filter + the task's paper law, and LQG on the task's cost.
"""
from .pooled import PooledKalmanPolicy, PooledLQGPolicy
from .references import Centralized, DecentralizedPolicy, OraclePolicy, ZeroInputPolicy

__all__ = ["OraclePolicy", "DecentralizedPolicy", "ZeroInputPolicy", "Centralized", "PooledKalmanPolicy",
           "PooledLQGPolicy"]
