"""PettingZoo parallel environments and their centralised Gymnasium views.

- :class:`DObsParallelEnv` / :func:`make_parallel_env`: any Scenario (or YAML/JSON file);
- :class:`TrackingEnv` (``tracking_v0``), :class:`TrackingLossyEnv` (``tracking_lossy_v0``),
  :class:`DisturbanceRejectionEnv`
  (``disturbance_rejection_v0``), :class:`HeteroMASEnv` (``hetero_mas_v0``),
  :class:`RandomNetworkEnv` (``random_network_v0``);
- :class:`CentralizedEnv` / :func:`make_gym_env`: one agent, concatenated
  observations, stacked inputs (registered as ``dobs_envs/Tracking-v0`` ...);
- :class:`DObsVectorEnv`: ``B`` centralised copies as one Gymnasium ``VectorEnv``
  (``gym.make_vec("dobs_envs/Tracking-v0", num_envs=B)``);
- :class:`EnvCore`: the batched core all of them drive; :class:`EnvOptions`: the options.
"""
from .parallel_env import COMMON_OPTIONS, DObsParallelEnv, make_parallel_env
from .centralized import CentralizedEnv, make_gym_env
from .env_core import REASONS, EnvCore, StepResult
from .disturbance import DisturbanceRejectionEnv
from .hetero_mas import HeteroMASEnv
from .random_network import RandomNetworkEnv
from .options import EnvOptions, HeteroMASOptions, RandomNetworkOptions
from .tracking import TrackingEnv, TrackingLossyEnv
from .vector import DObsVectorEnv

__all__ = ["DObsParallelEnv", "make_parallel_env", "COMMON_OPTIONS", "CentralizedEnv", "make_gym_env",
           "TrackingEnv", "TrackingLossyEnv", "DisturbanceRejectionEnv", "HeteroMASEnv", "RandomNetworkEnv", "DObsVectorEnv", "EnvCore",
           "StepResult", "REASONS", "EnvOptions", "HeteroMASOptions", "RandomNetworkOptions"]
