"""SAC as one compiled function, on the centralised JAX environments (:mod:`dobs_envs.jax`).

The structure is PureJaxRL's (Lu et al. 2022): a whole run is ``lax.scan`` over *collects* (a ``lax.scan``
of ``train_freq`` steps of ``n_envs`` vmapped copies written into a fixed-size replay ring buffer held in
the scan carry, then ``gradient_steps`` SAC updates), so ``jax.jit(train)`` compiles it once and
``jax.vmap(train)`` runs seeds (and the float hyperparameters of :data:`HPARAMS`) side by side.
What it computes is SBX 0.2x's ``SAC`` (``sbx/sac/sac.py``, ``sbx/sac/policies.py``: the implementation the
project's SAC rows train with, :mod:`agents.training.algos`) driven by SB3's ``OffPolicyAlgorithm`` loop and
``VecNormalize``, as the shipped recipes configure it (``agents/config/hyperparams/sac.yaml``):

- actor (``SquashedGaussianActor``): an MLP ``net_arch`` with ``activation_fn`` and two heads, the mean ``mu``
  and ``log sigma`` clipped to ``[-20, 2]``; the action ``a = tanh(x)``, ``x ~ N(mu, sigma^2)``, and
  ``log pi(a) = sum_j [log N(x_j; mu_j, sigma_j) - 2 (log 2 - x_j - softplus(-2 x_j))]`` (TFP's ``Tanh``
  bijector, evaluated at the sampled ``x``); the deterministic policy ``tanh(mu)``;
- twin critics (``VectorCritic``, ``n_critics = 2``): ``Q_c(o, a)``, an MLP of ``concat(o, a)``, with target
  copies initialised equal; layers initialised as flax's ``Dense`` (LeCun-normal weights, zero biases);
- per gradient step on a minibatch of the replay buffer (SBX's ``update_critic``, ``soft_update``,
  ``update_actor``, ``update_temperature``, in that order, ``policy_delay = 1``), with ``alpha`` the entropy
  coefficient before the step:

  ``y = r + (1 - d) gamma (min_c Q'_c(o', a') - alpha log pi(a'|o'))``, ``a' ~ pi(.|o')``;
  ``L_Q = 1/2 sum_c mean (y - Q_c(o, a))^2``; then ``theta' <- tau theta + (1 - tau) theta'``;
  ``L_pi = mean(alpha log pi(a~|o) - min_c Q_c(o, a~))``, ``a~ ~ pi(.|o)``, with the updated critics;
  ``L_alpha = log(alpha) (H - H_target)``, ``H = -mean log pi(a~|o)``, ``H_target = -dim(A)`` (``"auto"``);
  ``alpha = exp(log alpha)`` starts at 1 (``"auto"``) or ``x`` (``"auto_x"``); a number is a constant alpha;
- optimisers: Adam (``eps = 1e-8``) for the actor and the critics at ``learning_rate`` (``lin_x``: ``x p``,
  ``p = 1 - steps / total_timesteps`` after the collect: SB3's ``progress_remaining``), for ``log alpha`` at
  the initial learning rate (SBX's ``lrschedule(1)``);
- collection (SB3's ``collect_rollouts``): each collect takes ``train_freq`` steps of every copy; a step
  whose step count (before it) is below ``learning_starts`` takes uniform random actions in ``[-1, 1]``,
  the others ``tanh(mu + sigma eps)`` clipped to ``[-1, 1]`` (SBX's ``predict``); with ``use_sde``, ``eps (n_envs,
  m)`` is drawn once per collect and held (SBX's gSDE stand-in: the same noise key until ``reset_noise`` at
  the next collect), else drawn every step. Actions in ``[-1, 1]`` are stored and mapped linearly onto
  the action space (``normalize_actions``: the env's ``normalized_actions`` option, as ``RescaleAction``);
- the updates run after a collect when the step count exceeds ``learning_starts``; a run takes
  ``ceil(total_timesteps / (n_envs train_freq))`` collects (SB3's loop; it may overshoot the budget);
- replay buffer (SB3's ``ReplayBuffer``, ``n_envs`` copies): ``buffer_size // n_envs`` rows of ``n_envs``
  transitions, a ring; it holds the *raw* observations and rewards (``VecNormalize.get_original_obs`` /
  ``get_original_reward``), normalised with the current statistics when sampled; a sample draws
  ``batch_size gradient_steps`` (row, copy) pairs uniformly over the filled rows at once (SBX's ``train``);
- time limits: the next observation of a transition that ended an episode is its true final observation
  (``info["final_observation"]``), and the stored ``done`` is the termination alone (SB3's
  ``handle_timeout_termination``): a truncated episode is bootstrapped, ``Q(o_final)`` in ``y``;
- ``VecNormalize``: :func:`agents.training.jax.normalize.norm_step` per vector step (the policy acts on the
  normalised observation), the reset's observations counted first.

Deliberate differences from SBX (and SB3's loop):

- random streams: JAX keys split per collect and gradient step (SBX's key stream and NumPy's buffer
  sampling differ; the distributions are the same); given the same key, a Gaussian draw is SBX's
  (:func:`standard_normal`), so one gradient step from the same state, batch and keys is SBX's (tested);
- the final observation is stored raw; SB3 stores ``unnormalize_obs(normalize_obs(o_final))``, which equals
  ``o_final`` except where ``clip_obs`` clipped it;
- the buffer is float32 for observations and rewards (SB3's: the observation space's dtype, float32 here,
  and float32 rewards); statistics in the environment's dtype as :mod:`.normalize`;
- not implemented (refused by name): ``policy_delay``, ``n_steps`` (n-step returns), ``qf_learning_rate``,
  ``sde_sample_freq``, ``use_sde_at_warmup``, action noise (``noise_type``), dropout / layer norm, ``param_resets``,
  ``target_update_interval``, ``optimize_memory_usage``, a ``train_freq`` in episodes.

Why not rejax 0.1.3's ``SAC`` (in the heavy-clients environment; read from its source and measured on tracking,
20k env steps, 8 copies, 2 gradient steps of 256 per vector step, [64, 64] ReLU, obs + reward normalisation, one
XLA thread, rejax's evaluations switched off, two alternating pairs on the shared 2-core machine at load ~5: run
7.2 / 8.9 s CPU against this trainer's 5.6 / 5.9 s, compile 16 / 18 s against 17 / 20 s; no speed reason either
way): it cannot express the shipped recipe. Its learning rate is a constant (the recipe: ``lin_1e-3``) shared
with the temperature, whose loss it takes on ``alpha`` instead of ``log alpha``; it clips every gradient element
(``optax.clip``); it collects one vector step per iteration (no ``train_freq``), updates the target once per
vector step instead of once per gradient step, and has no held exploration noise (``use_sde``) and no initial
random actions; it updates the actor before the critics; it treats the 400-step truncation as termination (no
bootstrap) and stores the auto-reset observation as the next one; its normalisers do not clip (the recipe:
``clip_obs = clip_reward = 10``). It also needs distrax (tfp-nightly) and gymnax 1.0 (``gymnasium < 1.4``),
which conflict with the main environment (see :mod:`.ppo`).

The hyperparameters are the recipe's keys (``agents.training.recipes.resolve_recipe("sac", env).hyperparams``),
read by :func:`sac_config`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import optax

from . import normalize as nz
from .policy import ACTIVATIONS
from ..xla import check_xla_runtime
from .envs import make_env
from .validate import (float_dtype, non_negative_int, pos_int, schedule, train_env_kwargs,
                       vec_normalize)

__all__ = ["SACConfig", "HPARAMS", "RECIPE_KEYS", "sac_config", "make_env", "make_train", "init_params",
           "actor_dist", "tanh_log_prob", "standard_normal", "q_values", "critic_loss", "actor_loss", "alpha_loss",
           "polyak",
           "init_opts", "update_step", "ring_init", "ring_write", "sample_indices", "offpolicy_fields",
           "offpolicy_train", "SACHooks"]

#: float hyperparameters passed to ``train(key, hparams)``: traced, so ``jax.vmap`` sweeps them
HPARAMS = ("learning_rate", "tau", "gamma", "ent_coef", "target_entropy", "norm_gamma", "clip_obs", "clip_reward",
           "norm_epsilon")

#: recipe keys read by :func:`sac_config` (anything else is refused with its name)
RECIPE_KEYS = ("policy", "n_envs", "n_timesteps", "learning_rate", "buffer_size", "learning_starts", "batch_size",
               "tau", "gamma", "train_freq", "gradient_steps", "ent_coef", "target_entropy", "use_sde", "normalize",
               "normalize_actions", "policy_kwargs", "env_kwargs")
_POLICY_KWARGS = ("net_arch", "activation_fn")
_NORMALIZE_KEYS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")
#: ``log sigma`` bounds of SBX's ``SquashedGaussianActor``
LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0
N_CRITICS = 2


@dataclass(frozen=True)
class SACConfig:
    """What fixes the shapes and branches of a run (static under ``jit``); the float hyperparameters are the
    ``hparams`` dict of :func:`sac_config` (:data:`HPARAMS`)."""
    env_id: str
    total_timesteps: int
    n_envs: int = 1
    buffer_size: int = 1_000_000
    learning_starts: int = 100
    batch_size: int = 256
    train_freq: int = 1
    gradient_steps: int = 1
    net_arch: tuple = (256, 256)
    activation: str = "relu"
    lr_linear: bool = False
    ent_auto: bool = True
    use_sde: bool = False
    norm_obs: bool = False
    norm_reward: bool = False
    normalize_actions: bool = False
    env_kwargs: dict = field(default_factory=dict)
    dtype: str = "float32"

    #: the exported policy's map (:mod:`.numpy_policy`): tanh of the mean, onto the action bounds
    POLICY_KIND: ClassVar[str] = "tanh"
    TRAINER: ClassVar[str] = "agents.training.jax.sac"

    @property
    def rollout(self) -> int:
        """Env steps per collect: ``n_envs train_freq``."""
        return self.n_envs * self.train_freq

    @property
    def n_updates(self) -> int:
        """Collects of a run (each followed by its gradient steps once learning started):
        ``ceil(total_timesteps / rollout)`` (SB3's loop)."""
        return -(-self.total_timesteps // self.rollout)

    @property
    def steps_done(self) -> int:
        """Env steps a run takes: ``n_updates rollout`` (at least ``total_timesteps``)."""
        return self.n_updates * self.rollout

    @property
    def buffer_rows(self) -> int:
        """Rows of the ring buffer, each ``n_envs`` transitions: ``max(buffer_size // n_envs, 1)`` (SB3's)."""
        return max(self.buffer_size // self.n_envs, 1)


def _ent_coef(value) -> tuple[float, bool]:
    """``(initial alpha, learned)`` of SBX's ``ent_coef``: ``"auto"`` (1.0), ``"auto_<x>"`` or a number."""
    if isinstance(value, str):
        if value == "auto":
            return 1.0, True
        if value.startswith("auto_"):
            try:
                x = float(value[5:])
            except ValueError:
                x = float("nan")
            if not x > 0:
                raise ValueError(f"ent_coef 'auto_<x>' needs a positive x, got {value!r}")
            return x, True
        raise ValueError(f"ent_coef must be 'auto', 'auto_<x>' or a number, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
        raise ValueError(f"ent_coef must be 'auto', 'auto_<x>' or a non-negative number, got {value!r}")
    return float(value), False


def offpolicy_fields(hyperparams: dict, recipe_keys: tuple, name: str, *, total_timesteps: int | None,
                     dtype: str) -> tuple[dict, dict, dict]:
    """The keys SAC and TD3 share (SB3's ``OffPolicyAlgorithm``, ``VecNormalize``, the policy's MLP): ``(fields,
    hparams, hp)``, the :class:`SACConfig` fields and float hyperparameters they give, and the recipe as a dict
    (for the algorithm's own keys). A key outside ``recipe_keys`` is refused naming it and the trainer ``name``."""
    if not isinstance(hyperparams, dict):
        raise TypeError(f"hyperparams must be a dict of recipe keys, got {type(hyperparams).__name__}")
    unknown = sorted(set(hyperparams) - set(recipe_keys))
    if unknown:
        raise ValueError(f"hyperparameters {unknown} are not implemented by the JAX {name} trainer; "
                         f"supported keys: {list(recipe_keys)}")
    hp = dict(hyperparams)
    if hp.get("policy", "MlpPolicy") != "MlpPolicy":
        raise ValueError(f"policy must be 'MlpPolicy', got {hp['policy']!r}")
    pk = dict(hp.get("policy_kwargs") or {})
    bad = sorted(set(pk) - set(_POLICY_KWARGS))
    if bad:
        raise ValueError(f"policy_kwargs {bad} are not implemented by the JAX {name} trainer; supported: "
                         f"{list(_POLICY_KWARGS)}")
    net_arch = pk.get("net_arch", [256, 256])
    if not isinstance(net_arch, (list, tuple)) or not net_arch:
        raise ValueError(f"policy_kwargs.net_arch must be a non-empty list of layer widths (shared by actor and "
                         f"critics), got {net_arch!r}")
    net_arch = tuple(pos_int("policy_kwargs.net_arch[i]", h) for h in net_arch)
    activation = str(pk.get("activation_fn", "relu")).lower().removeprefix("nn.")
    if activation not in ACTIVATIONS:
        raise ValueError(f"policy_kwargs.activation_fn must be one of {list(ACTIVATIONS)}, got "
                         f"{pk.get('activation_fn')!r}")
    norm = vec_normalize(hp.get("normalize", False), _NORMALIZE_KEYS)
    lr, lr_linear = schedule("learning_rate", hp.get("learning_rate", 3e-4))
    train_freq = hp.get("train_freq", 1)
    if isinstance(train_freq, (list, tuple)):
        if len(train_freq) != 2 or train_freq[1] != "step":
            raise ValueError(f"train_freq must be a positive integer or [n, 'step'] (episodes are not implemented), "
                             f"got {train_freq!r}")
        train_freq = train_freq[0]
    total = pos_int("total_timesteps", hp.get("n_timesteps", 1_000_000) if total_timesteps is None
                     else total_timesteps)
    learning_starts = non_negative_int("learning_starts", hp.get("learning_starts", 100))
    tau = hp.get("tau", 0.005)
    if isinstance(tau, bool) or not isinstance(tau, (int, float)) or not 0 < tau <= 1:
        raise ValueError(f"tau must be a number in (0, 1], got {tau!r}")
    float_dtype(dtype)
    env_kwargs = train_env_kwargs(hp.get("env_kwargs"))
    fields = dict(total_timesteps=total, n_envs=pos_int("n_envs", hp.get("n_envs", 1)),
                  buffer_size=pos_int("buffer_size", hp.get("buffer_size", 1_000_000)),
                  learning_starts=learning_starts, batch_size=pos_int("batch_size", hp.get("batch_size", 256)),
                  train_freq=pos_int("train_freq", train_freq),
                  gradient_steps=pos_int("gradient_steps", hp.get("gradient_steps", 1)), net_arch=net_arch,
                  activation=activation, lr_linear=lr_linear, norm_obs=bool(norm.get("norm_obs", True)),
                  norm_reward=bool(norm.get("norm_reward", True)),
                  normalize_actions=bool(hp.get("normalize_actions", False)), env_kwargs=env_kwargs, dtype=dtype)
    gamma = float(hp.get("gamma", 0.99))
    hparams = {"learning_rate": lr, "tau": float(tau), "gamma": gamma, "norm_gamma": float(norm.get("gamma", gamma)),
               "clip_obs": float(norm.get("clip_obs", 10.0)), "clip_reward": float(norm.get("clip_reward", 10.0)),
               "norm_epsilon": float(norm.get("epsilon", 1e-8))}
    return fields, hparams, hp


def sac_config(hyperparams: dict, env_id: str = "dobs_envs/Tracking-v0", *, total_timesteps: int | None = None,
               dtype: str = "float32") -> tuple[SACConfig, dict]:
    """``(config, hparams)`` of a recipe's hyperparameters (SB3/rl-zoo3 names, defaults SBX's SAC).

    Parameters
    ----------
    hyperparams : the recipe's keys (:data:`RECIPE_KEYS`): ``n_envs``, ``buffer_size``, ``learning_starts``,
        ``batch_size``, ``tau``, ``gamma``, ``train_freq`` (env steps per copy between updates), ``gradient_steps``,
        ``learning_rate`` (number or ``"lin_<x>"``), ``ent_coef`` (``"auto"``, ``"auto_<x>"`` or a number),
        ``target_entropy`` (``"auto"``: ``-dim(A)``, or a number), ``use_sde``, ``normalize`` (as
        :func:`agents.training.jax.ppo.ppo_config`), ``normalize_actions``, ``policy_kwargs`` (``net_arch`` a
        list shared by actor and critics, ``activation_fn`` ``"relu"``/``"tanh"``), ``env_kwargs``,
        ``n_timesteps``. A key the trainer does not implement raises ``ValueError`` naming it.
    env_id : a Gymnasium id of :func:`dobs_envs.jax.registered_envs`.
    total_timesteps : the budget (default ``n_timesteps``).
    dtype : the environment's (and the normaliser's) float type; the networks are float32.
    """
    fields, hparams, hp = offpolicy_fields(hyperparams, RECIPE_KEYS, "SAC", total_timesteps=total_timesteps,
                                           dtype=dtype)
    alpha0, ent_auto = _ent_coef(hp.get("ent_coef", "auto"))
    target = hp.get("target_entropy", "auto")
    if target != "auto" and (isinstance(target, bool) or not isinstance(target, (int, float))):
        raise ValueError(f"target_entropy must be 'auto' or a number, got {target!r}")
    use_sde = hp.get("use_sde", False)
    if not isinstance(use_sde, bool):
        raise ValueError(f"use_sde must be true or false, got {use_sde!r}")
    cfg = SACConfig(env_id=env_id, ent_auto=ent_auto, use_sde=use_sde, **fields)
    hparams.update(ent_coef=alpha0, target_entropy=math.nan if target == "auto" else float(target))
    return cfg, hparams


# ---- networks (flax's Dense layout as plain arrays) ------------------------------------------------------------

def _dense_init(key, d_in: int, d_out: int, lead: tuple = ()):
    """flax ``nn.Dense``'s default: LeCun-normal (truncated) weights ``(*lead, in, out)``, zero biases."""
    w = jax.nn.initializers.lecun_normal()(key, (*lead, d_in, d_out), jnp.float32)
    return w, jnp.zeros((*lead, d_out), jnp.float32)


def init_params(key, obs_dim: int, act_dim: int, net_arch) -> dict:
    """The actor and the twin critics (float32 arrays in a dict).

    Actor: ``pi_w{i}``, ``pi_b{i}`` (hidden layers ``i < k``, the mean head ``i = k``; the exported arrays)
    and ``ls_w``, ``ls_b`` (the ``log sigma`` head). Critics: ``qf_w{i}``, ``qf_b{i}`` with a leading axis of
    the :data:`N_CRITICS` critics, the input ``concat(obs, action)``.
    """
    sizes = [obs_dim, *[int(h) for h in net_arch]]
    k_pi, k_ls, k_qf = jax.random.split(key, 3)
    params = {}
    keys = jax.random.split(k_pi, len(sizes))
    for i, (d_in, d_out) in enumerate(list(zip(sizes[:-1], sizes[1:])) + [(sizes[-1], act_dim)]):
        params[f"pi_w{i}"], params[f"pi_b{i}"] = _dense_init(keys[i], d_in, d_out)
    params["ls_w"], params["ls_b"] = _dense_init(k_ls, sizes[-1], act_dim)
    q_sizes = [obs_dim + act_dim, *sizes[1:], 1]
    keys = jax.random.split(k_qf, len(q_sizes) - 1)
    for i, (d_in, d_out) in enumerate(zip(q_sizes[:-1], q_sizes[1:])):
        params[f"qf_w{i}"], params[f"qf_b{i}"] = _dense_init(keys[i], d_in, d_out, (N_CRITICS,))
    return params


def actor_dist(params: dict, obs, activation: str):
    """``(mu, log sigma)`` of the squashed Gaussian at ``obs (..., D)``: ``(..., m)`` each, ``log sigma``
    clipped to ``[LOG_STD_MIN, LOG_STD_MAX]``."""
    act = ACTIVATIONS[activation]
    n = sum(1 for k in params if k.startswith("pi_w"))
    x = obs.astype(jnp.float32)
    for i in range(n - 1):
        x = act(x @ params[f"pi_w{i}"] + params[f"pi_b{i}"])
    mu = x @ params[f"pi_w{n - 1}"] + params[f"pi_b{n - 1}"]
    log_std = jnp.clip(x @ params["ls_w"] + params["ls_b"], LOG_STD_MIN, LOG_STD_MAX)
    return mu, log_std


def tanh_log_prob(mu, log_std, x):
    """``log pi(tanh x)`` of the pre-squash sample ``x``: the Gaussian's log density minus the ``Tanh``
    bijector's ``log |d tanh / dx| = 2 (log 2 - x - softplus(-2 x))``, summed over the action axis."""
    z = (x - mu) * jnp.exp(-log_std)
    gauss = -0.5 * z ** 2 - log_std - 0.5 * math.log(2.0 * math.pi)
    return jnp.sum(gauss - 2.0 * (math.log(2.0) - x - jax.nn.softplus(-2.0 * x)), axis=-1)


def standard_normal(key, shape: tuple):
    """``N(0, 1)`` draws of ``shape (n, m)`` in the order of SBX's ``dist.sample(seed=key)`` (TFP's
    ``MultivariateNormalDiag`` draws ``(m, n)`` with ``jax.random.normal`` and transposes): the same key gives
    the same exploration noise as SBX."""
    return jax.random.normal(key, shape[::-1], jnp.float32).T


def _sample(params, obs, activation, key):
    """``(a, log pi(a))`` with ``a = tanh(mu + sigma eps)``, ``eps`` drawn with ``key`` (:func:`standard_normal`);
    ``obs (n, D)``."""
    mu, log_std = actor_dist(params, obs, activation)
    x = mu + jnp.exp(log_std) * standard_normal(key, mu.shape)
    return jnp.tanh(x), tanh_log_prob(mu, log_std, x)


def q_values(params: dict, obs, action, activation: str):
    """``Q_c(obs, action)`` of every critic: ``(N_CRITICS, ...)`` (``params``: the ``qf_*`` arrays)."""
    act = ACTIVATIONS[activation]
    n = sum(1 for k in params if k.startswith("qf_w"))
    x = jnp.concatenate([obs.astype(jnp.float32), action.astype(jnp.float32)], axis=-1)

    def one(p):
        h = x
        for i in range(n):
            h = h @ p[f"qf_w{i}"] + p[f"qf_b{i}"]
            if i < n - 1:
                h = act(h)
        return h[..., 0]

    return jax.vmap(one)({k: v for k, v in params.items() if k.startswith("qf_")})


def _critic_params(params):
    return {k: v for k, v in params.items() if k.startswith("qf_")}


def _actor_params(params):
    return {k: v for k, v in params.items() if not k.startswith("qf_")}


# ---- the losses of one gradient step (SBX's update_critic / update_actor / update_temperature) ----------------

def critic_loss(qf: dict, target_qf: dict, actor: dict, alpha, batch, gamma, key, activation: str):
    """``L_Q = 1/2 sum_c mean_b (y - Q_c(o, a))^2`` with ``y = r + (1 - d) gamma (min_c Q'_c(o', a') -
    alpha log pi(a'|o'))``, ``a' ~ pi(.|o')`` drawn with ``key``, ``y`` held constant."""
    obs, act, next_obs, rew, done = batch
    a_next, logp_next = _sample(actor, next_obs, activation, key)
    q_next = jnp.min(q_values(target_qf, next_obs, a_next, activation), axis=0) - alpha * logp_next
    y = jax.lax.stop_gradient(rew + (1.0 - done) * gamma * q_next)
    q = q_values(qf, obs, act, activation)
    return 0.5 * jnp.sum(jnp.mean((y[None] - q) ** 2, axis=1))


def actor_loss(actor: dict, qf: dict, alpha, obs, key, activation: str):
    """``(L_pi, H)``: ``L_pi = mean(alpha log pi(a~|o) - min_c Q_c(o, a~))`` (``a~`` drawn with ``key``,
    reparameterised) and the entropy estimate ``H = -mean log pi(a~|o)``."""
    a, logp = _sample(actor, obs, activation, key)
    q = jnp.min(q_values(qf, obs, a, activation), axis=0)
    return jnp.mean(alpha * logp - q), -jnp.mean(logp)


def alpha_loss(log_alpha, entropy, target_entropy):
    """``L_alpha = log(alpha) (H - H_target)`` (SBX's temperature loss, on ``log alpha``)."""
    return log_alpha * (jax.lax.stop_gradient(entropy) - target_entropy)


def polyak(params: dict, target: dict, tau) -> dict:
    """``tau params + (1 - tau) target`` (``optax.incremental_update``)."""
    return jax.tree.map(lambda p, t: tau * p + (1.0 - tau) * t, params, target)


def ring_init(rows: int, n_envs: int, obs_dim: int, act_dim: int):
    """An empty replay ring buffer ``(arrays, pos, full)``: ``obs``, ``next_obs`` ``(rows, n_envs, D)``,
    ``action (rows, n_envs, m)``, ``reward``, ``done (rows, n_envs)`` (float32), write position 0, not full."""
    f32 = jnp.float32
    buf = {"obs": jnp.zeros((rows, n_envs, obs_dim), f32), "action": jnp.zeros((rows, n_envs, act_dim), f32),
           "next_obs": jnp.zeros((rows, n_envs, obs_dim), f32), "reward": jnp.zeros((rows, n_envs), f32),
           "done": jnp.zeros((rows, n_envs), f32)}
    return buf, jnp.asarray(0, jnp.int32), jnp.asarray(False)


def ring_write(ring, row: dict):
    """``ring`` with one row of ``n_envs`` transitions written at its position (SB3's ``ReplayBuffer.add``):
    the position advances modulo the rows, ``full`` once it wrapped."""
    buf, pos, full = ring
    buf = {k: buf[k].at[pos].set(jnp.asarray(row[k]).astype(buf[k].dtype)) for k in buf}
    pos = (pos + 1) % buf["reward"].shape[0]
    return buf, pos, full | (pos == 0)


#: optax.adam's moments (b1 0.9, b2 0.999, eps 1e-8); the learning rate is applied by :func:`_adam_step`
_ADAM = optax.scale_by_adam()


def init_opts(params: dict, log_alpha):
    """The Adam states ``(actor, critics, log alpha)`` of a new run."""
    return _ADAM.init(_actor_params(params)), _ADAM.init(_critic_params(params)), _ADAM.init(log_alpha)


def _adam_step(p, grads, opt, lr):
    step, opt = _ADAM.update(grads, opt)
    return jax.tree.map(lambda a, s: a - lr * s, p, step), opt


def update_step(state, batch, keys, *, lr, lr_alpha, gamma, tau, target_entropy, activation: str,
                ent_auto: bool = True):
    """One SAC gradient step (SBX's ``update_critic``, ``soft_update``, ``update_actor``, ``update_temperature``).

    ``state = (params, target, log_alpha, opts)`` (:func:`init_params`, the target critics, ``log alpha``,
    :func:`init_opts`); ``batch = (obs, action, next_obs, reward, done)`` (normalised, ``done`` the
    termination); ``keys = (k_critic, k_actor)`` draw the critic's next actions and the actor's actions.
    Returns ``(state', (critic loss, actor loss, alpha))`` with ``alpha`` the coefficient the step used."""
    params, target, log_alpha, (o_pi, o_qf, o_al) = state
    k_q, k_pi = keys
    alpha = jnp.exp(log_alpha)
    actor, qf = _actor_params(params), _critic_params(params)
    q_loss, g_qf = jax.value_and_grad(critic_loss)(qf, target, actor, alpha, batch, gamma, k_q, activation)
    qf, o_qf = _adam_step(qf, g_qf, o_qf, lr)
    target = polyak(qf, target, tau)
    (pi_loss, entropy), g_pi = jax.value_and_grad(actor_loss, has_aux=True)(actor, qf, alpha, batch[0], k_pi,
                                                                           activation)
    actor, o_pi = _adam_step(actor, g_pi, o_pi, lr)
    if ent_auto:
        g_al = jax.grad(alpha_loss)(log_alpha, entropy, target_entropy)
        log_alpha, o_al = _adam_step(log_alpha, g_al, o_al, lr_alpha)
    return (dict(actor, **qf), target, log_alpha, (o_pi, o_qf, o_al)), (q_loss, pi_loss, alpha)


def sample_indices(key, n: int, pos, full, rows: int, n_envs: int):
    """``(row, copy)`` of ``n`` transitions drawn uniformly from the filled part of the ring buffer (rows
    ``0 .. rows - 1`` when ``full``, else ``0 .. pos - 1``; SB3's ``ReplayBuffer.sample``)."""
    k_row, k_env = jax.random.split(key)
    upper = jnp.where(full, rows, jnp.maximum(pos, 1))
    return jax.random.randint(k_row, (n,), 0, upper), jax.random.randint(k_env, (n,), 0, n_envs)


# ---- the run ---------------------------------------------------------------------------------------------------

class SACHooks:
    """What :func:`offpolicy_train` asks of SAC: the learner's state ``(params, target critics, log alpha, Adam
    states)``, the exploring action, one gradient step, the run's outputs."""
    HPARAMS = HPARAMS
    LOSSES = ("critic_loss", "actor_loss", "ent_coef")

    def __init__(self, cfg: SACConfig, obs_dim: int, act_dim: int):
        self.cfg, self.obs_dim, self.act_dim = cfg, obs_dim, act_dim

    def init(self, key, hp):
        params = init_params(key, self.obs_dim, self.act_dim, self.cfg.net_arch)
        log_alpha = jnp.log(hp["ent_coef"]).astype(jnp.float32)
        return params, _critic_params(params), log_alpha, init_opts(params, log_alpha)

    def act(self, learner, obs_n, key, eps_held, hp):
        """``tanh(mu + sigma eps)`` clipped to ``[-1, 1]``; ``eps`` held over the collect with ``use_sde``."""
        mu, log_std = actor_dist(learner[0], obs_n, self.cfg.activation)
        eps = eps_held if self.cfg.use_sde else standard_normal(key, mu.shape)
        return jnp.clip(jnp.tanh(mu + jnp.exp(log_std) * eps), -1.0, 1.0)

    def noise(self, a, key, hp):
        return a

    def update(self, learner, batch, key, lr, hp):
        target_entropy = jnp.where(jnp.isnan(hp["target_entropy"]), -float(self.act_dim), hp["target_entropy"])
        return update_step(learner, batch, jax.random.split(key), lr=lr, lr_alpha=hp["learning_rate"],
                           gamma=hp["gamma"], tau=hp["tau"], target_entropy=target_entropy,
                           activation=self.cfg.activation, ent_auto=self.cfg.ent_auto)

    def outputs(self, learner) -> dict:
        return {"params": learner[0], "target": learner[1], "log_alpha": learner[2]}


def make_train(cfg: SACConfig, env=None, env_params=None, snapshots=None, return_buffer: bool = False):
    """``train(key, hparams) -> dict``: one SAC run as a pure function (``jax.jit`` / ``jax.vmap`` it).

    Parameters
    ----------
    cfg : the static configuration (:func:`sac_config`).
    env, env_params : the environment (default :func:`make_env`).
    snapshots : collect counts in ``0 .. cfg.n_updates`` (0: the initial policy) after which the actor's
        ``pi_*`` arrays and the observation statistics are kept (the learning curve); default none.
    return_buffer : also return the replay buffer's arrays (``buffer``: :func:`ring_init`'s dict).

    Returns
    -------
    train : ``train(key, hparams)``, ``hparams`` a dict of the :data:`HPARAMS` scalars. Its result is a dict:

        - ``params``: the actor's and the critics' arrays (:func:`init_params`), ``target``: the target
          critics, ``log_alpha``;
        - ``obs_mean (D,)``, ``obs_var (D,)``, ``obs_count``, ``ret_var``, ``ret_count``: the normaliser's
          statistics at the end;
        - ``curve``: per collect ``steps (U,)``, ``episode_return (U,)``, ``episode_length (U,)``, ``episodes
          (U,)`` (as :func:`agents.training.jax.ppo.make_train`'s), ``critic_loss``, ``actor_loss``,
          ``ent_coef`` (the last gradient step's; NaN before learning starts);
        - ``buffer_pos``, ``buffer_full``: the ring buffer's write position and whether it wrapped;
        - ``snapshots`` (with ``snapshots``): ``pi_*`` ``(K, ...)``, ``obs_mean (K, D)``, ``obs_var (K, D)``.
    """
    return offpolicy_train(cfg, SACHooks, env, env_params, snapshots, return_buffer)


def offpolicy_train(cfg: SACConfig, hooks, env=None, env_params=None, snapshots=None, return_buffer: bool = False):
    """The run of :func:`make_train` for an off-policy algorithm given by ``hooks`` (a class like
    :class:`SACHooks`, built with ``(cfg, obs_dim, act_dim)``): SB3's collect / train loop, the ring buffer,
    ``VecNormalize``, the learning-curve snapshots of ``learner[0]``'s ``pi_*`` arrays."""
    check_xla_runtime(f"{cfg.TRAINER}.make_train")
    if env is None:
        env, env_params = make_env(cfg)
    elif env_params is None:
        env_params = env.default_params
    B, F, G, R = cfg.n_envs, cfg.train_freq, cfg.gradient_steps, cfg.buffer_rows
    obs_dim = int(np.prod(env.observation_space(env_params).shape))
    act_dim = int(env.num_actions)
    algo = hooks(cfg, obs_dim, act_dim)
    space = env.action_space(env_params)
    a_low = jnp.asarray(np.broadcast_to(np.asarray(space.low, np.float32), (act_dim,)))
    a_high = jnp.asarray(np.broadcast_to(np.asarray(space.high, np.float32), (act_dim,)))
    stat_dtype = jnp.float64 if cfg.dtype == "float64" else jnp.float32
    total = float(cfg.total_timesteps)
    v_step = jax.vmap(env.step, in_axes=(0, 0, 0, None))
    v_reset = jax.vmap(env.reset, in_axes=(0, None))
    snap_at = None
    if snapshots is not None:
        snap_at = np.unique(np.asarray([int(u) for u in snapshots], dtype=np.int64))
        if snap_at.size == 0 or snap_at[0] < 0 or snap_at[-1] > cfg.n_updates:
            raise ValueError(f"snapshots must be collect counts in 0..{cfg.n_updates}, got {list(snapshots)!r}")

    def snapshot(params, norm):
        return {**{k: v for k, v in params.items() if k.startswith("pi_")}, "obs_mean": norm.obs_rms.mean,
                "obs_var": norm.obs_rms.var}

    def keep(buf, snap, count):
        slot = jnp.minimum(jnp.searchsorted(jnp.asarray(snap_at), count), snap_at.size - 1)
        hit = jnp.asarray(snap_at)[slot] == count
        return jax.tree.map(lambda b, x: b.at[slot].set(jnp.where(hit, x.astype(b.dtype), b[slot])), buf, snap)

    def train(key, hparams: dict):
        hp = {k: jnp.asarray(hparams[k]) for k in algo.HPARAMS}
        k_init, k_reset, key = jax.random.split(key, 3)
        learner = algo.init(k_init, hp)
        obs, env_state = v_reset(jax.random.split(k_reset, B), env_params)
        norm = nz.norm_init((obs_dim,), B, stat_dtype)
        if cfg.norm_obs:  # VecNormalize.reset updates the statistics with the first observations
            norm = norm._replace(obs_rms=nz.rms_update(norm.obs_rms, obs))
            obs_n = nz.normalize_obs(norm.obs_rms, obs, hp["clip_obs"], hp["norm_epsilon"])
        else:
            obs_n = obs
        f32 = jnp.float32
        ring = ring_init(R, B, obs_dim, act_dim)

        def env_step(carry, x):
            learner, norm, env_state, obs_raw, obs_n, ep_ret, ep_len, ring, eps_held = carry
            k, t = x
            k_act, k_rand, k_noise, k_env = jax.random.split(k, 4)
            a = algo.act(learner, obs_n, k_act, eps_held, hp)
            random = jax.random.uniform(k_rand, a.shape, f32, -1.0, 1.0)
            a = jnp.where(t * B < cfg.learning_starts, random, a)  # t: vector steps taken before this one
            a = algo.noise(a, k_noise, hp)  # SB3's action noise (TD3), on random actions too
            u = a_low + 0.5 * (a + 1.0) * (a_high - a_low)
            obs, env_state, reward, term, trunc, info = v_step(jax.random.split(k_env, B), env_state, u, env_params)
            done = term | trunc
            next_raw = jnp.where(done[:, None], info["final_observation"], obs)
            # the stored done is the termination alone: a truncated episode bootstraps from o_final
            ring = ring_write(ring, {"obs": obs_raw, "action": a, "next_obs": next_raw, "reward": reward,
                                     "done": term})
            norm, next_obs_n, _ = nz.norm_step(
                norm, obs, reward, done, gamma=hp["norm_gamma"], clip_obs=hp["clip_obs"],
                clip_reward=hp["clip_reward"], epsilon=hp["norm_epsilon"], norm_obs=cfg.norm_obs,
                norm_reward=cfg.norm_reward)
            ep_ret = ep_ret + reward.astype(stat_dtype)
            ep_len = ep_len + 1
            ended = (jnp.sum(done), jnp.sum(jnp.where(done, ep_ret, 0.0)), jnp.sum(jnp.where(done, ep_len, 0)))
            carry = (learner, norm, env_state, obs, next_obs_n, jnp.where(done, 0.0, ep_ret),
                     jnp.where(done, 0, ep_len), ring, eps_held)
            return carry, ended

        def gradient_steps(learner, norm, ring, key, lr):
            buf, pos, full = ring
            k_idx, k_steps = jax.random.split(key)
            rows, envs = sample_indices(k_idx, cfg.batch_size * G, pos, full, R, B)

            def take(name):
                return buf[name][rows, envs].reshape((G, cfg.batch_size) + buf[name].shape[2:])

            obs_b, next_b = take("obs"), take("next_obs")
            rew_b = take("reward")
            if cfg.norm_obs:
                obs_b, next_b = (nz.normalize_obs(norm.obs_rms, o, hp["clip_obs"], hp["norm_epsilon"]).astype(f32)
                                 for o in (obs_b, next_b))
            if cfg.norm_reward:
                rew_b = nz.normalize_reward(norm.ret_rms, rew_b, hp["clip_reward"], hp["norm_epsilon"]).astype(f32)
            data = (obs_b, take("action"), next_b, rew_b, take("done"))

            def one(learner, x):
                batch, k = x
                return algo.update(learner, batch, k, lr, hp)

            learner, losses = jax.lax.scan(one, learner, (data, jax.random.split(k_steps, G)))
            return learner, tuple(x[-1] for x in losses)

        def collect(carry, u):
            learner, norm, env_state, obs_raw, obs_n, ep_ret, ep_len, ring, key = carry
            key, k_roll, k_eps, k_grad = jax.random.split(key, 4)
            eps_held = standard_normal(k_eps, (B, act_dim))  # use_sde: one draw per collect (reset_noise)
            (learner, norm, env_state, obs_raw, obs_n, ep_ret, ep_len, ring, _), ended = jax.lax.scan(
                env_step, (learner, norm, env_state, obs_raw, obs_n, ep_ret, ep_len, ring, eps_held),
                (jax.random.split(k_roll, F), u * F + jnp.arange(F)))
            steps = (u + 1) * cfg.rollout
            lr = hp["learning_rate"] * ((1.0 - steps / total) if cfg.lr_linear else 1.0)
            nan = jnp.full((), jnp.nan, f32)
            learner, losses = jax.lax.cond(steps > cfg.learning_starts,
                                           lambda lrn: gradient_steps(lrn, norm, ring, k_grad, lr),
                                           lambda lrn: (lrn, (nan,) * len(algo.LOSSES)), learner)
            n_ep, ret_sum, len_sum = (jnp.sum(x) for x in ended)
            has = n_ep > 0
            curve = {"steps": steps,
                     "episode_return": jnp.where(has, ret_sum / jnp.maximum(n_ep, 1), jnp.nan),
                     "episode_length": jnp.where(has, len_sum / jnp.maximum(n_ep, 1), jnp.nan),
                     "episodes": n_ep, **dict(zip(algo.LOSSES, (x.astype(f32) for x in losses)))}
            return (learner, norm, env_state, obs_raw, obs_n, ep_ret, ep_len, ring, key), curve

        carry = (learner, norm, env_state, obs, obs_n.astype(f32), jnp.zeros((B,), stat_dtype),
                 jnp.zeros((B,), jnp.int32), ring, key)
        if snap_at is None:
            carry, curve = jax.lax.scan(collect, carry, jnp.arange(cfg.n_updates))
        else:
            first = snapshot(learner[0], norm)
            buf = keep(jax.tree.map(lambda x: jnp.zeros((snap_at.size,) + x.shape, x.dtype), first), first, 0)

            def collect_and_keep(c, u):
                c, buf = c
                c, curve = collect(c, u)
                return (c, keep(buf, snapshot(c[0][0], c[1]), u + 1)), curve

            (carry, buf), curve = jax.lax.scan(collect_and_keep, (carry, buf), jnp.arange(cfg.n_updates))
        learner, norm, ring = carry[0], carry[1], carry[7]
        out = {**algo.outputs(learner), "obs_mean": norm.obs_rms.mean,
               "obs_var": norm.obs_rms.var, "obs_count": norm.obs_rms.count, "ret_var": norm.ret_rms.var,
               "ret_count": norm.ret_rms.count, "curve": curve, "buffer_pos": ring[1], "buffer_full": ring[2]}
        if snap_at is not None:
            out["snapshots"] = buf
        if return_buffer:
            out["buffer"] = ring[0]
        return out

    return train
