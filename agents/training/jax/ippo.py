"""IPPO with parameter sharing as one compiled function, on the multi-agent JAX view (:func:`dobs_envs.jax.make_marl`).

One actor-critic is shared by every controller node; each node acts on its own observation (the paper's
information pattern: controller ``k`` sees what its node has, nothing of the other nodes'). What it computes is
``dobs-envs train --multi-agent`` (SB3 PPO on :class:`agents.vecenv.batched_core.CoreVecEnv` with ``shared=True``,
under ``VecNormalize``), with the same recipe (:func:`agents.training.recipes.resolve_recipe` with
``multi_agent=True``: the ``default-ma`` and ``<env>-ma`` sections):

- **slots**: the agents are a batch axis. A rollout step of ``n_envs`` copies gives ``n_envs * K`` samples, slot
  ``c * K + k`` being agent ``k`` of copy ``c`` (:class:`agents.vecenv.slots.SlotEncoder`'s slot order); every
  slot's observation is that agent's observation of the env, zero-padded to the widest agent, with the one-hot
  agent id appended when the recipe's ``agent_id`` is set (:func:`slot_observations`: ``SlotEncoder.encode_batch``
  in JAX);
- **actions**: the shared action of slot ``(c, k)`` (in ``[-1, 1]`` with ``normalize_actions``) is clipped to the
  policy's space, mapped onto agent ``k``'s bounds ``lo + (a + 1) (hi - lo) / 2``, clipped to them and truncated
  to the agent's width (:func:`agent_actions`: ``SlotEncoder.decode_batch``); the env runs in its own input units
  (``normalized_actions=False``), as the compiled env the run is evaluated on;
- **rewards**: every agent receives the team reward (the PettingZoo env's, and JaxMARL's, convention: each
  agent's own entry of ``rewards``), so each of a copy's ``K`` slots carries the same reward and ends its
  episode at the same step;
- **normalisation**: one ``VecNormalize`` over the ``n_envs * K`` slots (as SB3's over the shared VecEnv):
  observation statistics over all slots' encoded observations, one running discounted return per slot;
- **budget**: ``timesteps`` counts environment steps (each advances all ``K`` agents of a copy), as
  ``dobs-envs train --multi-agent`` does (SB3 counts ``timesteps * K`` samples there). An update takes
  ``n_envs * n_steps`` env steps (``n_envs * K * n_steps`` samples, ``n_epochs`` passes of minibatches of
  ``batch_size`` samples), so a run takes ``ceil(timesteps / (n_envs n_steps))`` updates and the ``lin_``
  schedules reach 0 at the budget, as SB3's (its progress ``1 - (timesteps done K) / (timesteps K)``);
- **truncation** at the time limit is bootstrapped with each slot's final observation (normalised with the
  current statistics), the episode returns of the training curve are the raw team returns.

Everything else (GAE, loss, Adam, gradient clipping, schedules, the normaliser, the policy, snapshots for the
learning curve) is :func:`agents.training.jax.ppo.make_train`'s, run on :class:`~agents.training.jax.ppo.VecSlots`
whose slots are the (copy, agent) pairs (:func:`marl_slots`).

Not implemented: a centralised critic (MAPPO); the critic sees what the actor sees.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from dobs_envs.envs.step_kernel import REASON_HORIZON

from . import normalize as nz
from . import policy as pol
from .ppo import PPOConfig, VecSlots, ppo_config
from .ppo import make_train as ppo_make_train

__all__ = ["IPPOConfig", "SlotLayout", "ippo_config", "make_marl_env", "slot_layout", "slot_observations",
           "agent_actions", "marl_slots", "make_train", "jax_act_shared"]


@dataclass(frozen=True)
class IPPOConfig:
    """A shared-policy run: the PPO configuration (``ppo.env_id`` the Gymnasium id, ``ppo.n_envs`` copies of the
    multi-agent env, ``ppo.normalize_actions`` the slots' ``[-1, 1]`` actions), the PettingZoo env's name
    (``tracking_v0``) and whether a one-hot agent id is appended to the observations."""
    ppo: PPOConfig
    env_name: str
    agent_id: bool = False


class SlotLayout(NamedTuple):
    """The slots' encoding (static, numpy): the agents in slot order, their observation and action widths, the
    padded widths (``obs_dim``, ``act_dim``), the policy's input width (``width = obs_dim (+ K)``), the policy's
    action bounds ``low``, ``high`` ``(act_dim,)`` and each agent's ``act_lo``, ``act_hi`` ``(K, act_dim)`` (zero
    beyond its width): :class:`agents.vecenv.slots.SlotEncoder`'s."""
    agents: tuple
    obs_widths: tuple
    act_widths: tuple
    obs_dim: int
    act_dim: int
    width: int
    agent_id: bool
    rescale: bool
    low: np.ndarray
    high: np.ndarray
    act_lo: np.ndarray
    act_hi: np.ndarray

    @property
    def n_agents(self) -> int:
        return len(self.agents)


