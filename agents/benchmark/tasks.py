"""The benchmark's work units, run by an execution backend (:mod:`agents.benchmark.backends`) in a worker:
train and evaluate one (env, agent, seed) run (:func:`train_and_evaluate`), a jitted agent's seeds of one env
vmapped in one compiled run and each of them evaluated (:func:`train_seeds_and_evaluate`), evaluate a kept model
again on other episodes (:func:`reevaluate`), evaluate the analytic controllers of one env
(:func:`analytic_results`) and, for an env with faults, the paper's controller on its fault-free counterpart
(:func:`fault_free_paper`).

A worker needs no file system shared with the driver: it trains in a scratch directory of its own
machine (``scratch``: the directory to make it in, ``None`` for the system's temporary directory),
removes it, and returns the run *record* ``{"result": dict, "files": {name: bytes},
"reevaluated": bool}``; the driver writes it (:func:`agents.benchmark.store.write_record`). What a run
computes does not depend on where it runs: the same spec gives the same record on every backend.
"""
from __future__ import annotations

import json
import os
import socket
import sys
import tempfile
import time

import numpy as np

from ..config.envs import FAULT_FREE, gym_factory, parallel_factory
from ..evaluate import evaluate_policy
from .plan import ANALYTIC, _run_signature, _training_overrides, agent_spec
from .store import RECORD_FILES, read_run_files

__all__ = ["train_and_evaluate", "train_seeds_and_evaluate", "reevaluate", "analytic_results", "fault_free_paper", "compile_kernels",
           "mean_trajectory", "executed_on"]


def mean_trajectory(series) -> np.ndarray:
    """Mean over episodes of per-step series; a shorter one (an episode that ended early) is padded
    with its last value."""
    arrs = [np.asarray(x, dtype=np.float64) for x in series]
    L = max(len(a) for a in arrs)
    return np.mean([np.concatenate([a, np.full(L - len(a), a[-1])]) if len(a) < L else a for a in arrs], axis=0)


def _episode_payload(res) -> dict:
    """What a run keeps of its evaluation: every episode's metrics and, for the error-norm figure, the
    task and estimation errors averaged over the episodes (``result.json`` of a full-budget run: ~45 kB
    instead of ~500 kB with every episode's trajectories)."""
    return {"episodes": [r.as_dict() for r in res],
            "t": max(res, key=lambda r: len(r.t)).t.tolist() if res else [],
            "tracking_error_mean": mean_trajectory([r.tracking_error for r in res]).tolist() if res else [],
            "estimation_error_mean": mean_trajectory([r.estimation_error for r in res]).tolist() if res else []}


def executed_on() -> dict:
    """Where this work unit runs: ``{"host": hostname, "pid": process id, "ray_node_id": the Ray node's id
    (``None`` outside a Ray worker)}`` (a record's ``executed_on``; it does not enter the numbers)."""
    node = None
    ray = sys.modules.get("ray")  # never imports Ray: a Ray worker has it imported already
    if ray is not None and ray.is_initialized():
        node = ray.get_runtime_context().get_node_id()
    return {"host": socket.gethostname(), "pid": os.getpid(), "ray_node_id": node}


def _evaluate(spec: dict, run_dir: str, train_s: float, curve: list) -> dict:
    """Evaluate the model in ``run_dir`` on the spec's episodes: the run's ``result.json`` document."""
    from ..training.loading import load_agent

    a = agent_spec(spec["agent"])
    agent = load_agent(run_dir)
    eval_env = (parallel_factory if a.multi_agent else gym_factory)(spec["env"], spec["env_kwargs"])()
    res = evaluate_policy(eval_env, agent.policy_for(eval_env), len(spec["eval_seeds"]), spec["eval_seeds"][0],
                          parallel=a.multi_agent)
    eval_env.close()
    return {"signature": _run_signature(spec), "agent": spec["agent"], "seed": spec["seed"], "train_seconds": train_s,
            "curve": curve, **_episode_payload(res), "cached": False, "executed_on": executed_on(),
            **({"recipe_file": spec["recipe_file"]} if "recipe_file" in spec else {})}


