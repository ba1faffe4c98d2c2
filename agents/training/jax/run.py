"""``dobs-envs train --trainer jax``: one jitted PPO (:mod:`.ppo`), SAC (:mod:`.sac`) or TD3 (:mod:`.td3`) run.

:func:`train_jax` resolves the same recipe as SB3 PPO / SBX SAC / SBX TD3
(:func:`agents.training.recipes.resolve_recipe`, overrides merged), compiles the whole run as one function (the
algorithm's ``make_train``, ``jax.random.PRNGKey(seed)``), runs it and writes into ``out`` (nothing pickled):

- ``policy.npz`` + ``policy.json``: the exported deterministic policy (:func:`.export.save_policy`; acted by
  :class:`.numpy_policy.NumpyPolicy`, numpy only);
- ``curve.json``: the learning curve in the format of :mod:`agents.training.curves` (what the benchmark reads for
  SB3 runs): ``{"seeds", "paper_cost", "points": [{"env_steps", "cost_ratio"}]}``, the cost ratio ``J_policy /
  J_paper`` per learning-curve episode (seeds from :data:`CURVE_SEED`, the tuning range) on the task's own compiled
  environment, of the policy kept after evenly spaced updates (the run's snapshots, ``make_train``'s ``snapshots``;
  the first point is the initial policy), evaluated after the run; an update is PPO's rollout of ``n_envs n_steps``
  steps, SAC's (TD3's) collect of ``n_envs train_freq`` steps and its gradient steps;
- ``train_curve.json``: the trainer's own per-update figures (env steps, mean raw return and length of the training
  episodes that ended in the rollout, their count; PPO: approximate KL, value loss; SAC: critic and actor losses,
  entropy coefficient; TD3: critic and actor losses; ``null`` where no episode ended or nothing was learnt yet);
- ``config.json``: ``trainer: "jax"``, ``library`` (:data:`agents.training.jax.LIBRARY`) and ``library_version``
  (dobs-envs'), ``jax_version``, ``jaxlib_version``, ``optax_version``, the env and its JAX id, the recipe
  (``hyperparams``), the seed, the budget (``timesteps``; ``timesteps_done``: whole rollouts, at least the budget),
  ``n_updates``, ``rollout`` (env steps per update), the times (``setup_seconds``, ``compile_seconds`` /
  ``compile_cpu_seconds``, ``train_seconds`` / ``train_cpu_seconds``: the compiled run alone, ``curve_seconds``),
  ``status`` and ``provenance`` (the source revision and the machine: :mod:`agents.training.provenance`).

CPU times are this process's (``time.process_time``), wall times ``time.perf_counter``.
"""
from __future__ import annotations

import importlib
import math
import os
import sys
import time
from importlib import metadata
from typing import Any, Callable, NamedTuple

import numpy as np

from ..curves import CURVE_EPISODES, CURVE_POINTS, CURVE_SEED
from ..provenance import run_provenance
from ..runs import COMPLETE, RUNNING, clear_run, write_json_atomic
from ..seeds import TUNING
from ..train import TrainResult
from ..xla import xla_threads
from . import ALGOS, LIBRARY, TRAINER

__all__ = ["train_jax", "JaxRunError", "jax_env", "curve_updates", "run_config", "finish_config", "build_run",
           "enable_x64_for", "RunSetup", "curve_episodes", "TIME_FIELDS", "CURVE_SEED", "CURVE_POINTS", "CURVE_EPISODES"]



class JaxRunError(ValueError):
    """What :func:`train_jax` refuses before touching the run directory: an algorithm, env or hyperparameter the
    jitted trainer does not implement (one line naming it)."""


def _version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def jax_env(env: str) -> tuple[str, str]:
    """``(name, Gymnasium id)`` of ``env`` (a name of :data:`agents.config.envs.ENVS` or a Gymnasium id) if the JAX
    environments have it (:func:`dobs_envs.jax.registered_envs`), else :class:`JaxRunError` listing their names."""
    from dobs_envs.registry import ENVIRONMENTS  # registered_envs() are their ids; read here without importing JAX

    from ...config.envs import env_key, gym_id

    gid = gym_id(env_key(env))
    names = [e.name for e in ENVIRONMENTS.values() if e.gym_id == gid]
    if not names:
        raise JaxRunError(f"--env {env!r}: the jitted trainer runs the JAX environments "
                          f"({', '.join(ENVIRONMENTS)})")
    return names[0], gid


