"""Several training seeds of one jitted agent as ONE compiled function vmapped over the seeds.

:func:`train_jax_seeds` builds the run as :func:`.run.train_jax` (centralised PPO, SAC, TD3) or
:func:`.run_marl.train_jax_marl` (shared PPO) do, from the same recipe, compiles ``jax.vmap(train)`` over the seeds'
keys ``jax.random.PRNGKey(seed)`` once, runs it, and writes one ordinary run directory per seed: the files those
functions write (``config.json``, ``policy.npz`` + ``policy.json``, ``curve.json``, ``train_curve.json``), each with
its own seed, so that every directory is one run for ``evaluate --model`` and the benchmark (the run is the
statistical unit).

Times: the vmapped phases serve every seed at once, so a run's ``setup_seconds``, ``compile_seconds`` /
``compile_cpu_seconds`` and ``train_seconds`` / ``train_cpu_seconds`` are its share, the vmapped run's figure divided
by the number of seeds; ``curve_seconds`` is the run's own learning curve; ``total_seconds`` the sum of the run's
shares and its own curve and export. ``config.json`` ``vmapped`` records the seeds sharing the run (``seeds``,
``runs``) and the whole figures (``setup_seconds``, ``compile_seconds``, ``compile_cpu_seconds``, ``train_seconds``,
``train_cpu_seconds``).

One seed, or an algorithm of :data:`agents.training.jax.ALGOS` without a builder here (:data:`BUILDERS`): the seeds
are trained one after another by :func:`.run.train_jax` / :func:`.run_marl.train_jax_marl` themselves (no vmap, no
shared times), so every jitted algorithm has multi-seed runs and a vmapped builder is an optimisation.

A vmapped seed's run equals its single run up to float32 round-off (the batched and the single program are compiled
separately; tests/test_agents_benchmark_jax.py, tests/test_jax_vmap_offpolicy.py); a run is reproduced exactly by the
same group of seeds.

The vmapped algorithms: :data:`BUILDERS`, ``(algo, multi_agent) -> builder`` (a builder returns the
:class:`VmapRun` of a recipe).

Cost: on one XLA thread a vmapped run's compiled part takes about the CPU time of its seeds run one after another
(SAC's shipped tracking recipe, 10 seeds x 20k env steps, benchmarks/bench_vmap_seeds.py: 0.99x per run, measured
on a shared 2-core machine); what the seeds share is the compilation (28 s CPU for the 10 seeds against 19 s for
each single run there). Memory: the seeds' states are held at once, an off-policy run's replay buffer included (SAC's
tracking recipe: 100k transitions, ~127 MB per seed; peak resident memory 2.9 GB for 10 seeds vmapped against 1.4 GB
for one, same script).
"""
from __future__ import annotations

import functools
import os
import sys
import time
from typing import Callable, NamedTuple

import numpy as np

from ..runs import clear_run, write_json_atomic
from ..train import TrainResult
from ..xla import xla_threads
from . import ALGOS
from .run import (CURVE_POINTS, JaxRunError, _plain, curve_episodes, curve_updates, enable_x64_for, finish_config,
                  jax_env, run_config)

__all__ = ["train_jax_seeds", "VmapRun", "BUILDERS", "SHARED_TIMES"]

#: the time fields of config.json shared by the vmapped seeds (each run records its share: figure / seeds)
SHARED_TIMES = ("setup_seconds", "compile_seconds", "compile_cpu_seconds", "train_seconds", "train_cpu_seconds")


class VmapRun(NamedTuple):
    """One algorithm's run built from its recipe, before compiling: ``train(key, hparams)`` (snapshots after the
    ``updates`` of the learning curve), its float hyperparameters ``hp``, the run's ``config.json`` fields
    (``timesteps``, ``n_updates``, ``hyperparams``, ...: :func:`.run.run_config`'s ``fields``), ``steps_done`` (env
    steps a run takes), ``export(out, result, extra)`` (the run's ``policy.npz`` + ``policy.json``), ``curve(result)
    -> curve.json's document``, ``describe`` (a progress line)."""
    train: Callable
    hp: dict
    updates: list
    config: dict
    steps_done: int
    export: Callable
    curve: Callable
    describe: str


