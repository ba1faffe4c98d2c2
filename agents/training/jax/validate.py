"""Validators of the jitted trainers' recipe values (:func:`.ppo.ppo_config`, :func:`.sac.offpolicy_fields`,
:func:`.td3.td3_config`): one place for each check, a ``ValueError`` naming the recipe key and what was expected.
Plain Python (no JAX)."""
from __future__ import annotations

import numpy as np

__all__ = ["pos_int", "non_negative_int", "number", "schedule", "float_dtype", "vec_normalize", "train_env_kwargs"]


def pos_int(name: str, value) -> int:
    """``value`` as an ``int`` if it is an integer >= 1 (``bool`` refused), else ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def non_negative_int(name: str, value) -> int:
    """``value`` as an ``int`` if it is an integer >= 0 (``bool`` refused), else ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    return int(value)


def number(name: str, value, low: float = 0.0) -> float:
    """``value`` as a ``float`` if it is a number >= ``low`` (``bool`` and NaN refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= low:
        raise ValueError(f"{name} must be a number >= {low:g}, got {value!r}")
    return float(value)


def schedule(name: str, value) -> tuple[float, bool]:
    """``(x, linear)`` of a constant or an ``lin_x`` string (rl-zoo3's schedules)."""
    if isinstance(value, str):
        if not value.startswith("lin_"):
            raise ValueError(f"{name} must be a number or 'lin_<number>', got {value!r}")
        try:
            return float(value[4:]), True
        except ValueError:
            raise ValueError(f"{name} must be a number or 'lin_<number>', got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number or 'lin_<number>', got {value!r}")
    return float(value), False


def float_dtype(dtype) -> str:
    """The environment's float type: ``"float32"`` or ``"float64"``."""
    if dtype not in ("float32", "float64"):
        raise ValueError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    return dtype


def vec_normalize(value, keys: tuple) -> dict:
    """The recipe's ``normalize`` as ``VecNormalize``'s arguments: ``True`` -> ``{}`` (its defaults), ``False`` /
    ``None`` -> no normalisation, a mapping of ``keys``."""
    if value is True:
        value = {}
    if value is False or value is None:
        value = {"norm_obs": False, "norm_reward": False}
    if not isinstance(value, dict):
        raise ValueError(f"normalize must be true/false or a mapping of VecNormalize arguments, got {value!r}")
    bad = sorted(set(value) - set(keys))
    if bad:
        raise ValueError(f"normalize keys {bad} are not implemented; supported: {list(keys)}")
    return value


def train_env_kwargs(value) -> dict:
    """The recipe's ``env_kwargs`` (training-only env options) as a new dict; the options the trainer sets
    (``normalized_actions``, ``dtype``) refused."""
    env_kwargs = dict(value or {})
    for k in ("normalized_actions", "dtype"):
        if k in env_kwargs:
            raise ValueError(f"env_kwargs may not set {k!r} (the trainer sets it: normalize_actions / dtype)")
    return env_kwargs