def curve_updates(n_updates: int, points: int = CURVE_POINTS) -> list[int]:
    """Update counts of the learning-curve points: 0 (the initial policy) and ``min(points, n_updates)``
    evenly spaced counts ending at ``n_updates``."""
    k = min(int(points), int(n_updates))
    return sorted({0, *(int(round(n_updates * (i + 1) / k)) for i in range(k))})


def curve_episodes(curve_points, curve_seeds) -> list[int]:
    """The learning curve's episodes (``curve_seeds``; default ``CURVE_SEED .. CURVE_SEED + CURVE_EPISODES - 1``),
    checked to lie in the tuning range, and ``curve_points`` checked to be a positive integer (:class:`JaxRunError`
    naming the argument)."""
    seeds = [int(s) for s in (range(CURVE_SEED, CURVE_SEED + CURVE_EPISODES) if curve_seeds is None else curve_seeds)]
    if not seeds or not all(s in TUNING for s in seeds):
        raise JaxRunError(f"curve_seeds must be seeds of the {TUNING}, got {seeds}")
    if isinstance(curve_points, bool) or not isinstance(curve_points, int) or curve_points < 1:
        raise JaxRunError(f"curve_points must be a positive integer, got {curve_points!r}")
    return seeds


def _plain(x):
    """JSON-able lists of an array (NaN -> None)."""
    return [None if isinstance(v, float) and math.isnan(v) else v for v in np.asarray(x).tolist()]


#: per algorithm: (module, its recipe reader)
_ALGO_MODULES = {"ppo": ("ppo", "ppo_config"), "sac": ("sac", "sac_config"), "td3": ("td3", "td3_config")}

#: the times a finished run's config.json records (:func:`finish_config`)
TIME_FIELDS = ("setup_seconds", "compile_seconds", "compile_cpu_seconds", "train_seconds", "train_cpu_seconds",
               "curve_seconds", "total_seconds", "total_cpu_seconds")


def _rollout(cfg) -> int:
    """Env steps per update: SAC's ``rollout`` (``n_envs train_freq``), PPO's ``n_envs n_steps``."""
    return int(getattr(cfg, "rollout", None) or cfg.n_envs * cfg.n_steps)


def run_config(env: str, algo: str, fields: dict, *, seed: int, curve_seeds: list) -> dict:
    """``config.json`` of a jitted run as it starts (``status`` running): the trainer and its versions, the run's
    ``fields`` (its builder's: :func:`build_run`, :func:`.run_marl.build_marl_run`), the seed and its key, the
    exported policy's file, the learning curve's episodes, what trained it (``provenance``:
    :func:`agents.training.provenance.run_provenance`). The one place these fields are assembled (:func:`train_jax`,
    :func:`.run_marl.train_jax_marl`, :func:`.vmap_seeds.train_jax_seeds`); :func:`finish_config` completes it."""
    import jax

    return {"env": env, "algo": algo, "trainer": TRAINER, "library": LIBRARY, "library_version": _version("dobs-envs"),
            "jax_version": jax.__version__, "jaxlib_version": _version("jaxlib"), "optax_version": _version("optax"),
            **fields, "seed": int(seed), "key": f"jax.random.PRNGKey({int(seed)})", "timesteps_done": 0,
            "policy": "policy.npz", "curve_seeds": [int(s) for s in curve_seeds], "status": RUNNING,
            "provenance": run_provenance()}


def finish_config(config: dict, steps_done: int, times: dict) -> dict:
    """``config`` (:func:`run_config`'s) of the finished run: ``status`` complete, the env steps taken and every
    time of :data:`TIME_FIELDS` (``times`` must hold exactly those)."""
    if set(times) != set(TIME_FIELDS):
        raise ValueError(f"times must be {list(TIME_FIELDS)}, got {sorted(times)}")
    config.update(status=COMPLETE, timesteps_done=int(steps_done), **{k: times[k] for k in TIME_FIELDS})
    return config


class RunSetup(NamedTuple):
    """A centralised run built from its recipe, before compiling (:func:`build_run`): the algorithm's static config
    and float hyperparameters, the JAX env and its params, the algorithm's ``make_train``, ``config.json``'s fields
    of the run (:func:`run_config`'s ``fields``)."""
    cfg: Any
    hp: dict
    env: Any
    env_params: Any
    make_train: Callable
    fields: dict


