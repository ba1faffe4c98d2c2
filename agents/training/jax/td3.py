"""TD3 as one compiled function: SBX's ``TD3`` in the off-policy loop of :mod:`.sac`.

The run is :func:`agents.training.jax.sac.offpolicy_train` (SB3's collect / train loop, the replay ring buffer,
``VecNormalize``, truncation bootstrapped from the final observation: see :mod:`.sac`) with TD3's learner, as
SBX 0.2x's ``sbx/td3/td3.py`` and ``policies.py`` compute it, configured by the shipped recipes
(``agents/config/hyperparams/td3.yaml``):

- actor (SBX's TD3 ``Actor``): ``pi(o) = tanh(MLP(o))``, deterministic; twin critics as SAC's; target copies of
  the actor and the critics, initialised equal;
- per gradient step (SBX's ``update_critic``, ``soft_update``, then every ``policy_delay``-th step
  ``update_actor``): ``a' = clip(pi'(o') + clip(sigma' eps, -c, c), -1, 1)`` (target policy smoothing,
  ``sigma' = target_policy_noise``, ``c = target_noise_clip``, ``eps ~ N(0, 1)``),
  ``y = r + (1 - d) gamma min_c Q'_c(o', a')``, ``L_Q = 1/2 sum_c mean (y - Q_c(o, a))^2``; both targets
  ``theta' <- tau theta + (1 - tau) theta'`` after *every* critic step (SBX's order: the actor target
  follows the actor at every step, the actor itself is delayed); the actor step
  ``L_pi = -mean(min_c Q_c(o, pi(o)))`` with the updated critics when ``(j + 1) % policy_delay == 0``, ``j``
  the gradient steps taken before in the run (SBX's ``policy_delay_offset``);
- optimisers: Adam (``eps = 1e-8``) at ``learning_rate`` (``lin_x`` as in :mod:`.sac`), actor and critics;
- exploration (SB3's ``_sample_action`` with ``NormalActionNoise``): ``a = clip(pi(o) + noise_std eps, -1, 1)``,
  the noise added to the uniform random actions before ``learning_starts`` too (``noise_type: normal``).

Deliberate differences from SBX: the random streams (as :mod:`.sac`; a Gaussian draw from a key is SBX's
``jax.random.normal``, so gradient steps from the same state, batch and keys are SBX's, tested); not
implemented (refused by name): ``noise_type`` other than ``normal`` (``ornstein-uhlenbeck``, ``pink``),
``n_steps``, ``qf_learning_rate``, ``param_resets``, the keys of :mod:`.sac`'s list.

The hyperparameters are the recipe's keys (``agents.training.recipes.resolve_recipe("td3", env).hyperparams``),
read by :func:`td3_config`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import jax
import jax.numpy as jnp

from .policy import ACTIVATIONS
from .sac import (_ADAM, SACConfig, _adam_step, _critic_params, init_params, make_env, offpolicy_fields,
                  offpolicy_train, polyak, q_values)
from .validate import number, pos_int

__all__ = ["TD3Config", "HPARAMS", "RECIPE_KEYS", "td3_config", "make_env", "make_train", "init_td3",
           "actor_action", "critic_loss", "actor_loss", "update_step", "TD3Hooks"]

#: float hyperparameters passed to ``train(key, hparams)``: traced, so ``jax.vmap`` sweeps them
HPARAMS = ("learning_rate", "tau", "gamma", "target_policy_noise", "target_noise_clip", "noise_std", "norm_gamma",
           "clip_obs", "clip_reward", "norm_epsilon")

#: recipe keys read by :func:`td3_config` (anything else is refused with its name)
RECIPE_KEYS = ("policy", "n_envs", "n_timesteps", "learning_rate", "buffer_size", "learning_starts", "batch_size",
               "tau", "gamma", "train_freq", "gradient_steps", "policy_delay", "target_policy_noise",
               "target_noise_clip", "noise_type", "noise_std", "normalize", "normalize_actions", "policy_kwargs",
               "env_kwargs")


@dataclass(frozen=True)
class TD3Config(SACConfig):
    """:class:`~.sac.SACConfig`'s loop and sizes with TD3's ``policy_delay`` (static: it fixes the branch of each
    gradient step); ``ent_auto`` and ``use_sde`` are unused."""
    policy_delay: int = 2

    TRAINER: ClassVar[str] = "agents.training.jax.td3"


def td3_config(hyperparams: dict, env_id: str = "dobs_envs/Tracking-v0", *, total_timesteps: int | None = None,
               dtype: str = "float32") -> tuple[TD3Config, dict]:
    """``(config, hparams)`` of a recipe's hyperparameters (SB3/rl-zoo3 names, defaults SBX's TD3).

    Parameters
    ----------
    hyperparams : the recipe's keys (:data:`RECIPE_KEYS`): those of :func:`agents.training.jax.sac.sac_config`
        shared by the off-policy algorithms (:func:`~.sac.offpolicy_fields`), ``policy_delay`` (2),
        ``target_policy_noise`` (0.2), ``target_noise_clip`` (0.5), ``noise_type`` (``"normal"`` only) and
        ``noise_std`` (the exploration noise's standard deviation in ``[-1, 1]`` action units; none without
        ``noise_type``). A key the trainer does not implement raises ``ValueError`` naming it.
    env_id, total_timesteps, dtype : as :func:`~.sac.sac_config`.
    """
    fields, hparams, hp = offpolicy_fields(hyperparams, RECIPE_KEYS, "TD3", total_timesteps=total_timesteps,
                                           dtype=dtype)
    noise_type = hp.get("noise_type")
    if noise_type not in (None, "normal"):
        raise ValueError(f"noise_type {noise_type!r} is not implemented by the JAX TD3 trainer (normal only)")
    noise_std = number("noise_std", hp.get("noise_std", 0.1)) if noise_type else 0.0
    cfg = TD3Config(env_id=env_id, ent_auto=False, use_sde=False,
                    policy_delay=pos_int("policy_delay", hp.get("policy_delay", 2)), **fields)
    hparams.update(target_policy_noise=number("target_policy_noise", hp.get("target_policy_noise", 0.2)),
                   target_noise_clip=number("target_noise_clip", hp.get("target_noise_clip", 0.5)),
                   noise_std=noise_std)
    return cfg, hparams


def init_td3(key, obs_dim: int, act_dim: int, net_arch) -> dict:
    """The actor (``pi_w{i}``, ``pi_b{i}``: the MLP whose ``tanh`` is the action; the exported arrays) and the
    twin critics (``qf_*``, as :func:`~.sac.init_params`), flax ``Dense`` initialisation."""
    params = init_params(key, obs_dim, act_dim, net_arch)
    del params["ls_w"], params["ls_b"]
    return params


def actor_action(params: dict, obs, activation: str):
    """``pi(obs) = tanh(MLP(obs))``: ``(..., D) -> (..., m)`` in ``[-1, 1]``."""
    act = ACTIVATIONS[activation]
    n = sum(1 for k in params if k.startswith("pi_w"))
    x = obs.astype(jnp.float32)
    for i in range(n):
        x = x @ params[f"pi_w{i}"] + params[f"pi_b{i}"]
        if i < n - 1:
            x = act(x)
    return jnp.tanh(x)


def critic_loss(qf: dict, target: dict, batch, gamma, noise_std, noise_clip, key, activation: str):
    """``L_Q = 1/2 sum_c mean_b (y - Q_c(o, a))^2``, ``y = r + (1 - d) gamma min_c Q'_c(o', a')`` with the
    smoothed target action ``a' = clip(pi'(o') + clip(noise_std eps, -noise_clip, noise_clip), -1, 1)``,
    ``eps = jax.random.normal(key, a.shape)``; ``target`` holds the target actor and critics."""
    obs, act, next_obs, rew, done = batch
    noise = jnp.clip(jax.random.normal(key, act.shape, jnp.float32) * noise_std, -noise_clip, noise_clip)
    a_next = jnp.clip(actor_action(target, next_obs, activation) + noise, -1.0, 1.0)
    q_next = jnp.min(q_values(_critic_params(target), next_obs, a_next, activation), axis=0)
    y = jax.lax.stop_gradient(rew + (1.0 - done) * gamma * q_next)
    q = q_values(qf, obs, act, activation)
    return 0.5 * jnp.sum(jnp.mean((y[None] - q) ** 2, axis=1))


def actor_loss(actor: dict, qf: dict, obs, activation: str):
    """``L_pi = -mean_b min_c Q_c(o, pi(o))``."""
    return -jnp.mean(jnp.min(q_values(qf, obs, actor_action(actor, obs, activation), activation), axis=0))


def _actor_params(params):
    return {k: v for k, v in params.items() if k.startswith("pi_")}


def init_opts(params: dict):
    """The Adam states ``(actor, critics)`` of a new run."""
    return _ADAM.init(_actor_params(params)), _ADAM.init(_critic_params(params))


def update_step(state, batch, key, *, lr, gamma, tau, noise_std, noise_clip, activation: str, policy_delay: int):
    """One TD3 gradient step (SBX's ``update_critic``, ``soft_update``, and ``update_actor`` on every
    ``policy_delay``-th step). ``state = (params, target, opts, count)`` (``count``: the gradient steps taken
    before); ``key`` draws the target policy smoothing noise. Returns ``(state', (critic loss, actor loss))``,
    the actor loss NaN on a step without actor update."""
    params, target, (o_pi, o_qf), count = state
    actor, qf = _actor_params(params), _critic_params(params)
    q_loss, g_qf = jax.value_and_grad(critic_loss)(qf, target, batch, gamma, noise_std, noise_clip, key, activation)
    qf, o_qf = _adam_step(qf, g_qf, o_qf, lr)
    target = polyak({**actor, **qf}, target, tau)

    def actor_step(args):
        actor, o_pi = args
        pi_loss, g_pi = jax.value_and_grad(actor_loss)(actor, qf, batch[0], activation)
        actor, o_pi = _adam_step(actor, g_pi, o_pi, lr)
        return actor, o_pi, pi_loss

    actor, o_pi, pi_loss = jax.lax.cond((count + 1) % policy_delay == 0, actor_step,
                                        lambda args: (*args, jnp.full((), jnp.nan, jnp.float32)), (actor, o_pi))
    return ({**actor, **qf}, target, (o_pi, o_qf), count + 1), (q_loss, pi_loss)


class TD3Hooks:
    """What :func:`~.sac.offpolicy_train` asks of TD3: the learner's state ``(params, targets, Adam states,
    gradient steps taken)``, the exploring action, one gradient step, the run's outputs."""
    HPARAMS = HPARAMS
    LOSSES = ("critic_loss", "actor_loss")

    def __init__(self, cfg: TD3Config, obs_dim: int, act_dim: int):
        self.cfg, self.obs_dim, self.act_dim = cfg, obs_dim, act_dim

    def init(self, key, hp):
        params = init_td3(key, self.obs_dim, self.act_dim, self.cfg.net_arch)
        return params, dict(params), init_opts(params), jnp.asarray(0, jnp.int32)

    def act(self, learner, obs_n, key, eps_held, hp):
        return actor_action(learner[0], obs_n, self.cfg.activation)

    def noise(self, a, key, hp):
        return jnp.clip(a + hp["noise_std"] * jax.random.normal(key, a.shape, jnp.float32), -1.0, 1.0)

    def update(self, learner, batch, key, lr, hp):
        return update_step(learner, batch, key, lr=lr, gamma=hp["gamma"], tau=hp["tau"],
                           noise_std=hp["target_policy_noise"], noise_clip=hp["target_noise_clip"],
                           activation=self.cfg.activation, policy_delay=self.cfg.policy_delay)

    def outputs(self, learner) -> dict:
        return {"params": learner[0], "target": learner[1], "gradient_steps": learner[3]}


def make_train(cfg: TD3Config, env=None, env_params=None, snapshots=None, return_buffer: bool = False):
    """``train(key, hparams) -> dict``: one TD3 run as a pure function (``jax.jit`` / ``jax.vmap`` it); the
    arguments and the result as :func:`agents.training.jax.sac.make_train`'s, with ``params`` the actor and
    critics (:func:`init_td3`), ``target`` the target actor and critics, ``gradient_steps`` the count, and the
    curve's ``critic_loss``, ``actor_loss`` (the last step's; NaN on a step without actor update or before
    learning starts)."""
    return offpolicy_train(cfg, TD3Hooks, env, env_params, snapshots, return_buffer)
