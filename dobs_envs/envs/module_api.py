"""The PettingZoo module convention (``raw_env``, ``parallel_env``, ``env``) for a registered environment."""
from __future__ import annotations

from pettingzoo.utils import parallel_to_aec

from ..registry import get

__all__ = ["module_api"]


def module_api(name: str):
    """``(raw_env, parallel_env, env)`` of the PettingZoo-style module of registry entry ``name``.

    ``raw_env`` is the entry's ParallelEnv class (:attr:`dobs_envs.registry.EnvEntry.entry_point`);
    ``parallel_env(**kwargs)`` builds it (unknown keyword arguments raise
    ``TypeError`` listing the valid ones); ``env(**kwargs)`` is its AEC form
    (``pettingzoo.utils.parallel_to_aec``). ``parallel_env.__doc__`` carries the
    class docstring (the environment's spec).
    """
    raw_env = get(name).load_class()

    def parallel_env(**kwargs):
        return raw_env(**kwargs)

    def env(**kwargs):
        return parallel_to_aec(raw_env(**kwargs))

    parallel_env.__doc__ = (
        "The parallel environment; unknown keyword arguments raise ``TypeError`` listing the valid ones.\n\n"
        + (raw_env.__doc__ or "")
    )
    env.__doc__ = "AEC version (``parallel_to_aec`` of :func:`parallel_env`)."
    return raw_env, parallel_env, env
