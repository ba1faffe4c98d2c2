"""``dobs-envs train --trainer jax --multi-agent``: one jitted shared-policy PPO run (:mod:`.ippo`) as a run directory.

:func:`train_jax_marl` resolves the recipe of ``dobs-envs train --multi-agent`` (SB3's shared PPO:
:func:`agents.training.recipes.resolve_recipe` with ``multi_agent=True``, overrides merged), compiles the whole run
as one function (:func:`.ippo.make_train`, ``jax.random.PRNGKey(seed)``) and writes what :func:`.run.train_jax`
writes, with the multi-agent fields of an SB3 shared run:

- ``policy.npz`` + ``policy.json``: the one shared actor (:func:`.export.save_policy`'s format, acted by
  :class:`.numpy_policy.NumpyPolicy` on the slot observations, its output the slot's action in the policy's space,
  ``[-1, 1]`` with ``normalize_actions``); ``policy.json``'s ``extra.multi_agent`` records the agents, ``agent_id``
  and ``rescale_actions``. On the PettingZoo env the policy acts through :class:`agents.vecenv.slots.SlotEncoder`
  (padding, one-hot id, each agent's bounds) as an SB3 shared run does
  (:class:`agents.training.loading.JaxTrainedAgent`);
- ``curve.json`` (J / J_paper of the snapshots on the curve episodes of the tuning range, on the compiled PettingZoo
  env), ``train_curve.json`` (per update; ``episodes``: copies' episodes), ``config.json`` (``multi_agent: true``,
  ``n_agents``, ``agent_id``, ``normalize_actions``, ``rollout`` in env steps, ``samples_per_update``; the rest as
  :func:`.run.train_jax`'s).
"""
from __future__ import annotations

import os
import sys
import time
from typing import Any, NamedTuple

import numpy as np

from ..runs import clear_run, write_json_atomic
from ..train import TrainResult
from ..xla import xla_threads
from . import TRAINER
from .run import (CURVE_POINTS, JaxRunError, _plain, curve_episodes, curve_updates, enable_x64_for, finish_config,
                  jax_env, run_config)

__all__ = ["train_jax_marl", "shared_export", "build_marl_run", "MarlSetup", "MARL_ALGOS"]

#: the algorithms the jitted shared-policy trainer implements
MARL_ALGOS = ("ppo",)


class _Bounds(NamedTuple):
    low: np.ndarray
    high: np.ndarray


class _PolicySpace:
    """The slots' action space as :func:`.export.save_policy` reads an env's (``num_actions``, ``action_space``)."""

    def __init__(self, low, high):
        self.num_actions = int(np.asarray(low).shape[0])
        self._space = _Bounds(np.asarray(low, np.float32), np.asarray(high, np.float32))

    def action_space(self, params=None) -> _Bounds:
        return self._space


def shared_export(cfg, layout) -> tuple:
    """``(cfg', env', extra)`` with which :func:`.export.policy_arrays` / :func:`.export.save_policy` write the shared
    actor: the policy maps a slot observation to the slot's action in the policy's space (action scale 1; the
    agents' bounds are :class:`agents.vecenv.slots.SlotEncoder`'s at acting time)."""
    from dataclasses import replace

    extra = {"multi_agent": {"agents": list(layout.agents), "agent_id": bool(layout.agent_id),
                             "rescale_actions": bool(layout.rescale)}}
    return replace(cfg.ppo, normalize_actions=False), _PolicySpace(layout.low, layout.high), extra


class MarlSetup(NamedTuple):
    """A shared-policy run built from its recipe, before compiling (:func:`build_marl_run`): the
    :class:`.ippo.IPPOConfig` and float hyperparameters, the multi-agent JAX env, its slot layout, ``config.json``'s
    fields of the run (:func:`.run.run_config`'s ``fields``)."""
    cfg: Any
    hp: dict
    env: Any
    layout: Any
    fields: dict


def build_marl_run(algo: str, env: str, gid: str, hyperparams: dict | None, timesteps: int | None) -> MarlSetup:
    """The shared-policy ``algo`` run of ``env`` from the recipe of ``train --multi-agent`` (overrides
    ``hyperparams``; ``timesteps`` default the recipe's ``n_timesteps``): what :func:`train_jax_marl` and
    :mod:`.vmap_seeds`' builder compile. A recipe the trainer cannot run: :class:`.run.JaxRunError` naming it."""
    from ..recipes import resolve_recipe
    from .ippo import ippo_config, make_marl_env, slot_layout

    recipe = resolve_recipe(algo, env, multi_agent=True, overrides=hyperparams, trainer=TRAINER)
    timesteps = int(recipe.n_timesteps if timesteps is None else timesteps)
    try:
        cfg, hp = ippo_config(recipe.hyperparams, env, total_timesteps=timesteps)
        env_jax = make_marl_env(cfg)
        layout = slot_layout(env_jax, cfg)
    except ValueError as exc:
        raise JaxRunError(f"the multi-agent {algo} recipe of {env} (with its overrides) for the jitted trainer: "
                          f"{exc}") from None
    p = cfg.ppo
    K, rollout = layout.n_agents, p.n_envs * p.n_steps
    fields = {"env_id": gid, "marl_env": cfg.env_name, "dtype": p.dtype, "multi_agent": True, "hybrid": None,
              "timesteps": timesteps, "n_updates": p.n_updates, "rollout": rollout, "samples_per_update": rollout * K,
              "n_agents": K, "agent_id": layout.agent_id, "normalize_actions": p.normalize_actions, "env_kwargs": {},
              "train_env_kwargs": dict(p.env_kwargs), "normalize": p.norm_obs or p.norm_reward,
              "hyperparams": dict(recipe.hyperparams)}
    return MarlSetup(cfg, hp, env_jax, layout, fields)


