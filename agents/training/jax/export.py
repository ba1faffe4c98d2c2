"""Writing a jitted run's trained policy (PPO or SAC) as plain files (``policy.npz`` + ``policy.json``, no pickle).

:func:`save_policy` writes what :class:`agents.training.jax.numpy_policy.NumpyPolicy` loads (the map
from observations to inputs is stated there); :func:`jax_act` is the same map in JAX on the trainer's
output, the reference the exported callable is tested against.
"""
from __future__ import annotations

import json
import os
from importlib import metadata

import jax
import jax.numpy as jnp
import numpy as np

from . import normalize as nz
from . import policy as pol
from .numpy_policy import _FILES, FORMAT, NumpyPolicy
from .ppo import PPOConfig

__all__ = ["FORMAT", "policy_arrays", "save_policy", "NumpyPolicy", "jax_act", "select_run"]



def select_run(result: dict, i: int) -> dict:
    """Run ``i`` of the output of a ``vmap``-ped ``train`` (every leaf indexed on its first axis)."""
    return jax.tree.map(lambda a: a[i], result)


def _action_map(cfg: PPOConfig, env, env_params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(low, high, scale)``: the policy's clip bounds and the factor to the env's inputs."""
    m = int(env.num_actions)
    space = env.action_space(env_params)
    low = np.broadcast_to(np.asarray(space.low, np.float64), (m,)).copy()
    high = np.broadcast_to(np.asarray(space.high, np.float64), (m,)).copy()
    scale = np.asarray(env_params.action_scale, np.float64) if cfg.normalize_actions else np.ones(m)
    return low, high, scale


def _kind(cfg) -> str:
    """The exported policy's ``kind`` (:mod:`.numpy_policy`): ``cfg.POLICY_KIND`` ("tanh": SAC), else "clip" (PPO)."""
    return getattr(cfg, "POLICY_KIND", "clip")


def jax_act(result: dict, cfg: PPOConfig, hparams: dict, env, env_params):
    """The deterministic policy of one run in JAX: ``obs (..., D) -> u (..., m)`` (float32 network); ``cfg`` a
    :class:`~.ppo.PPOConfig` (the clipped mean) or a :class:`~.sac.SACConfig` (``tanh`` of the mean, onto the
    bounds)."""
    low, high, scale = (jnp.asarray(x, jnp.float32) for x in _action_map(cfg, env, env_params))
    rms = nz.RunningMeanStd(result["obs_mean"], result["obs_var"], result["obs_count"])
    params = {k: v for k, v in result["params"].items() if k.startswith("pi_")}
    tanh = _kind(cfg) == "tanh"

    @jax.jit
    def act(obs):
        o = nz.normalize_obs(rms, obs, hparams["clip_obs"], hparams["norm_epsilon"]) if cfg.norm_obs else obs
        mu = pol.actor_mean(params, o.astype(jnp.float32), cfg.activation)
        if tanh:
            return (low + 0.5 * (jnp.tanh(mu) + 1.0) * (high - low)) * scale
        return jnp.clip(mu, low, high) * scale

    return act


def _version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def policy_arrays(result: dict, cfg: PPOConfig, hparams: dict, env, env_params, *,
                  extra: dict | None = None) -> tuple[dict, dict]:
    """``(arrays, meta)``: what :func:`save_policy` writes (``policy.npz``, ``policy.json``) for one run's
    ``result`` (only ``params``' ``pi_*`` arrays, ``obs_mean`` and ``obs_var`` are read: a snapshot of
    :func:`agents.training.jax.ppo.make_train` will do); :meth:`NumpyPolicy.from_arrays` acts with them."""
    if result["params"]["pi_w0"].ndim != 2:
        raise ValueError("result holds several runs (a vmapped train's output): pick one with select_run(result, i)")
    low, high, scale = _action_map(cfg, env, env_params)
    arrays = {k: np.asarray(v) for k, v in result["params"].items() if k.startswith("pi_")}
    arrays.update(obs_mean=np.asarray(result["obs_mean"]), obs_var=np.asarray(result["obs_var"]),
                  action_low=low, action_high=high, action_scale=scale)
    meta = {"format": FORMAT, "kind": _kind(cfg), "env_id": cfg.env_id, "obs_dim": int(arrays["pi_w0"].shape[0]),
            "act_dim": int(low.shape[0]), "net_arch": list(cfg.net_arch), "activation": cfg.activation,
            "norm_obs": cfg.norm_obs, "clip_obs": float(hparams["clip_obs"]),
            "epsilon": float(hparams["norm_epsilon"]), "normalize_actions": cfg.normalize_actions,
            "trainer": getattr(cfg, "TRAINER", "agents.training.jax.ppo"), "library": "jax",
            "library_version": _version("jax"),
            "optax_version": _version("optax"), "env_kwargs": cfg.env_kwargs, "extra": extra or {}}
    return arrays, meta


def save_policy(directory: str, result: dict, cfg: PPOConfig, hparams: dict, env, env_params, *,
                overwrite: bool = False, extra: dict | None = None) -> str:
    """Write ``policy.npz`` and ``policy.json`` of one run (``result``: the output of ``train``, or
    :func:`select_run` of a vmapped one) into ``directory``; returns ``directory``.

    Existing policy files are kept unless ``overwrite`` (``FileExistsError`` naming them).
    ``extra``: JSON-serialisable provenance added under ``"extra"`` (seed, budget, ...)."""
    arrays, meta = policy_arrays(result, cfg, hparams, env, env_params, extra=extra)
    os.makedirs(directory, exist_ok=True)
    existing = [f for f in _FILES if os.path.exists(os.path.join(directory, f))]
    if existing and not overwrite:
        raise FileExistsError(f"{directory} already holds {existing}; pass overwrite=True to replace them")
    tmp = os.path.join(directory, ".policy.tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, os.path.join(directory, "policy.npz"))
    with open(os.path.join(directory, ".policy.tmp.json"), "w") as f:
        json.dump(meta, f, indent=1)
    os.replace(os.path.join(directory, ".policy.tmp.json"), os.path.join(directory, "policy.json"))
    return directory
