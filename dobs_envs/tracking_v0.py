"""``tracking_v0``: PettingZoo parallel environment (see :class:`dobs_envs.envs.TrackingEnv` for the spec).

``parallel_env(**kwargs)`` builds the ParallelEnv (``raw_env`` is its class);
``env(**kwargs)`` is its AEC form (``pettingzoo.utils.parallel_to_aec``).
"""
from pettingzoo.utils import parallel_to_aec

from .envs import TrackingEnv as raw_env

__all__ = ["parallel_env", "raw_env", "env"]


def parallel_env(**kwargs) -> raw_env:
    """The parallel environment; unknown keyword arguments raise ``TypeError`` listing the valid ones."""
    return raw_env(**kwargs)


def env(**kwargs):
    """AEC version (``parallel_to_aec`` of :func:`parallel_env`)."""
    return parallel_to_aec(parallel_env(**kwargs))


parallel_env.__doc__ = (parallel_env.__doc__ or "") + "\n\n" + (raw_env.__doc__ or "")
