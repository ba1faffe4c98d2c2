"""Observation and reward normalisation of SB3's ``VecNormalize``, as pure JAX functions.

Source: stable-baselines3 2.x, ``common/running_mean_std.py`` and ``common/vec_env/vec_normalize.py``.
A :class:`RunningMeanStd` holds the mean, the (population) variance and the count of a stream; a batch
``x (B, ...)`` with mean ``m_b``, variance ``v_b`` and count ``B`` updates it by the parallel algorithm
(Chan et al.)::

    delta = m_b - mean,  n = count + B
    mean' = mean + delta B / n
    var'  = (var count + v_b B + delta^2 count B / n) / n,  count' = n

starting from ``mean = 0, var = 1, count = 1e-4``. Per vector-env step, with ``gamma`` the
normaliser's discount and ``eps = 1e-8``:

- observations: update with the step's observations (those after the auto-reset where an episode
  ended), then ``clip((obs - mean) / sqrt(var + eps), -clip_obs, clip_obs)``;
- rewards: ``R <- gamma R + r`` per copy, update the return statistics with ``R``, then
  ``clip(r / sqrt(var_R + eps), -clip_reward, clip_reward)``, and ``R <- 0`` where the episode ended.
"""
from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

__all__ = ["RunningMeanStd", "NormState", "rms_init", "rms_update", "normalize_obs", "normalize_reward",
           "norm_init", "norm_step"]

#: ``RunningMeanStd``'s initial count (SB3's ``epsilon`` argument of RunningMeanStd)
RMS_EPSILON = 1e-4


class RunningMeanStd(NamedTuple):
    """Running mean, population variance and count of a stream (SB3's ``RunningMeanStd``)."""
    mean: jnp.ndarray
    var: jnp.ndarray
    count: jnp.ndarray


class NormState(NamedTuple):
    """``VecNormalize``'s state: observation statistics, return statistics, and the running
    discounted return ``returns (B,)`` of each copy."""
    obs_rms: RunningMeanStd
    ret_rms: RunningMeanStd
    returns: jnp.ndarray


def rms_init(shape: tuple, dtype) -> RunningMeanStd:
    """``mean = 0``, ``var = 1``, ``count = 1e-4`` (SB3's defaults)."""
    return RunningMeanStd(jnp.zeros(shape, dtype), jnp.ones(shape, dtype), jnp.asarray(RMS_EPSILON, dtype))


def rms_update(rms: RunningMeanStd, x: jnp.ndarray) -> RunningMeanStd:
    """The statistics after the batch ``x (B, ...)`` (batch axis first), as ``RunningMeanStd.update``."""
    x = x.astype(rms.mean.dtype)
    b_mean, b_var, b_count = x.mean(axis=0), x.var(axis=0), x.shape[0]
    delta = b_mean - rms.mean
    tot = rms.count + b_count
    mean = rms.mean + delta * b_count / tot
    m2 = rms.var * rms.count + b_var * b_count + delta ** 2 * rms.count * b_count / tot
    return RunningMeanStd(mean, m2 / tot, tot)


def normalize_obs(rms: RunningMeanStd, obs: jnp.ndarray, clip_obs, epsilon) -> jnp.ndarray:
    """``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)`` in the statistics' dtype."""
    z = (obs.astype(rms.mean.dtype) - rms.mean) / jnp.sqrt(rms.var + epsilon)
    return jnp.clip(z, -clip_obs, clip_obs)


def normalize_reward(rms: RunningMeanStd, reward: jnp.ndarray, clip_reward, epsilon) -> jnp.ndarray:
    """``clip(reward / sqrt(var_R + epsilon), -clip_reward, clip_reward)`` (no centring, as SB3)."""
    return jnp.clip(reward.astype(rms.var.dtype) / jnp.sqrt(rms.var + epsilon), -clip_reward, clip_reward)


def norm_init(obs_shape: tuple, n_envs: int, dtype) -> NormState:
    """The state of a new ``VecNormalize`` over ``n_envs`` copies with observations of ``obs_shape``."""
    return NormState(rms_init(obs_shape, dtype), rms_init((), dtype), jnp.zeros((n_envs,), dtype))


def norm_step(state: NormState, obs, reward, done, *, gamma, clip_obs, clip_reward, epsilon,
              norm_obs: bool = True, norm_reward: bool = True):
    """One ``VecNormalize.step_wait`` (training mode): ``(state', normalised obs, normalised reward)``.

    ``obs (B, D)``: the step's observations (after auto-reset); ``reward (B,)``, ``done (B,)``.
    ``norm_obs`` / ``norm_reward`` (static) switch the parts off as VecNormalize's flags do (the
    quantity is then passed through unchanged)."""
    obs_rms, ret_rms, returns = state
    if norm_obs:
        obs_rms = rms_update(obs_rms, obs)
        obs_n = normalize_obs(obs_rms, obs, clip_obs, epsilon)
    else:
        obs_n = obs.astype(obs_rms.mean.dtype)
    if norm_reward:
        returns = returns * gamma + reward.astype(returns.dtype)
        ret_rms = rms_update(ret_rms, returns)
        rew_n = normalize_reward(ret_rms, reward, clip_reward, epsilon)
    else:
        rew_n = reward.astype(returns.dtype)
    returns = jnp.where(done, jnp.zeros_like(returns), returns)
    return NormState(obs_rms, ret_rms, returns), obs_n, rew_n