def train_and_evaluate(spec: dict, scratch: str | None = None) -> dict:
    """Train one (env, agent, seed) run as ``spec`` asks (:func:`agents.benchmark.plan.plan_runs`), in a
    scratch directory, and evaluate it: the run's record with its files (:data:`RECORD_FILES`)."""
    from ..training.curves import make_curve_callback
    from ..training.train import set_threads, train

    set_threads(spec["threads"])
    a = agent_spec(spec["agent"])
    env, env_kwargs = spec["env"], spec["env_kwargs"]
    with tempfile.TemporaryDirectory(prefix="run-", dir=scratch) as path:
        n_agents = len(parallel_factory(env, env_kwargs)().possible_agents) if a.multi_agent else 1
        curve = make_curve_callback(env, env_kwargs, spec["curve_seeds"], spec["curve_every"], n_agents=n_agents,
                                    path=os.path.join(path, "curve.json"))
        t0 = time.perf_counter()
        train(env, a.algo, multi_agent=a.multi_agent, timesteps=spec["steps"], seed=spec["seed"], out=path,
              progress=False, hyperparams=_training_overrides(spec) or None, env_kwargs=env_kwargs, hybrid=a.hybrid,
              callbacks=[curve], checkpoint_freq=0)
        result = _evaluate(spec, path, time.perf_counter() - t0, curve.points)
        return {"result": result, "files": read_run_files(path, RECORD_FILES), "reevaluated": False}


def train_seeds_and_evaluate(specs: list[dict], scratch: str | None = None) -> list[dict]:
    """Train the runs ``specs`` of one jitted agent on one env (the same spec but for the seed) as ONE compiled
    run vmapped over their seeds (:func:`agents.training.jax.vmap_seeds.train_jax_seeds`), in a scratch
    directory, and evaluate each: one record per run, as :func:`train_and_evaluate`'s. A vmapped run's
    ``train_seconds`` is its share, the whole task's training wall time (setup, compilation, the vmapped run, the
    learning curves) divided by the number of seeds, and ``train_seconds_shared`` records ``{"seconds": that time,
    "runs": seeds}``; a run trained alone (one seed) records its own ``total_seconds``. ``jax_enable_x64`` (an env
    with communication faults switches it on) is restored afterwards: the worker's next job runs as before.

    The budget's env options train the jitted run too (:func:`agents.benchmark.plan.jax_env_options`); its learning
    curve is scored on the env's own episodes (:mod:`agents.training.jax.run`'s), which differ from the budget's
    only in ``tiny`` (20-step episodes there, 400 for the curve)."""
    first = specs[0]
    differ = [k for k in ("env", "agent", "steps", "hp", "env_kwargs", "curve_seeds", "curve_points", "threads")
            if any(sp[k] != first[k] for sp in specs)]
    if differ:
        raise ValueError(f"vmapped seeds must share their run's configuration; {differ} differ")
    a = agent_spec(first["agent"])
    import jax

    x64 = jax.config.jax_enable_x64
    with tempfile.TemporaryDirectory(prefix="runs-", dir=scratch) as root:
        try:
            return _train_seeds(specs, a, root)
        finally:
            jax.config.update("jax_enable_x64", x64)


def _train_seeds(specs: list[dict], a, root: str) -> list[dict]:
    """:func:`train_seeds_and_evaluate`'s work in the scratch directory ``root``."""
    from ..training.jax.vmap_seeds import train_jax_seeds

    first = specs[0]
    paths = [os.path.join(root, f"s{sp['seed']}") for sp in specs]
    t0 = time.perf_counter()
    runs = train_jax_seeds(first["env"], a.algo, multi_agent=a.multi_agent, seeds=[sp["seed"] for sp in specs],
                           outs=paths, timesteps=first["steps"], hyperparams=_training_overrides(first) or None,
                           threads=first["threads"], progress=False, curve_points=first["curve_points"],
                           curve_seeds=first["curve_seeds"])
    seconds = time.perf_counter() - t0
    records = []
    for sp, path, run in zip(specs, paths, runs):
        with open(os.path.join(path, "curve.json")) as fh:
            curve = json.load(fh)["points"]
        shared = "vmapped" in run.config  # else trained alone (one seed, or no vmapped builder): its own time
        result = _evaluate(sp, path, seconds / len(specs) if shared else run.config["total_seconds"], curve)
        if shared:
            result["train_seconds_shared"] = {"seconds": seconds, "runs": len(specs)}
        records.append({"result": result, "files": read_run_files(path, RECORD_FILES), "reevaluated": False})
    return records


