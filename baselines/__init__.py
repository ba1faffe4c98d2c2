"""Analytic policies acting through the environment API.

- :mod:`baselines.paper`: the paper's separation-based controllers on batched simulation states
  (re-exported from :mod:`dobs_envs.control`, where the environments use them too).
- :mod:`baselines.policies`: those controllers as ``policy(observations) -> actions``.
- :mod:`baselines.references`: the full-state oracle, decentralised control without
  communication, zero input (same calling convention).
"""
from .references import Centralized, DecentralizedPolicy, OraclePolicy, ZeroInputPolicy

__all__ = ["OraclePolicy", "DecentralizedPolicy", "ZeroInputPolicy", "Centralized"]