def enable_x64_for(env: str) -> None:
    """Switch ``jax_enable_x64`` on for the process if ``env`` has communication faults on by default
    (tracking_lossy): the JAX envs draw them with 64-bit integers (docs/jax.md); a run still simulates and trains
    in float32 (its config's dtype)."""
    import jax

    from dobs_envs.registry import ENVIRONMENTS

    if ENVIRONMENTS[env].fault_free is not None and not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)


def build_run(algo: str, env: str, gid: str, hyperparams: dict | None, timesteps: int | None) -> RunSetup:
    """The centralised ``algo`` run of ``env`` (Gymnasium id ``gid``) from its recipe
    (:func:`agents.training.recipes.resolve_recipe` with the overrides ``hyperparams``; ``timesteps`` default the
    recipe's ``n_timesteps``): what :func:`train_jax` and :mod:`.vmap_seeds`' builder compile. A recipe the trainer
    cannot run: :class:`JaxRunError` naming it."""
    from ..recipes import resolve_recipe

    module_name, config_name = _ALGO_MODULES[algo]
    module = importlib.import_module(f"{__package__}.{module_name}")
    recipe = resolve_recipe(algo, env, overrides=hyperparams, trainer=TRAINER)
    timesteps = int(recipe.n_timesteps if timesteps is None else timesteps)
    try:
        cfg, hp = getattr(module, config_name)(recipe.hyperparams, gid, total_timesteps=timesteps)
        env_jax, env_params = module.make_env(cfg)
    except ValueError as exc:
        raise JaxRunError(f"the {algo} recipe of {env} (with its overrides) for the jitted trainer: {exc}") from None
    fields = {"env_id": gid, "dtype": cfg.dtype, "multi_agent": False, "hybrid": None, "timesteps": timesteps,
              "n_updates": cfg.n_updates, "rollout": _rollout(cfg), "n_agents": 1,
              "normalize_actions": cfg.normalize_actions, "env_kwargs": {}, "train_env_kwargs": dict(cfg.env_kwargs),
              "normalize": cfg.norm_obs or cfg.norm_reward, "hyperparams": dict(recipe.hyperparams)}
    return RunSetup(cfg, hp, env_jax, env_params, module.make_train, fields)


def _curve(snapshots: dict, updates: list, rollout: int, cfg, hp, env, env_params, env_name: str,
           seeds: list) -> dict:
    """``curve.json``'s document: every snapshot's policy on the task's own compiled env (the harness of
    :func:`agents.training.curves.make_curve_callback`: :func:`agents.evaluate.run_episode`)."""
    from ...config.envs import gym_factory
    from ...evaluate import run_episode
    from ..curves import paper_costs
    from .export import policy_arrays
    from .numpy_policy import NumpyPolicy

    ref = paper_costs(env_name, {}, seeds)
    env_np = gym_factory(env_name, {})()
    points = []
    for k, u in enumerate(updates):
        snap = {key: np.asarray(v[k]) for key, v in snapshots.items()}
        result = {"params": {key: v for key, v in snap.items() if key.startswith("pi_")},
                  "obs_mean": snap["obs_mean"], "obs_var": snap["obs_var"]}
        pol = NumpyPolicy.from_arrays(*policy_arrays(result, cfg, hp, env, env_params))
        costs = np.array([run_episode(env_np, pol, s, parallel=False).cost for s in seeds])
        points.append({"env_steps": int(u) * rollout, "cost_ratio": (costs / ref).tolist()})
    env_np.close()
    return {"seeds": list(seeds), "paper_cost": ref.tolist(), "points": points}


