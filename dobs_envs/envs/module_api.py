"""The PettingZoo module convention (``parallel_env``, ``raw_env``, ``env``) for an env class."""
from __future__ import annotations

from pettingzoo.utils import parallel_to_aec

__all__ = ["module_api"]


def module_api(raw_env):
    """``(parallel_env, env)`` functions of a PettingZoo-style module for ``raw_env``.

    ``parallel_env(**kwargs)`` builds the ParallelEnv (unknown keyword arguments
    raise ``TypeError`` listing the valid ones); ``env(**kwargs)`` is its AEC form
    (``pettingzoo.utils.parallel_to_aec``). ``parallel_env.__doc__`` carries the
    class docstring (the environment's spec).
    """

    def parallel_env(**kwargs):
        return raw_env(**kwargs)

    def env(**kwargs):
        return parallel_to_aec(raw_env(**kwargs))

    parallel_env.__doc__ = (
        "The parallel environment; unknown keyword arguments raise ``TypeError`` listing the valid ones.\n\n"
        + (raw_env.__doc__ or "")
    )
    env.__doc__ = "AEC version (``parallel_to_aec`` of :func:`parallel_env`)."
    return parallel_env, env