def ippo_config(hyperparams: dict, env_name: str = "tracking", *, total_timesteps: int | None = None,
                dtype: str = "float32") -> tuple[IPPOConfig, dict]:
    """``(config, hparams)`` of a multi-agent recipe (the keys of :func:`agents.training.jax.ppo.ppo_config` plus
    ``agent_id``); ``env_name`` a registered env name (``tracking``) or its PettingZoo module name
    (``tracking_v0``). ``batch_size`` must divide ``n_envs * n_steps`` (then the rollout's ``n_envs * K * n_steps``
    samples too)."""
    from dobs_envs.registry import ENVIRONMENTS

    if not isinstance(hyperparams, dict):
        raise TypeError(f"hyperparams must be a dict of recipe keys, got {type(hyperparams).__name__}")
    by_module = {e.module.rsplit(".", 1)[-1]: e for e in ENVIRONMENTS.values()}
    entry = ENVIRONMENTS.get(env_name) or by_module.get(env_name)
    if entry is None:
        raise ValueError(f"unknown environment {env_name!r}; the JAX environments are {sorted(ENVIRONMENTS)}")
    hp = dict(hyperparams)
    agent_id = hp.pop("agent_id", False)
    if not isinstance(agent_id, bool):
        raise ValueError(f"agent_id must be true or false, got {agent_id!r}")
    cfg, hparams = ppo_config(hp, entry.gym_id, total_timesteps=total_timesteps, dtype=dtype)
    return IPPOConfig(ppo=cfg, env_name=entry.module.rsplit(".", 1)[-1], agent_id=agent_id), hparams


def make_marl_env(cfg: IPPOConfig):
    """:func:`dobs_envs.jax.make_marl` of the run's env with its training options, in the env's own input units."""
    from dobs_envs.jax import make_marl

    return make_marl(cfg.env_name, dtype=cfg.ppo.dtype, **cfg.ppo.env_kwargs)


def slot_layout(env, cfg: IPPOConfig) -> SlotLayout:
    """The :class:`SlotLayout` of ``env`` (a :func:`make_marl` env): :class:`agents.vecenv.slots.SlotEncoder` of the
    PettingZoo env's spaces (:func:`dobs_envs.envs.adapter.agent_spaces`), as the SB3 shared run and its
    evaluation build it."""
    from dobs_envs.envs.adapter import agent_spaces

    from ...vecenv.slots import SlotEncoder

    obs_sp, act_sp = agent_spaces(env.core)
    agents = list(env.agents)
    enc = SlotEncoder(agents, dict(zip(agents, obs_sp)), dict(zip(agents, act_sp)), agent_id=cfg.agent_id,
                      rescale_actions=cfg.ppo.normalize_actions)
    K, m = enc.n_agents, enc.act_dim
    lo, hi = np.zeros((K, m)), np.zeros((K, m))
    for k, (sp, d) in enumerate(zip(act_sp, enc.act_dims)):
        lo[k, :d], hi[k, :d] = np.asarray(sp.low, np.float64).reshape(-1), np.asarray(sp.high, np.float64).reshape(-1)
    return SlotLayout(tuple(agents), tuple(enc.obs_dims), tuple(enc.act_dims), enc.obs_dim, m,
                      int(enc.observation_space.shape[0]), enc.agent_id, enc.rescale_actions,
                      np.asarray(enc.action_space.low, np.float64), np.asarray(enc.action_space.high, np.float64),
                      lo, hi)


def slot_observations(obs: dict, layout: SlotLayout) -> jax.Array:
    """``{agent: (w_k,)}`` of one copy -> ``(K, width)`` float32: row ``k`` is agent ``k``'s observation, zero-padded
    to ``obs_dim``, then its one-hot id (``agent_id``); nothing of another agent enters it."""
    W = layout.obs_dim
    rows = [jnp.pad(jnp.asarray(obs[a], jnp.float32), (0, W - w)) for a, w in zip(layout.agents, layout.obs_widths)]
    o = jnp.stack(rows)
    if layout.agent_id:
        o = jnp.concatenate([o, jnp.eye(layout.n_agents, dtype=jnp.float32)], axis=1)
    return o


