"""The actor-critic of SB3's ``MlpPolicy`` for Box actions, in plain JAX, with its numpy twin.

Source: stable-baselines3 2.x ``ActorCriticPolicy`` with ``net_arch=[h_1, ..., h_k]`` (separate actor
and critic networks of those widths), ``activation_fn``, ``ortho_init=True`` and a state-independent
``log_std`` (``DiagGaussianDistribution``):

- actor ``mu(o) = W_a phi(...phi(W_1 o + b_1)...) + b_a``, critic ``V(o)`` likewise with its own layers;
- orthogonal initialisation: hidden layers gain ``sqrt(2)``, the action layer ``0.01``, the value layer
  ``1``, biases 0; ``log_std`` starts at ``log_std_init`` (one per action dimension);
- the Gaussian ``N(mu, diag(exp(2 log_std)))``: ``log p(a) = sum_j [-(a_j - mu_j)^2 / (2 s_j^2) - log s_j
  - log(2 pi) / 2]``, entropy ``sum_j [1/2 + log(2 pi)/2 + log s_j]``.

Parameters are a dict of plain arrays: ``pi_w{i}``, ``pi_b{i}``, ``vf_w{i}``, ``vf_b{i}`` (``i = 0..k``,
the last the output layer; ``w`` of shape ``(in, out)``) and ``log_std``. The same names are the arrays
of the exported ``.npz`` (:mod:`agents.training.jax.export`); the numpy twin of the actor is
:func:`agents.training.jax.numpy_policy.numpy_actor_mean`.
"""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp

__all__ = ["ACTIVATIONS", "init_params", "actor_mean", "value", "log_prob", "entropy"]

#: activation names (the recipes' ``activation_fn``) -> jax function (numpy twins: .numpy_policy)
ACTIVATIONS = {"tanh": jnp.tanh, "relu": jax.nn.relu}
_LOG_2PI = math.log(2.0 * math.pi)


def init_params(key, obs_dim: int, act_dim: int, net_arch, log_std_init) -> dict:
    """SB3's orthogonal initialisation (float32); ``log_std_init`` may be a traced scalar."""
    sizes = [obs_dim, *[int(h) for h in net_arch]]
    params = {}
    k_pi, k_vf = jax.random.split(key)
    for prefix, k, out_dim, out_gain in (("pi", k_pi, act_dim, 0.01), ("vf", k_vf, 1, 1.0)):
        keys = jax.random.split(k, len(sizes))
        dims = list(zip(sizes[:-1], sizes[1:])) + [(sizes[-1], out_dim)]
        for i, (d_in, d_out) in enumerate(dims):
            gain = out_gain if i == len(dims) - 1 else math.sqrt(2.0)
            params[f"{prefix}_w{i}"] = jax.nn.initializers.orthogonal(gain)(keys[i], (d_in, d_out), jnp.float32)
            params[f"{prefix}_b{i}"] = jnp.zeros((d_out,), jnp.float32)
    params["log_std"] = jnp.full((act_dim,), log_std_init, jnp.float32)
    return params


def _mlp(params: dict, prefix: str, x, act):
    n = sum(1 for k in params if k.startswith(prefix + "_w"))
    for i in range(n):
        x = x @ params[f"{prefix}_w{i}"] + params[f"{prefix}_b{i}"]
        if i < n - 1:
            x = act(x)
    return x


def actor_mean(params: dict, obs, activation: str = "tanh"):
    """The mean action ``mu(obs)``: ``obs (..., D) -> (..., m)``, float32."""
    return _mlp(params, "pi", obs.astype(jnp.float32), ACTIVATIONS[activation])


def value(params: dict, obs, activation: str = "tanh"):
    """The critic ``V(obs)``: ``obs (..., D) -> (...)``, float32."""
    return _mlp(params, "vf", obs.astype(jnp.float32), ACTIVATIONS[activation])[..., 0]


def log_prob(params: dict, mean, action):
    """``log N(action; mean, diag(exp(2 log_std)))`` summed over the action axis."""
    log_std = params["log_std"]
    z = (action - mean) * jnp.exp(-log_std)
    return jnp.sum(-0.5 * z ** 2 - log_std - 0.5 * _LOG_2PI, axis=-1)


def entropy(params: dict):
    """The Gaussian's entropy (state independent): ``sum_j (1/2 + log(2 pi)/2 + log_std_j)``."""
    return jnp.sum(0.5 + 0.5 * _LOG_2PI + params["log_std"])