def reevaluate(spec: dict, files: dict, previous: dict, scratch: str | None = None) -> dict:
    """Evaluate a kept model (``files``: its ``config.json``, ``model.zip`` and ``vecnormalize.pkl`` as
    bytes) on the episodes of ``spec``; ``previous``: its stored result (training time and learning
    curve are kept). The record holds no files: the run's own stay as they are."""
    from ..training.train import set_threads

    set_threads(spec["threads"])
    with tempfile.TemporaryDirectory(prefix="run-", dir=scratch) as path:
        for name, data in files.items():
            with open(os.path.join(path, os.path.basename(name)), "wb") as fh:
                fh.write(data)
        result = _evaluate(spec, path, previous["train_seconds"], previous["curve"])
    return {"result": result, "files": {}, "reevaluated": True}


# ---------------------------------------------------------------------- analytic controllers
def _analytic_policies(penv) -> list:
    """The analytic controllers in :data:`ANALYTIC` order, built on the parallel env ``penv``:
    the paper's separation controller; the same law on a Kalman estimate from the centralised
    agent's information (every node's observation pooled) and the LQ-optimal controller for the
    task's own cost on that information (:mod:`baselines.pooled`); the full-state oracle, the
    decentralised controller and zero input (:mod:`baselines.references`)."""
    from baselines.policies import SeparationPolicy
    from baselines.pooled import PooledKalmanPolicy, PooledLQGPolicy
    from baselines.references import DecentralizedPolicy, OraclePolicy, ZeroInputPolicy

    return [cls(penv) for cls in (SeparationPolicy, PooledKalmanPolicy, PooledLQGPolicy, OraclePolicy,
                                  DecentralizedPolicy, ZeroInputPolicy)]


def analytic_results(env: str, env_kwargs: dict, eval_seed: int, episodes: int) -> dict:
    """Every analytic controller's evaluation payload on ``env``'s episodes ``eval_seed + k``, by label."""
    penv = parallel_factory(env, env_kwargs)()
    out = {label: _episode_payload(evaluate_policy(penv, pol, episodes, eval_seed, parallel=True))
           for label, pol in zip(ANALYTIC, _analytic_policies(penv))}
    penv.close()
    return out


def fault_free_paper(env: str, env_kwargs: dict, eval_seed: int, episodes: int) -> dict:
    """The paper's controller on the fault-free counterpart of ``env`` (:data:`agents.config.envs.FAULT_FREE`: the
    same task with ``faults=None``) on the episodes ``eval_seed + k``: its evaluation payload, the reference
    ``J_paper,fault-free`` of the degradation columns (:mod:`agents.benchmark.report`). The same seed gives the
    same episode in both environments (initial state, reference; the faulted environment draws its fault
    seed last from the copy's generator), which the report checks on the recorded ``x(0)``."""
    from baselines.policies import SeparationPolicy

    penv = parallel_factory(FAULT_FREE[env], env_kwargs)()
    out = _episode_payload(evaluate_policy(penv, SeparationPolicy(penv), episodes, eval_seed, parallel=True))
    penv.close()
    return out


def compile_kernels(env_names: list[str], env_kwargs: dict) -> None:
    """Compile (or load from numba's on-disk cache) the compiled steps every worker needs, once, in
    this process before the workers start: on a cold cache (a fresh install) each worker would
    otherwise compile the same kernels concurrently (measured on 2 cores, the tiny budget: 195 s
    cold against 14 s warm with the workers compiling; one compilation takes ~90 s)."""
    from baselines.policies import SeparationPolicy

    # with the fault-free counterparts of faulted envs (fault_free_paper runs them)
    for e in dict.fromkeys([*env_names, *(FAULT_FREE[e] for e in env_names if e in FAULT_FREE)]):
        penv = parallel_factory(e, env_kwargs)()
        obs, _ = penv.reset(seed=0)
        penv.step(SeparationPolicy(penv)(obs))
        penv.close()