def agent_actions(action: jax.Array, layout: SlotLayout) -> dict:
    """``(K, act_dim)`` shared actions of one copy -> ``{agent: (w_k,)}`` in the env's units: mapped from
    ``[-1, 1]`` onto each agent's bounds (``rescale``), clipped to them, truncated to the agent's width."""
    lo, hi = jnp.asarray(layout.act_lo, jnp.float32), jnp.asarray(layout.act_hi, jnp.float32)
    a = action.astype(jnp.float32)
    if layout.rescale:
        a = lo + (jnp.clip(a, -1.0, 1.0) + 1.0) * 0.5 * (hi - lo)
    a = jnp.clip(a, lo, hi)
    return {ag: a[k, :w] for k, (ag, w) in enumerate(zip(layout.agents, layout.act_widths))}


def marl_slots(env, layout: SlotLayout, n_envs: int) -> VecSlots:
    """:class:`~agents.training.jax.ppo.VecSlots` of ``n_envs`` vmapped copies of the multi-agent ``env``, one slot
    per (copy, agent), slot ``c * K + k``. A step is ``env.step`` (the same key split, ``step_env`` then the
    auto-reset) keeping the final observations; ``truncated`` is the reason code ``horizon``."""
    K, width = layout.n_agents, layout.width
    B = int(n_envs)
    encode = jax.vmap(lambda o: slot_observations(o, layout))

    def flat(x):
        return x.reshape((B * K,) + x.shape[2:])

    def reset(key):
        obs, state = jax.vmap(env.reset)(jax.random.split(key, B))
        return flat(encode(obs)), state

    def one(key, state, action):
        key, key_reset = jax.random.split(key)  # env.step's split
        obs_st, state_st, rewards, dones, infos = env.step_env(key, state, agent_actions(action, layout))
        obs_re, state_re = env.reset(key_reset)
        done = dones["__all__"]
        state = jax.tree.map(lambda r, s: jax.lax.select(done, r, s), state_re, state_st)
        final, nxt = slot_observations(obs_st, layout), slot_observations(obs_re, layout)
        trunc = infos["termination_reason"] == REASON_HORIZON  # (K,), agent-major
        reward = jnp.stack([rewards[a] for a in layout.agents])  # each agent's own reward (the team's)
        return jnp.where(done, nxt, final), state, reward, jnp.broadcast_to(done, (K,)) & ~trunc, trunc, final

    def step(key, state, action):
        obs, state, reward, term, trunc, final = jax.vmap(one)(jax.random.split(key, B), state,
                                                               action.reshape(B, K, -1))
        return flat(obs), state, flat(reward), flat(term), flat(trunc), flat(final)

    return VecSlots(B * K, B, width, layout.act_dim, jnp.asarray(layout.low, jnp.float32),
                    jnp.asarray(layout.high, jnp.float32), reset, step)


def make_train(cfg: IPPOConfig, env=None, snapshots=None):
    """``train(key, hparams) -> dict``: one shared-policy run as a pure function (``jax.jit`` / ``jax.vmap`` over
    keys and the float hyperparameters of :data:`agents.training.jax.ppo.HPARAMS`).

    ``env``: the multi-agent env (default :func:`make_marl_env`). The result is
    :func:`agents.training.jax.ppo.make_train`'s over the slots (``obs_mean (width,)``, ...), with the curve's
    ``episodes`` counted per copy (each copy's episode ends ``K`` slot episodes at once) and ``episode_return`` the
    team's return."""
    env = make_marl_env(cfg) if env is None else env
    layout = slot_layout(env, cfg)
    inner = ppo_make_train(cfg.ppo, snapshots=snapshots, slots=marl_slots(env, layout, cfg.ppo.n_envs))
    K = layout.n_agents

    def train(key, hparams: dict):
        out = inner(key, hparams)
        return dict(out, curve=dict(out["curve"], episodes=out["curve"]["episodes"] // K))

    return train


def jax_act_shared(result: dict, cfg: IPPOConfig, hparams: dict, layout: SlotLayout):
    """The deterministic shared policy of one run in JAX, per copy: ``{agent: obs} -> {agent: input}`` (the
    reference of the exported policy acting through :class:`agents.vecenv.slots.SlotEncoder`)."""
    rms = nz.RunningMeanStd(result["obs_mean"], result["obs_var"], result["obs_count"])
    low, high = jnp.asarray(layout.low, jnp.float32), jnp.asarray(layout.high, jnp.float32)
    c = cfg.ppo

    @jax.jit
    def act(obs: dict) -> dict:
        o = slot_observations(obs, layout)
        if c.norm_obs:
            o = nz.normalize_obs(rms, o, hparams["clip_obs"], hparams["norm_epsilon"])
        a = jnp.clip(pol.actor_mean(result["params"], o.astype(jnp.float32), c.activation), low, high)
        return agent_actions(a, layout)

    return act