def _centralised(algo: str, env: str, gid: str, hyperparams: dict | None, timesteps: int | None, curve_points: int,
                 seeds: list) -> VmapRun:
    """Centralised PPO, SAC or TD3: :func:`.run.train_jax`'s run (:func:`.run.build_run`; its export and learning
    curve)."""
    from .export import save_policy
    from .run import _curve, _rollout, build_run

    run = build_run(algo, env, gid, hyperparams, timesteps)
    cfg, hp, env_jax, env_params = run.cfg, run.hp, run.env, run.env_params
    updates = curve_updates(cfg.n_updates, curve_points)
    rollout = _rollout(cfg)

    def export(out, result, extra):
        save_policy(out, result, cfg, hp, env_jax, env_params, overwrite=True, extra=extra)

    def curve(result):
        return _curve(result["snapshots"], updates, rollout, cfg, hp, env_jax, env_params, env, seeds)

    return VmapRun(run.make_train(cfg, env_jax, env_params, snapshots=updates), hp, updates, run.fields,
                   cfg.steps_done, export, curve, f"{cfg.n_updates} updates of {rollout} env steps")


def _ppo_shared(env: str, gid: str, hyperparams: dict | None, timesteps: int | None, curve_points: int,
                seeds: list) -> VmapRun:
    """PPO with one policy shared by the controller nodes: :func:`.run_marl.train_jax_marl`'s run
    (:func:`.run_marl.build_marl_run`; its export and learning curve)."""
    from .export import save_policy
    from .ippo import make_train
    from .run_marl import _marl_curve, build_marl_run, shared_export

    run = build_marl_run("ppo", env, gid, hyperparams, timesteps)
    cfg, hp, layout = run.cfg, run.hp, run.layout
    p = cfg.ppo
    K, rollout = layout.n_agents, run.fields["rollout"]
    updates = curve_updates(p.n_updates, curve_points)
    cfg_p, space, shared = shared_export(cfg, layout)

    def export(out, result, extra):
        save_policy(out, result, cfg_p, hp, space, None, overwrite=True, extra={**shared, **extra})

    def curve(result):
        return _marl_curve(result["snapshots"], updates, rollout, cfg, hp, layout, env, seeds)

    return VmapRun(make_train(cfg, run.env, snapshots=updates), hp, updates, run.fields, p.steps_done, export, curve,
                   f"{p.n_updates} updates of {p.n_envs} copies x {K} agents x {p.n_steps} steps")


#: ``(algo, multi_agent) -> builder(env, gym id, hyperparams, timesteps, curve_points, curve seeds) -> VmapRun``
BUILDERS = {**{(a, False): functools.partial(_centralised, a) for a in ("ppo", "sac", "td3")},
            ("ppo", True): _ppo_shared}


def _check_seeds(seeds, outs) -> list[int]:
    seeds = list(seeds)
    if not seeds or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
        raise JaxRunError(f"seeds must be a non-empty list of integers >= 0, got {seeds!r}")
    seeds = [int(s) for s in seeds]
    if len(set(seeds)) != len(seeds):
        raise JaxRunError(f"seeds must be distinct, got {seeds}")
    outs = list(outs)
    if len(outs) != len(seeds) or len({os.path.abspath(o) for o in outs}) != len(outs):
        raise JaxRunError(f"outs must be one distinct run directory per seed ({len(seeds)}), got {outs!r}")
    return seeds


