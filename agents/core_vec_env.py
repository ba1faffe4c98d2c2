"""The documented import path of :class:`~agents.vecenv.batched_core.CoreVecEnv` (docs/integrations.md):
``from agents.core_vec_env import CoreVecEnv``. The class lives in :mod:`agents.vecenv.batched_core`."""
from .vecenv.batched_core import CoreVecEnv

__all__ = ["CoreVecEnv"]
