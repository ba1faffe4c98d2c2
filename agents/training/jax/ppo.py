"""PPO as one compiled function, on the centralised JAX environments (:mod:`dobs_envs.jax`).

The trainer follows PureJaxRL (Lu et al. 2022, ``purejaxrl/ppo_continuous_action.py``): a whole run is
``lax.scan`` over updates of (a ``lax.scan`` rollout of ``n_envs`` vmapped copies for ``n_steps`` steps,
GAE, ``n_epochs`` epochs of shuffled minibatches), so ``jax.jit(train)`` compiles it once and
``jax.vmap(train)`` runs seeds (and the float hyperparameters of :data:`HPARAMS`) side by side.
What it computes is stable-baselines3 2.x PPO with ``VecNormalize``, as the shipped recipes train it
(``agents/hyperparams/ppo.yaml``):

- policy: :mod:`agents.training.jax.policy` (SB3's ``MlpPolicy``: separate actor and critic MLPs,
  orthogonal initialisation, state-independent ``log_std`` starting at ``log_std_init``);
- rollout: the sampled (unclipped) action is stored, ``clip(a, low, high)`` is applied (the action
  space, ``[-1, 1]`` with ``normalize_actions``: the environment's ``normalized_actions`` option scales
  it by the input bounds, as ``RescaleAction`` does for the symmetric bounds of these environments);
  observations and rewards go through :func:`agents.training.jax.normalize.norm_step` (``VecNormalize``);
  an episode cut by the time limit (truncated, not terminated) gets ``r <- r + gamma V(o_final)``,
  ``o_final`` its final observation normalised with the current statistics (SB3's
  ``collect_rollouts``);
- GAE (Schulman et al. 2016): ``delta_t = r_t + gamma V_{t+1} (1 - d_t) - V_t``,
  ``A_t = delta_t + gamma lambda (1 - d_t) A_{t+1}``, returns ``A_t + V_t``;
- loss per minibatch: advantages normalised ``(A - mean) / (std + 1e-8)`` (``std`` with ``ddof=1``
  as torch's), ``L = -mean(min(rho A, clip(rho, 1 -+ eps) A)) - ent_coef mean(H) + vf_coef
  mean((R - V)^2)`` (no value clipping, ``clip_range_vf=None``), gradients clipped to global norm
  ``max_grad_norm`` (``clip_grad_norm_``), Adam with ``eps = 1e-5``;
- schedules: ``lin_x`` means ``x * p``, ``p = 1 - steps / total_timesteps`` with ``steps`` counted
  after the update's rollout (SB3's ``progress_remaining``; the runs take ``ceil(total / (n_envs
  n_steps))`` updates, so the last one may overshoot the budget, as SB3's does).

Why not rejax 0.1.3's ``PPO`` (measured on tracking, same sizes, one core: the same CPU time per step
within the noise of a shared machine): it cannot express the shipped recipe. Its Gaussian policy starts
at ``log_std = 0`` (the recipe: -2; the recipes' comments record that a large initial std makes these
plants leave the state bound), its learning rate is a constant (the recipe: ``lin_3e-4``), its
``max_grad_norm`` clips each gradient element (``optax.clip``), not the global norm, its critic loss is
always value-clipped, it treats truncation as termination (no bootstrap of the 400-step time limit), its
normalisers clip neither observations nor rewards, and the actor and critic have separate optimisers
and default (not orthogonal) initialisation. It also needs distrax (which pulls tfp-nightly) and
gymnax 1.0 (``gymnasium < 1.4``: it conflicts with the main environment, so it cannot go into the
``jax`` extra).

The hyperparameters are the recipe's keys (the merged section of ``agents/hyperparams/ppo.yaml``, e.g.
``agents.training.recipes.resolve_recipe("ppo", "tracking").hyperparams``), read by :func:`ppo_config`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from . import normalize as nz
from . import policy as pol
from ..xla import check_xla_runtime
from .envs import make_env
from .validate import float_dtype, pos_int, schedule, train_env_kwargs, vec_normalize

__all__ = ["PPOConfig", "HPARAMS", "ppo_config", "make_env", "make_train", "VecSlots", "gymnax_slots"]

#: float hyperparameters passed to ``train(key, hparams)``: traced, so ``jax.vmap`` sweeps them
HPARAMS = ("learning_rate", "clip_range", "gamma", "gae_lambda", "ent_coef", "vf_coef", "max_grad_norm",
           "log_std_init", "norm_gamma", "clip_obs", "clip_reward", "norm_epsilon")

#: recipe keys read by :func:`ppo_config` (anything else is refused with its name)
RECIPE_KEYS = ("policy", "n_envs", "n_timesteps", "n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda",
               "learning_rate", "clip_range", "ent_coef", "vf_coef", "max_grad_norm", "normalize",
               "normalize_actions", "policy_kwargs", "env_kwargs", "normalize_advantage")
_POLICY_KWARGS = ("net_arch", "activation_fn", "log_std_init", "ortho_init")
_NORMALIZE_KEYS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")


@dataclass(frozen=True)
class PPOConfig:
    """What fixes the shapes and branches of a run (static under ``jit``); the float hyperparameters
    are the ``hparams`` dict of :func:`ppo_config` (:data:`HPARAMS`)."""
    env_id: str
    total_timesteps: int
    n_envs: int = 8
    n_steps: int = 2048
    batch_size: int = 64
    n_epochs: int = 10
    net_arch: tuple = (64, 64)
    activation: str = "tanh"
    lr_linear: bool = False
    clip_linear: bool = False
    norm_obs: bool = False
    norm_reward: bool = False
    normalize_actions: bool = False
    normalize_advantage: bool = True
    env_kwargs: dict = field(default_factory=dict)
    dtype: str = "float32"

    @property
    def n_updates(self) -> int:
        """Updates of a run: ``ceil(total_timesteps / (n_envs n_steps))`` (SB3's loop)."""
        return -(-self.total_timesteps // (self.n_envs * self.n_steps))

    @property
    def steps_done(self) -> int:
        """Env steps a run takes: ``n_updates n_envs n_steps`` (at least ``total_timesteps``)."""
        return self.n_updates * self.n_envs * self.n_steps

    @property
    def n_minibatches(self) -> int:
        return self.n_envs * self.n_steps // self.batch_size


def ppo_config(hyperparams: dict, env_id: str = "dobs_envs/Tracking-v0", *, total_timesteps: int | None = None,
               dtype: str = "float32") -> tuple[PPOConfig, dict]:
    """``(config, hparams)`` of a recipe's hyperparameters (SB3/rl-zoo3 names, defaults SB3's).

    Parameters
    ----------
    hyperparams : the recipe's keys (:data:`RECIPE_KEYS`): ``n_envs``, ``n_steps``, ``batch_size``,
        ``n_epochs``, ``gamma``, ``gae_lambda``, ``learning_rate`` and ``clip_range`` (number or
        ``"lin_<x>"``), ``ent_coef``, ``vf_coef``, ``max_grad_norm``, ``normalize`` (False/True or
        ``VecNormalize``'s ``norm_obs``, ``norm_reward``, ``clip_obs``, ``clip_reward``, ``gamma`` (default:
        the algorithm's), ``epsilon``), ``normalize_actions``, ``policy_kwargs`` (``net_arch`` a list,
        ``activation_fn`` ``"tanh"``/``"relu"``, ``log_std_init``), ``env_kwargs`` (training-only env
        options), ``n_timesteps``. A key the trainer does not implement raises ``ValueError``.
    env_id : a Gymnasium id of :func:`dobs_envs.jax.registered_envs`.
    total_timesteps : the budget (default ``n_timesteps``).
    dtype : ``"float32"`` or ``"float64"``: the environment's (and the normaliser's) float type; the
        networks are float32 either way (as SB3's).
    """
    if not isinstance(hyperparams, dict):
        raise TypeError(f"hyperparams must be a dict of recipe keys, got {type(hyperparams).__name__}")
    unknown = sorted(set(hyperparams) - set(RECIPE_KEYS))
    if unknown:
        raise ValueError(f"hyperparameters {unknown} are not implemented by the JAX PPO trainer; "
                         f"supported keys: {list(RECIPE_KEYS)}")
    hp = dict(hyperparams)
    if hp.get("policy", "MlpPolicy") != "MlpPolicy":
        raise ValueError(f"policy must be 'MlpPolicy', got {hp['policy']!r}")
    pk = dict(hp.get("policy_kwargs") or {})
    bad = sorted(set(pk) - set(_POLICY_KWARGS))
    if bad:
        raise ValueError(f"policy_kwargs {bad} are not implemented; supported: {list(_POLICY_KWARGS)}")
    if pk.get("ortho_init", True) is not True:
        raise ValueError("policy_kwargs.ortho_init must be True (the trainer initialises as SB3's default)")
    net_arch = pk.get("net_arch", [64, 64])
    if not isinstance(net_arch, (list, tuple)) or not net_arch:
        raise ValueError(f"policy_kwargs.net_arch must be a non-empty list of layer widths (shared by actor and "
                         f"critic), got {net_arch!r}")
    net_arch = tuple(pos_int("policy_kwargs.net_arch[i]", h) for h in net_arch)
    activation = str(pk.get("activation_fn", "tanh")).lower().removeprefix("nn.")
    if activation not in pol.ACTIVATIONS:
        raise ValueError(f"policy_kwargs.activation_fn must be one of {list(pol.ACTIVATIONS)}, got "
                         f"{pk.get('activation_fn')!r}")
    norm = vec_normalize(hp.get("normalize", False), _NORMALIZE_KEYS)
    lr, lr_linear = schedule("learning_rate", hp.get("learning_rate", 3e-4))
    clip, clip_linear = schedule("clip_range", hp.get("clip_range", 0.2))
    n_envs, n_steps = pos_int("n_envs", hp.get("n_envs", 1)), pos_int("n_steps", hp.get("n_steps", 2048))
    batch = pos_int("batch_size", hp.get("batch_size", 64))
    if (n_envs * n_steps) % batch:
        raise ValueError(f"batch_size {batch} must divide n_envs * n_steps = {n_envs * n_steps} (equal minibatches)")
    total = pos_int("total_timesteps", hp.get("n_timesteps", 1_000_000) if total_timesteps is None
                     else total_timesteps)
    float_dtype(dtype)
    env_kwargs = train_env_kwargs(hp.get("env_kwargs"))
    cfg = PPOConfig(env_id=env_id, total_timesteps=total, n_envs=n_envs, n_steps=n_steps, batch_size=batch,
                    n_epochs=pos_int("n_epochs", hp.get("n_epochs", 10)), net_arch=net_arch, activation=activation,
                    lr_linear=lr_linear, clip_linear=clip_linear, norm_obs=bool(norm.get("norm_obs", True)),
                    norm_reward=bool(norm.get("norm_reward", True)),
                    normalize_actions=bool(hp.get("normalize_actions", False)),
                    normalize_advantage=bool(hp.get("normalize_advantage", True)), env_kwargs=env_kwargs,
                    dtype=dtype)
    gamma = float(hp.get("gamma", 0.99))
    hparams = {"learning_rate": lr, "clip_range": clip, "gamma": gamma,
               "gae_lambda": float(hp.get("gae_lambda", 0.95)), "ent_coef": float(hp.get("ent_coef", 0.0)),
               "vf_coef": float(hp.get("vf_coef", 0.5)), "max_grad_norm": float(hp.get("max_grad_norm", 0.5)),
               "log_std_init": float(pk.get("log_std_init", 0.0)), "norm_gamma": float(norm.get("gamma", gamma)),
               "clip_obs": float(norm.get("clip_obs", 10.0)), "clip_reward": float(norm.get("clip_reward", 10.0)),
               "norm_epsilon": float(norm.get("epsilon", 1e-8))}
    return cfg, hparams


def _clip_by_global_norm(grads, max_norm):
    """``clip_grad_norm_``: scale by ``min(1, max_norm / (||g|| + 1e-6))``."""
    norm = optax.tree.norm(grads)
    scale = jnp.minimum(1.0, max_norm / (norm + 1e-6))
    return jax.tree.map(lambda g: g * scale, grads)


class VecSlots(NamedTuple):
    """The vectorised environment a run steps, as the trainer sees it: ``n_slots`` samples per vector step
    (the policy's batch) from ``copies`` environment copies (``n_slots = copies``: the centralised env, one
    slot per copy; :mod:`agents.training.jax.ippo`: one slot per (copy, agent), ``n_slots = copies * K``).

    ``reset(key) -> (obs (N, D), state)``; ``step(key, state, action (N, m)) -> (obs (N, D), state,
    reward (N,), terminated (N,), truncated (N,), final_obs (N, D))`` with auto-reset (``obs``: the next
    episode's first observation where an episode ended, ``final_obs`` its last one); ``action`` already
    clipped to ``[low, high]`` (the policy's action space). Budgets, schedules and the curve's ``steps``
    count environment steps: ``copies`` per vector step, whatever ``n_slots``."""
    n_slots: int
    copies: int
    obs_dim: int
    act_dim: int
    low: Any
    high: Any
    reset: Callable
    step: Callable


def gymnax_slots(env, env_params, n_envs: int) -> VecSlots:
    """:class:`VecSlots` of ``n_envs`` vmapped copies of a gymnax-style env (:func:`dobs_envs.jax.make`): one slot
    per copy, the action space's bounds, ``info["final_observation"]``."""
    obs_dim = int(np.prod(env.observation_space(env_params).shape))
    act_dim = int(env.num_actions)
    space = env.action_space(env_params)
    low = jnp.asarray(np.broadcast_to(np.asarray(space.low, np.float32), (act_dim,)))
    high = jnp.asarray(np.broadcast_to(np.asarray(space.high, np.float32), (act_dim,)))
    v_step = jax.vmap(env.step, in_axes=(0, 0, 0, None))
    v_reset = jax.vmap(env.reset, in_axes=(0, None))

    def reset(key):
        return v_reset(jax.random.split(key, n_envs), env_params)

    def step(key, state, action):
        obs, state, reward, term, trunc, info = v_step(jax.random.split(key, n_envs), state, action, env_params)
        return obs, state, reward, term, trunc, info["final_observation"]

    return VecSlots(n_envs, n_envs, obs_dim, act_dim, low, high, reset, step)


def make_train(cfg: PPOConfig, env=None, env_params=None, snapshots=None, *, slots: VecSlots | None = None):
    """``train(key, hparams) -> dict``: one PPO run as a pure function (``jax.jit`` / ``jax.vmap`` it).

    Parameters
    ----------
    cfg : the static configuration (:func:`ppo_config`).
    env, env_params : the environment (default :func:`make_env`).
    snapshots : update counts in ``0 .. cfg.n_updates`` (0: the initial policy) after which the
        actor and the observation statistics are kept (a learning curve evaluated after the run, as
        :mod:`agents.training.jax.run` does); default none.
    slots : the vectorised environment as :class:`VecSlots` (default :func:`gymnax_slots` of ``env``: one slot per
        copy); :mod:`agents.training.jax.ippo` passes one slot per (copy, agent) of the multi-agent view.
        ``batch_size`` must divide ``n_slots * n_steps``.

    Returns
    -------
    train : ``train(key, hparams)``, ``hparams`` a dict of the :data:`HPARAMS` scalars (the second
        output of :func:`ppo_config`; vmap over any of them). Its result is a dict:

        - ``params``: the actor-critic's arrays (:mod:`agents.training.jax.policy`);
        - ``obs_mean (D,)``, ``obs_var (D,)``, ``obs_count``, ``ret_var``, ``ret_count``: the normaliser's
          statistics at the end (what :mod:`agents.training.jax.export` needs: the observation part);
        - ``curve``: per update ``steps (U,)`` (env steps after its rollout), ``episode_return (U,)`` and
          ``episode_length (U,)`` (means over the episodes that ended in that rollout, NaN if none:
          the raw rewards, as SB3's ``Monitor``), ``episodes (U,)`` (their count, one per slot), ``approx_kl (U,)``,
          ``value_loss (U,)`` (means over the update's minibatches);
        - ``snapshots`` (with ``snapshots``, K of them in increasing order): the actor's arrays ``pi_*``
          ``(K, ...)``, ``obs_mean (K, D)`` and ``obs_var (K, D)`` after those updates.
    """
    check_xla_runtime("agents.training.jax.ppo.make_train")
    if slots is None:
        if env is None:
            env, env_params = make_env(cfg)
        elif env_params is None:
            env_params = env.default_params
        slots = gymnax_slots(env, env_params, cfg.n_envs)
    N, T = slots.n_slots, cfg.n_steps
    obs_dim, act_dim, a_low, a_high = slots.obs_dim, slots.act_dim, slots.low, slots.high
    stat_dtype = jnp.float64 if cfg.dtype == "float64" else jnp.float32
    n_samples, total = N * T, float(cfg.total_timesteps)
    if n_samples % cfg.batch_size:
        raise ValueError(f"batch_size {cfg.batch_size} must divide the rollout's {n_samples} samples (equal "
                         f"minibatches)")
    n_mb, env_steps = n_samples // cfg.batch_size, slots.copies * T  # env steps per update
    adam = optax.scale_by_adam(eps=1e-5)
    act_fn = cfg.activation
    snap_at = None
    if snapshots is not None:
        snap_at = np.unique(np.asarray([int(u) for u in snapshots], dtype=np.int64))
        if snap_at.size == 0 or snap_at[0] < 0 or snap_at[-1] > cfg.n_updates:
            raise ValueError(f"snapshots must be update counts in 0..{cfg.n_updates}, got {list(snapshots)!r}")

    def snapshot(params, norm):
        return {**{k: v for k, v in params.items() if k.startswith("pi_")}, "obs_mean": norm.obs_rms.mean,
                "obs_var": norm.obs_rms.var}

    def keep(buf, snap, count):
        """``buf`` with ``snap`` written at the slot of update count ``count`` (unchanged if none)."""
        slot = jnp.minimum(jnp.searchsorted(jnp.asarray(snap_at), count), snap_at.size - 1)
        hit = jnp.asarray(snap_at)[slot] == count
        return jax.tree.map(lambda b, x: b.at[slot].set(jnp.where(hit, x.astype(b.dtype), b[slot])), buf, snap)

    def train(key, hparams: dict):
        hp = {k: jnp.asarray(hparams[k]) for k in HPARAMS}
        k_init, k_reset, key = jax.random.split(key, 3)
        params = pol.init_params(k_init, obs_dim, act_dim, cfg.net_arch, hp["log_std_init"])
        opt_state = adam.init(params)
        obs, env_state = slots.reset(k_reset)
        norm = nz.norm_init((obs_dim,), N, stat_dtype)
        if cfg.norm_obs:  # VecNormalize.reset updates the statistics with the first observations
            norm = norm._replace(obs_rms=nz.rms_update(norm.obs_rms, obs))
            obs_n = nz.normalize_obs(norm.obs_rms, obs, hp["clip_obs"], hp["norm_epsilon"])
        else:
            obs_n = obs
        obs_n = obs_n.astype(jnp.float32)
        zeros = jnp.zeros((N,), stat_dtype)

        def env_step(carry, k):
            params, norm, env_state, obs_n, ep_ret, ep_len = carry
            k_act, k_env = jax.random.split(k)
            mean = pol.actor_mean(params, obs_n, act_fn)
            action = mean + jnp.exp(params["log_std"]) * jax.random.normal(k_act, mean.shape, jnp.float32)
            logp = pol.log_prob(params, mean, action)
            v = pol.value(params, obs_n, act_fn)
            obs, env_state, reward, term, trunc, final = slots.step(k_env, env_state, jnp.clip(action, a_low, a_high))
            done = term | trunc
            norm, next_obs_n, rew_n = nz.norm_step(
                norm, obs, reward, done, gamma=hp["norm_gamma"], clip_obs=hp["clip_obs"],
                clip_reward=hp["clip_reward"], epsilon=hp["norm_epsilon"], norm_obs=cfg.norm_obs,
                norm_reward=cfg.norm_reward)
            if cfg.norm_obs:
                final = nz.normalize_obs(norm.obs_rms, final, hp["clip_obs"], hp["norm_epsilon"])
            v_final = pol.value(params, final.astype(jnp.float32), act_fn)
            rew_n = rew_n.astype(jnp.float32) + jnp.where(trunc & ~term, hp["gamma"] * v_final, 0.0)
            ep_ret = ep_ret + reward.astype(stat_dtype)
            ep_len = ep_len + 1
            ended = (jnp.sum(done), jnp.sum(jnp.where(done, ep_ret, 0.0)), jnp.sum(jnp.where(done, ep_len, 0)))
            carry = (params, norm, env_state, next_obs_n.astype(jnp.float32),
                     jnp.where(done, 0.0, ep_ret), jnp.where(done, 0, ep_len))
            return carry, ((obs_n, action, logp, v, rew_n, done.astype(jnp.float32)), ended)

        def loss_fn(params, batch, clip_eps):
            obs_b, act_b, logp_old, adv, ret = batch
            mean = pol.actor_mean(params, obs_b, act_fn)
            logp = pol.log_prob(params, mean, act_b)
            v = pol.value(params, obs_b, act_fn)
            if cfg.normalize_advantage:
                adv = (adv - adv.mean()) / (adv.std(ddof=1) + 1e-8)
            log_ratio = logp - logp_old
            ratio = jnp.exp(log_ratio)
            pg = -jnp.mean(jnp.minimum(adv * ratio, adv * jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps)))
            v_loss = jnp.mean((ret - v) ** 2)
            ent_loss = -pol.entropy(params)  # state independent: its mean over the batch
            loss = pg + hp["ent_coef"] * ent_loss + hp["vf_coef"] * v_loss
            approx_kl = jnp.mean((ratio - 1.0) - log_ratio)
            return loss, (v_loss, approx_kl)

        def update(carry, u):
            params, opt_state, norm, env_state, obs_n, ep_ret, ep_len, key = carry
            key, k_roll, k_perm = jax.random.split(key, 3)
            (params, norm, env_state, obs_n, ep_ret, ep_len), (traj, ended) = jax.lax.scan(
                env_step, (params, norm, env_state, obs_n, ep_ret, ep_len), jax.random.split(k_roll, T))
            obs_t, act_t, logp_t, v_t, rew_t, done_t = traj
            last_v = pol.value(params, obs_n, act_fn)

            def gae(carry, x):
                adv_next, v_next = carry
                r, v, d = x
                delta = r + hp["gamma"] * v_next * (1.0 - d) - v
                adv = delta + hp["gamma"] * hp["gae_lambda"] * (1.0 - d) * adv_next
                return (adv, v), adv

            _, adv_t = jax.lax.scan(gae, (jnp.zeros_like(last_v), last_v), (rew_t, v_t, done_t), reverse=True)
            data = tuple(x.reshape((n_samples,) + x.shape[2:]) for x in (obs_t, act_t, logp_t, adv_t, adv_t + v_t))
            progress = 1.0 - (u + 1.0) * env_steps / total  # SB3's progress_remaining after the rollout
            lr = hp["learning_rate"] * (progress if cfg.lr_linear else 1.0)
            clip_eps = hp["clip_range"] * (progress if cfg.clip_linear else 1.0)

            def minibatch(carry, idx):
                params, opt_state = carry
                batch = tuple(x[idx] for x in data)
                grads, (v_loss, kl) = jax.grad(loss_fn, has_aux=True)(params, batch, clip_eps)
                grads = _clip_by_global_norm(grads, hp["max_grad_norm"])
                step, opt_state = adam.update(grads, opt_state)
                params = jax.tree.map(lambda p, s: p - lr * s, params, step)
                return (params, opt_state), (v_loss, kl)

            def epoch(carry, k):
                idx = jax.random.permutation(k, n_samples).reshape(n_mb, cfg.batch_size)
                return jax.lax.scan(minibatch, carry, idx)

            (params, opt_state), (v_loss, kl) = jax.lax.scan(epoch, (params, opt_state),
                                                             jax.random.split(k_perm, cfg.n_epochs))
            n_ep, ret_sum, len_sum = (jnp.sum(x) for x in ended)
            has = n_ep > 0
            curve = {"steps": (u + 1) * env_steps,
                     "episode_return": jnp.where(has, ret_sum / jnp.maximum(n_ep, 1), jnp.nan),
                     "episode_length": jnp.where(has, len_sum / jnp.maximum(n_ep, 1), jnp.nan),
                     "episodes": n_ep, "approx_kl": kl.mean(), "value_loss": v_loss.mean()}
            return (params, opt_state, norm, env_state, obs_n, ep_ret, ep_len, key), curve

        carry = (params, opt_state, norm, env_state, obs_n, zeros, jnp.zeros((N,), jnp.int32), key)
        if snap_at is None:
            carry, curve = jax.lax.scan(update, carry, jnp.arange(cfg.n_updates))
        else:
            first = snapshot(params, norm)
            buf = keep(jax.tree.map(lambda x: jnp.zeros((snap_at.size,) + x.shape, x.dtype), first), first, 0)

            def update_and_keep(c, u):
                c, buf = c
                c, curve = update(c, u)
                return (c, keep(buf, snapshot(c[0], c[2]), u + 1)), curve

            (carry, buf), curve = jax.lax.scan(update_and_keep, (carry, buf), jnp.arange(cfg.n_updates))
        params, norm = carry[0], carry[2]
        out = {"params": params, "obs_mean": norm.obs_rms.mean, "obs_var": norm.obs_rms.var,
               "obs_count": norm.obs_rms.count, "ret_var": norm.ret_rms.var, "ret_count": norm.ret_rms.count,
               "curve": curve}
        if snap_at is not None:
            out["snapshots"] = buf
        return out

    return train