def _marl_curve(snapshots: dict, updates: list, rollout: int, cfg, hp, layout, env_name: str, seeds: list) -> dict:
    """``curve.json``'s document: every snapshot's shared policy on the task's own compiled PettingZoo env."""
    from ...config.envs import parallel_factory
    from ...evaluate import run_episode
    from ...vecenv.slots import SlotEncoder
    from ..curves import paper_costs
    from ..loading import slot_policy
    from .export import policy_arrays
    from .numpy_policy import NumpyPolicy

    ref = paper_costs(env_name, {}, seeds)
    env = parallel_factory(env_name, {})()
    agents = list(env.possible_agents)
    enc = SlotEncoder(agents, {a: env.observation_space(a) for a in agents},
                      {a: env.action_space(a) for a in agents}, agent_id=layout.agent_id,
                      rescale_actions=layout.rescale)
    cfg_p, space, _ = shared_export(cfg, layout)
    points = []
    for k, u in enumerate(updates):
        snap = {key: np.asarray(v[k]) for key, v in snapshots.items()}
        result = {"params": {key: v for key, v in snap.items() if key.startswith("pi_")},
                  "obs_mean": snap["obs_mean"], "obs_var": snap["obs_var"]}
        act = NumpyPolicy.from_arrays(*policy_arrays(result, cfg_p, hp, space, None))
        costs = np.array([run_episode(env, slot_policy(enc, act), s, parallel=True).cost for s in seeds])
        points.append({"env_steps": int(u) * rollout, "cost_ratio": (costs / ref).tolist()})
    env.close()
    return {"seeds": list(seeds), "paper_cost": ref.tolist(), "points": points}


def train_jax_marl(env: str, algo: str = "ppo", *, timesteps: int | None = None, seed: int = 0, out: str,
                   hyperparams: dict | None = None, threads: int | None = 1, progress: bool = True,
                   curve_points: int = CURVE_POINTS, curve_seeds=None) -> TrainResult:
    """Train ``algo`` with one policy shared by every controller node (:mod:`.ippo`) on the multi-agent JAX form of
    ``env`` and write the run directory ``out`` (module doc; arguments and errors as :func:`.run.train_jax`'s).

    ``timesteps``: environment steps (each advances every agent of a copy; default the recipe's ``n_timesteps``),
    rounded up to whole rollouts of ``n_envs * n_steps`` env steps (``n_envs * K * n_steps`` samples)."""
    if algo not in MARL_ALGOS:
        raise JaxRunError(f"--algo {algo}: the jitted shared-policy trainer implements {', '.join(MARL_ALGOS)}")
    seeds = curve_episodes(curve_points, curve_seeds)
    env, gid = jax_env(env)
    xla_threads(threads)
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    import jax

    from .export import save_policy
    from .ippo import make_train

    def say(msg: str) -> None:
        if progress:
            print(f"[jax ppo shared {env}] {msg}", file=sys.stderr, flush=True)

    enable_x64_for(env)
    run = build_marl_run(algo, env, gid, hyperparams, timesteps)
    cfg, hp, layout = run.cfg, run.hp, run.layout
    p = cfg.ppo
    K, rollout = layout.n_agents, run.fields["rollout"]
    updates = curve_updates(p.n_updates, curve_points)
    train = jax.jit(make_train(cfg, run.env, snapshots=updates))
    key = jax.random.PRNGKey(seed)
    setup = time.perf_counter() - t_wall
    config = run_config(env, algo, run.fields, seed=seed, curve_seeds=seeds)
    os.makedirs(out, exist_ok=True)
    clear_run(out)
    write_json_atomic(os.path.join(out, "config.json"), config)

    say(f"compiling {p.n_updates} updates of {p.n_envs} copies x {K} agents x {p.n_steps} steps ...")
    w0, c0 = time.perf_counter(), time.process_time()
    compiled = train.lower(key, hp).compile()
    compile_s, compile_cpu = time.perf_counter() - w0, time.process_time() - c0
    say(f"compiled in {compile_s:.1f} s; training {p.steps_done} env steps ({p.steps_done * K} samples) ...")
    w0, c0 = time.perf_counter(), time.process_time()
    result = jax.device_get(jax.block_until_ready(compiled(key, hp)))
    train_s, train_cpu = time.perf_counter() - w0, time.process_time() - c0
    say(f"trained in {train_s:.1f} s; learning curve: {len(updates)} points x {len(seeds)} episodes ...")

    cfg_p, space, extra = shared_export(cfg, layout)
    save_policy(out, result, cfg_p, hp, space, None, overwrite=True,
                extra={**extra, "seed": int(seed), "timesteps": run.fields["timesteps"],
                       "timesteps_done": p.steps_done})
    w0 = time.perf_counter()
    curve = _marl_curve(result["snapshots"], updates, rollout, cfg, hp, layout, env, seeds)
    write_json_atomic(os.path.join(out, "curve.json"), curve)
    write_json_atomic(os.path.join(out, "train_curve.json"), {k: _plain(v) for k, v in result["curve"].items()})
    curve_s = time.perf_counter() - w0
    finish_config(config, p.steps_done, {
        "setup_seconds": setup, "compile_seconds": compile_s, "compile_cpu_seconds": compile_cpu,
        "train_seconds": train_s, "train_cpu_seconds": train_cpu, "curve_seconds": curve_s,
        "total_seconds": time.perf_counter() - t_wall, "total_cpu_seconds": time.process_time() - t_cpu})
    write_json_atomic(os.path.join(out, "config.json"), config)
    return TrainResult(path=out, model=None, seconds=train_s, config=config)