def train_jax_seeds(env: str, algo: str = "ppo", *, multi_agent: bool = False, seeds, outs, timesteps: int | None = None,
                    hyperparams: dict | None = None, threads: int | None = 1, progress: bool = True,
                    curve_points: int = CURVE_POINTS, curve_seeds=None) -> list[TrainResult]:
    """Train ``algo`` (shared by the controller nodes with ``multi_agent``) with the jitted trainer for every seed of
    ``seeds`` in one compiled function vmapped over them, and write the run directory ``outs[i]`` of ``seeds[i]``
    (module doc). Arguments and errors as :func:`.run.train_jax`'s (``JaxRunError`` before any directory is touched;
    files of a previous run in an ``out`` are replaced, other files kept: the caller decides whether it may be
    written). Returns one :class:`agents.training.train.TrainResult` per seed (``seconds``: the compiled run's time,
    vmapped: its share; ``config["vmapped"]`` says whether the seeds shared one run)."""
    seeds = _check_seeds(seeds, outs)
    if algo not in ALGOS:
        raise JaxRunError(f"--algo {algo}: the jitted trainer implements {', '.join(ALGOS)}")
    builder = BUILDERS.get((algo, bool(multi_agent)))
    if builder is None or len(seeds) == 1:
        from .run import train_jax
        from .run_marl import train_jax_marl

        one = train_jax_marl if multi_agent else train_jax
        return [one(env, algo, timesteps=timesteps, seed=s, out=out, hyperparams=hyperparams, threads=threads,
                    progress=progress, curve_points=curve_points, curve_seeds=curve_seeds)
                for s, out in zip(seeds, outs)]
    curve_seeds = curve_episodes(curve_points, curve_seeds)
    env, gid = jax_env(env)
    xla_threads(threads)
    t_wall = time.perf_counter()
    import jax
    import jax.numpy as jnp

    n = len(seeds)
    tag = f"[jax {algo}{' shared' if multi_agent else ''} {env}, {n} seeds vmapped]"

    def say(msg: str) -> None:
        if progress:
            print(f"{tag} {msg}", file=sys.stderr, flush=True)

    enable_x64_for(env)
    run = builder(env, gid, hyperparams, timesteps, curve_points, curve_seeds)
    train = jax.jit(jax.vmap(run.train, in_axes=(0, None)))
    keys = jnp.stack([jax.random.PRNGKey(s) for s in seeds])
    setup = time.perf_counter() - t_wall
    configs = []
    for s, out in zip(seeds, outs):
        c = {**run_config(env, algo, run.config, seed=s, curve_seeds=curve_seeds),
             "vmapped": {"seeds": seeds, "runs": n}}
        os.makedirs(out, exist_ok=True)
        clear_run(out)
        write_json_atomic(os.path.join(out, "config.json"), c)
        configs.append(c)

    say(f"compiling {run.describe}, vmapped over the seeds {seeds} ...")
    w0, c0 = time.perf_counter(), time.process_time()
    compiled = train.lower(keys, run.hp).compile()
    compile_s, compile_cpu = time.perf_counter() - w0, time.process_time() - c0
    say(f"compiled in {compile_s:.1f} s; training {run.steps_done} env steps per seed ...")
    w0, c0 = time.perf_counter(), time.process_time()
    results = jax.device_get(jax.block_until_ready(compiled(keys, run.hp)))
    train_s, train_cpu = time.perf_counter() - w0, time.process_time() - c0
    say(f"trained in {train_s:.1f} s; learning curves: {len(run.updates)} points x {len(curve_seeds)} episodes ...")
    whole = {"setup_seconds": setup, "compile_seconds": compile_s, "compile_cpu_seconds": compile_cpu,
             "train_seconds": train_s, "train_cpu_seconds": train_cpu}
    share = {k: v / n for k, v in whole.items()}
    out_results = []
    for i, (s, out, config) in enumerate(zip(seeds, outs, configs)):
        result = jax.tree.map(lambda x, i=i: x[i], results)
        w0, c0 = time.perf_counter(), time.process_time()
        run.export(out, result, {"seed": s, "timesteps": run.config["timesteps"], "timesteps_done": run.steps_done})
        w1 = time.perf_counter()
        write_json_atomic(os.path.join(out, "curve.json"), run.curve(result))
        write_json_atomic(os.path.join(out, "train_curve.json"), {k: _plain(v) for k, v in result["curve"].items()})
        curve_s = time.perf_counter() - w1
        finish_config(config, run.steps_done, {
            **share, "curve_seconds": curve_s,
            "total_seconds": sum(share[k] for k in ("setup_seconds", "compile_seconds", "train_seconds"))
            + time.perf_counter() - w0,
            "total_cpu_seconds": share["compile_cpu_seconds"] + share["train_cpu_seconds"] + time.process_time() - c0})
        config["vmapped"].update(whole)
        write_json_atomic(os.path.join(out, "config.json"), config)
        out_results.append(TrainResult(path=out, model=None, seconds=share["train_seconds"], config=config))
    return out_results