def train_jax(env: str, algo: str = "ppo", *, timesteps: int | None = None, seed: int = 0, out: str,
              hyperparams: dict | None = None, threads: int | None = 1, progress: bool = True,
              curve_points: int = CURVE_POINTS, curve_seeds=None) -> TrainResult:
    """Train ``algo`` with the jitted trainer on the JAX form of ``env`` and write the run directory ``out``
    (see the module doc; files of a previous run in ``out`` are replaced, other files kept: the caller decides
    whether ``out`` may be written).

    Parameters
    ----------
    env : a name of the JAX environments or its Gymnasium id (:func:`jax_env`; the run records the name).
    timesteps : env steps (default: the recipe's ``n_timesteps``); the run takes whole updates (PPO: rollouts of
        ``n_envs * n_steps`` steps; SAC, TD3: collects of ``n_envs * train_freq``; ``timesteps_done >= timesteps``,
        as SB3).
    algo : ``"ppo"``, ``"sac"`` or ``"td3"`` (:data:`agents.training.jax.ALGOS`).
    hyperparams : overrides merged over the recipe (``agents/config/hyperparams/<algo>.yaml``).
    threads : 1 (default): XLA on one thread (:func:`agents.training.xla.xla_threads`).
    progress : one line on stderr per phase (compile, run, curve).
    curve_points, curve_seeds : the learning curve's points after the initial one (:func:`curve_updates`) and its
        episodes (default ``CURVE_SEED .. CURVE_SEED + CURVE_EPISODES - 1``; checked to lie in the tuning range).

    Errors (before ``out`` is touched): :class:`JaxRunError` for an algorithm, env or hyperparameter the
    trainer does not implement (:func:`.ppo.ppo_config`, :func:`.sac.sac_config`, :func:`.td3.td3_config` name the key);
    :class:`agents.config.hyperparam_files.HyperparamsError` from the recipe files.

    An env with communication faults on by default (tracking_lossy) needs 64-bit JAX for its fault
    generator: ``jax_enable_x64`` is switched on for the process (the run stays float32).
    """
    if algo not in ALGOS:
        raise JaxRunError(f"--algo {algo}: the jitted trainer implements {', '.join(ALGOS)}")
    seeds = curve_episodes(curve_points, curve_seeds)
    env, gid = jax_env(env)
    xla_threads(threads)
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    import jax

    from .export import save_policy

    def say(msg: str) -> None:
        if progress:
            print(f"[jax {algo} {env}] {msg}", file=sys.stderr, flush=True)

    enable_x64_for(env)
    run = build_run(algo, env, gid, hyperparams, timesteps)
    cfg, hp, env_jax, env_params = run.cfg, run.hp, run.env, run.env_params
    updates = curve_updates(cfg.n_updates, curve_points)
    train = jax.jit(run.make_train(cfg, env_jax, env_params, snapshots=updates))
    key = jax.random.PRNGKey(seed)
    setup = time.perf_counter() - t_wall
    config = run_config(env, algo, run.fields, seed=seed, curve_seeds=seeds)
    os.makedirs(out, exist_ok=True)
    clear_run(out)
    write_json_atomic(os.path.join(out, "config.json"), config)

    say(f"compiling {cfg.n_updates} updates of {_rollout(cfg)} env steps ...")
    w0, c0 = time.perf_counter(), time.process_time()
    compiled = train.lower(key, hp).compile()
    compile_s, compile_cpu = time.perf_counter() - w0, time.process_time() - c0
    say(f"compiled in {compile_s:.1f} s; training {cfg.steps_done} env steps ...")
    w0, c0 = time.perf_counter(), time.process_time()
    result = jax.device_get(jax.block_until_ready(compiled(key, hp)))
    train_s, train_cpu = time.perf_counter() - w0, time.process_time() - c0
    say(f"trained in {train_s:.1f} s; learning curve: {len(updates)} points x {len(seeds)} episodes ...")

    save_policy(out, result, cfg, hp, env_jax, env_params, overwrite=True,
                extra={"seed": int(seed), "timesteps": run.fields["timesteps"], "timesteps_done": cfg.steps_done})
    w0 = time.perf_counter()
    curve = _curve(result["snapshots"], updates, _rollout(cfg), cfg, hp, env_jax, env_params, env, seeds)
    write_json_atomic(os.path.join(out, "curve.json"), curve)
    c = result["curve"]
    write_json_atomic(os.path.join(out, "train_curve.json"), {k: _plain(v) for k, v in c.items()})
    curve_s = time.perf_counter() - w0
    finish_config(config, cfg.steps_done, {
        "setup_seconds": setup, "compile_seconds": compile_s, "compile_cpu_seconds": compile_cpu,
        "train_seconds": train_s, "train_cpu_seconds": train_cpu, "curve_seconds": curve_s,
        "total_seconds": time.perf_counter() - t_wall, "total_cpu_seconds": time.process_time() - t_cpu})
    write_json_atomic(os.path.join(out, "config.json"), config)
    return TrainResult(path=out, model=None, seconds=train_s, config=config)
