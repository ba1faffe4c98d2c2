"""Compatibility path: the subspace primitives live in :mod:`dobs_envs.linalg.subspaces`."""
from ..linalg.subspaces import *  # noqa: F401,F403
from ..linalg.subspaces import __all__  # noqa: F401
