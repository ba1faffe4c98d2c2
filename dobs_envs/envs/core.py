"""Deprecated alias of :mod:`dobs_envs.envs.env_core` (the batched core's module until issue 23).

The README documented ``dobs_envs.envs.core.REASONS``; its names now live in
:mod:`dobs_envs.envs.env_core` (and ``EnvCore``, ``StepResult``, ``REASONS`` in :mod:`dobs_envs.envs`).
Every attribute read here warns with a ``DeprecationWarning`` and returns the one of ``env_core``
(``load_scenario`` is now ``resolve_scenario``).
"""
from __future__ import annotations

import warnings

from . import env_core as _env_core

_RENAMED = {"load_scenario": "resolve_scenario"}


def __getattr__(name: str):
    new = _RENAMED.get(name, name)
    if name.startswith("__") or not hasattr(_env_core, new):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"dobs_envs.envs.core is deprecated: use dobs_envs.envs.env_core.{new}"
                  + (" (or dobs_envs.envs)" if new in ("EnvCore", "StepResult", "REASONS") else ""),
                  DeprecationWarning, stacklevel=2)
    return getattr(_env_core, new)
