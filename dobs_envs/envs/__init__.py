"""PettingZoo parallel environments and their centralised Gymnasium views.

- :class:`DObsParallelEnv` / :func:`make_parallel_env`: any Scenario (or YAML/JSON file);
- :class:`TrackingEnv` (``tracking_v0``), :class:`DisturbanceRejectionEnv`
  (``disturbance_rejection_v0``), :class:`HeteroMASEnv` (``hetero_mas_v0``),
  :class:`RandomNetworkEnv` (``random_network_v0``);
- :class:`CentralizedEnv` / :func:`make_gym_env`: one agent, concatenated
  observations, stacked inputs (registered as ``dobs_envs/Tracking-v0`` ...).
"""
from .base import COMMON_OPTIONS, DObsParallelEnv, make_parallel_env
from .centralized import CentralizedEnv, make_gym_env
from .disturbance import DisturbanceRejectionEnv
from .hetero_mas import HeteroMASEnv
from .random_network import RandomNetworkEnv
from .tracking import TrackingEnv

__all__ = ["DObsParallelEnv", "make_parallel_env", "COMMON_OPTIONS", "CentralizedEnv", "make_gym_env",
           "TrackingEnv", "DisturbanceRejectionEnv", "HeteroMASEnv", "RandomNetworkEnv"]
