"""The jitted shared-policy PPO (``train --trainer jax --multi-agent``) beside SB3's (``--multi-agent``) on tracking.

Both train one policy shared by the five controller nodes with the shipped multi-agent recipe
(``agents/config/hyperparams/ppo.yaml``: ``default-ma`` and ``tracking-ma`` over the tracking section), the same
budget in env steps and the same training seed, each through the ``dobs-envs train`` command in a child process
of this script, one after the other, one core each (``--threads 1``: torch on one thread, XLA on one thread).
Figures per run: the child's CPU seconds (user + system, ``resource.getrusage(RUSAGE_CHILDREN)``: imports, env
construction, the jitted run's compilation, the learning curve's episodes included) and wall seconds; the jitted
run's compile and training CPU seconds from its ``config.json``; SB3's ``train_seconds`` (wall of ``learn``).
Then both runs are scored by the evaluation harness of ``dobs-envs evaluate --model`` (``agents.training.loading``:
``load_agent(run).policy_for(env)`` on the compiled PettingZoo env, ``agents.evaluate.evaluate_policy``) on the
evaluation episodes ``--eval-seed .. + --episodes - 1``, with the paper's controller on the same episodes: a run's
score is the mean over the episodes of J / J_paper (the benchmark's per-run score).

    PYTHONPATH=. python benchmarks/bench_jax_ippo.py [--steps 122880] [--seed 0] [--out results/x.json]

Measured on a machine shared with other work: the load averages before and after each phase are recorded.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

ENV = "tracking"


def _load() -> list:
    return [round(x, 2) for x in os.getloadavg()]


def _child_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _train(trainer: str, steps: int, seed: int, out: str) -> dict:
    cmd = [sys.executable, "-m", "dobs_envs.cli", "train", "--trainer", trainer, "--multi-agent", "--env", ENV,
           "--timesteps", str(steps), "--seed", str(seed), "--out", out, "--threads", "1", "--no-progress"]
    rec = {"command": " ".join(["dobs-envs"] + cmd[3:]), "load_before": _load()}
    c0, w0 = _child_cpu(), time.perf_counter()
    subprocess.run(cmd, check=True)
    rec.update(cpu_seconds=_child_cpu() - c0, wall_seconds=time.perf_counter() - w0, load_after=_load())
    cfg = json.load(open(os.path.join(out, "config.json")))
    for k in ("timesteps_done", "n_agents", "train_seconds", "train_cpu_seconds", "compile_cpu_seconds",
              "compile_seconds", "curve_seconds", "library", "library_version"):
        if k in cfg:
            rec[k] = cfg[k]
    return rec


def _score(run: str, episodes: int, seed: int, paper: np.ndarray) -> dict:
    from agents.config.envs import parallel_factory
    from agents.evaluate import evaluate_policy
    from agents.training.loading import load_agent

    agent = load_agent(run)
    env = parallel_factory(ENV, agent.config.get("env_kwargs"))()
    res = evaluate_policy(env, agent.policy_for(env), episodes, seed, parallel=True)
    env.close()
    cost = np.array([r.cost for r in res])
    ratio = cost / paper
    return {"policy": agent.name, "cost_mean": float(cost.mean()), "cost_ratio_mean": float(ratio.mean()),
            "cost_ratio_median": float(np.median(ratio)), "cost_ratio": ratio.tolist(),
            "failure_rate": float(np.mean([r.failed for r in res]))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=122880)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--eval-seed", type=int, default=10000)
    ap.add_argument("--trainers", default="jax,sb3")
    ap.add_argument("--out", default=None)
    ap.add_argument("--overwrite", action="store_true")
    a = ap.parse_args(argv)
    if a.out and os.path.exists(a.out) and not a.overwrite:
        ap.error(f"--out {a.out} exists (--overwrite to replace it)")
    from agents.training.curves import paper_costs

    seeds = list(range(a.eval_seed, a.eval_seed + a.episodes))
    record = {"env": ENV, "steps": a.steps, "seed": a.seed, "eval_seeds": [seeds[0], seeds[-1]], "runs": {},
              "command": "PYTHONPATH=. python benchmarks/bench_jax_ippo.py " + " ".join(argv or sys.argv[1:])}
    paper = paper_costs(ENV, {}, seeds)
    record["paper_cost_mean"] = float(paper.mean())
    with tempfile.TemporaryDirectory() as tmp:
        for trainer in a.trainers.split(","):
            run = os.path.join(tmp, trainer)
            rec = _train(trainer, a.steps, a.seed, run)
            rec.update(_score(run, a.episodes, a.eval_seed, paper))
            record["runs"][trainer] = rec
            print(trainer, {k: v for k, v in rec.items() if k != "cost_ratio"}, flush=True)
    r = record["runs"]
    if "jax" in r and "sb3" in r:
        # whole commands (imports, set-up, compilation, the curve's episodes included), CPU seconds
        record["cpu_ratio_commands_jax_over_sb3"] = r["jax"]["cpu_seconds"] / r["sb3"]["cpu_seconds"]
        # training alone: the compiled run's CPU seconds over SB3's learn() wall seconds (one thread: ~its CPU)
        record["ratio_training_jax_cpu_over_sb3_learn"] = r["jax"]["train_cpu_seconds"] / r["sb3"]["train_seconds"]
        print("ratios jax / sb3: commands (CPU)", record["cpu_ratio_commands_jax_over_sb3"], "training",
              record["ratio_training_jax_cpu_over_sb3_learn"])
    if a.out:
        with open(a.out, "w") as f:
            json.dump(record, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
