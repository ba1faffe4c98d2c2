"""The exported policy of a jitted run as a plain numpy callable (imports numpy only: no JAX needed to act).

A directory written by :func:`agents.training.jax.export.save_policy` holds ``policy.npz`` (the actor's
arrays ``pi_w{i}`` ``(in, out)``, ``pi_b{i}``, the observation statistics ``obs_mean``, ``obs_var`` and the
action map ``action_low``, ``action_high``, ``action_scale``; read with ``allow_pickle=False``) and
``policy.json`` (``format``, ``kind``, sizes, activation, normaliser constants, provenance). :class:`NumpyPolicy`
computes, in float64::

    o_n = clip((o - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)     (VecNormalize, if norm_obs)
    a   = clip(mu(o_n), low, high)                  kind "clip" (PPO: the Gaussian's mean, clipped)
    a   = low + (tanh(mu(o_n)) + 1) (high - low) / 2    kind "tanh" (SAC: the squashed Gaussian's mode,
                                                     mapped from [-1, 1] onto the bounds)
    u   = a * action_scale                                                  (normalized_actions scaling)

Files of the first format (``dobs_envs.jax_ppo_policy/1``, PPO only, no ``kind``) load as kind ``"clip"``.
``mu`` is the actor MLP (:func:`numpy_actor_mean`, the reference of
:func:`agents.training.jax.policy.actor_mean`). ``u`` is an action of ``gymnasium.make(env_id)`` with its
default ``normalized_actions=False`` (its action space is the input bounds).
"""
from __future__ import annotations

import json
import os

import numpy as np

from . import POLICY_FILES

__all__ = ["FORMAT", "READ_FORMATS", "KINDS", "NUMPY_ACTIVATIONS", "NumpyPolicy", "numpy_actor_mean"]

#: the ``format`` field of ``policy.json``
FORMAT = "dobs_envs.jax_policy/2"
#: the formats read: the first one (PPO's, before SAC) has no ``kind`` and is a "clip" policy
READ_FORMATS = (FORMAT, "dobs_envs.jax_ppo_policy/1")
#: ``kind`` -> the map from the actor's output to the action (see the module doc)
KINDS = ("clip", "tanh")
_FILES = POLICY_FILES

#: activation names -> numpy functions (the same names as :data:`agents.training.jax.policy.ACTIVATIONS`)
NUMPY_ACTIVATIONS = {"tanh": np.tanh, "relu": lambda x: np.maximum(x, 0.0)}


def numpy_actor_mean(arrays: dict, obs: np.ndarray, activation: str = "tanh") -> np.ndarray:
    """The actor's mean action in numpy float64: ``obs (..., D) -> (..., m)``."""
    act = NUMPY_ACTIVATIONS[activation]
    n = sum(1 for k in arrays if k.startswith("pi_w"))
    x = np.asarray(obs, dtype=np.float64)
    for i in range(n):
        x = x @ np.asarray(arrays[f"pi_w{i}"], np.float64) + np.asarray(arrays[f"pi_b{i}"], np.float64)
        if i < n - 1:
            x = act(x)
    return x


class NumpyPolicy:
    """The exported deterministic policy: ``policy(obs) -> u`` in numpy float64.

    Parameters
    ----------
    directory : a directory written by :func:`save_policy`.

    ``obs`` is ``(D,)`` or ``(B, D)``; the result ``(m,)`` or ``(B, m)``, in the env's input units.
    """

    def __init__(self, directory: str):
        paths = [os.path.join(directory, f) for f in _FILES]
        missing = [p for p in paths if not os.path.isfile(p)]
        if missing:
            raise FileNotFoundError(f"not an exported policy: {missing} missing")
        with open(paths[1]) as f:
            meta = json.load(f)
        with np.load(paths[0], allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k], np.float64) for k in z.files}
        self._check(arrays, meta, *paths)

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict) -> "NumpyPolicy":
        """The policy of ``arrays`` and ``meta`` as :func:`agents.training.jax.export.policy_arrays` gives them
        (what ``policy.npz`` and ``policy.json`` would hold), checked as files are."""
        self = cls.__new__(cls)
        self._check({k: np.asarray(v, np.float64) for k, v in arrays.items()}, dict(meta), "arrays", "meta")
        return self

    def _check(self, arrays: dict, meta: dict, arrays_src: str, meta_src: str) -> None:
        if not isinstance(meta, dict) or meta.get("format") not in READ_FORMATS:
            raise ValueError(f"{meta_src}: format {meta.get('format') if isinstance(meta, dict) else meta!r} is not "
                             f"one of {list(READ_FORMATS)}")
        meta.setdefault("kind", "clip")
        if meta["kind"] not in KINDS:
            raise ValueError(f"{meta_src}: kind must be one of {list(KINDS)}, got {meta['kind']!r}")
        if meta.get("activation") not in NUMPY_ACTIVATIONS:
            raise ValueError(f"{meta_src}: activation must be one of {list(NUMPY_ACTIVATIONS)}, got "
                             f"{meta.get('activation')!r}")
        n = len(meta["net_arch"]) + 1
        need = [f"pi_{p}{i}" for i in range(n) for p in "wb"] + ["obs_mean", "obs_var", "action_low",
                                                                  "action_high", "action_scale"]
        absent = [k for k in need if k not in arrays]
        if absent:
            raise ValueError(f"{arrays_src}: arrays {absent} missing")
        D, m = int(meta["obs_dim"]), int(meta["act_dim"])
        if arrays["pi_w0"].shape[0] != D or arrays[f"pi_w{n - 1}"].shape[1] != m or arrays["obs_mean"].shape != (D,):
            raise ValueError(f"{arrays_src}: array shapes do not match obs_dim={D}, act_dim={m}")
        self.meta, self.arrays = meta, arrays
        self.obs_dim, self.act_dim = D, m

    def __call__(self, obs) -> np.ndarray:
        o = np.asarray(obs, np.float64)
        if o.shape[-1:] != (self.obs_dim,) or o.ndim not in (1, 2):
            raise ValueError(f"obs must have shape ({self.obs_dim},) or (B, {self.obs_dim}), got {o.shape}")
        a = self.arrays
        if self.meta["norm_obs"]:
            c = self.meta["clip_obs"]
            o = np.clip((o - a["obs_mean"]) / np.sqrt(a["obs_var"] + self.meta["epsilon"]), -c, c)
        mu = numpy_actor_mean(a, o, self.meta["activation"])
        low, high = a["action_low"], a["action_high"]
        if self.meta["kind"] == "tanh":
            return (low + 0.5 * (np.tanh(mu) + 1.0) * (high - low)) * a["action_scale"]
        return np.clip(mu, low, high) * a["action_scale"]
