"""RL versus the analytic controllers on the same seeded initial conditions.

``dobs-envs benchmark --env tracking --budget quick --out runs/benchmark``

1. trains (or loads from ``<out>/models/<agent>/`` when a run with the same
   budget, seed and env options is cached there) the RL agents of the budget:
   centralised PPO and SAC on the Gymnasium env, parameter-shared PPO on the
   PettingZoo env (``full`` adds TD3 and shared SAC);
2. evaluates every policy -- the RL agents, the paper's separation controller
   (:class:`baselines.policies.SeparationPolicy`), the full-state oracle, the
   no-communication decentralised controller and zero input
   (:mod:`baselines.references`) -- on the same ``K`` episodes, reset with seeds
   ``eval_seed + k`` (recorded with each episode's ``x(0)`` in the JSON);
3. prints the table (mean +- std over episodes) and writes ``results.csv``,
   ``results.json`` and ``error_norms.png`` (tracking-error and estimation-error
   norms over time, mean over episodes, per policy).

Budgets (environment steps per agent; wall times measured on a 2-core CPU):

- ``tiny``: a few hundred steps and 20-step (1 s) episodes (tests);
- ``quick``: the README's main job, ~10 minutes;
- ``full``: longer training (hours).
"""
from __future__ import annotations

import csv
import json
import os
import time

import numpy as np

from .config import gym_factory, parallel_factory
from .evaluate import evaluate_policy, summarise

__all__ = ["BUDGETS", "run_benchmark", "format_table"]

#: agent key -> (algorithm, multi_agent, label)
AGENTS = {
    "ppo": ("ppo", False, "PPO (centralised)"),
    "sac": ("sac", False, "SAC (centralised)"),
    "td3": ("td3", False, "TD3 (centralised)"),
    "ppo_ma": ("ppo", True, "PPO (shared, per node)"),
    "sac_ma": ("sac", True, "SAC (shared, per node)"),
}

BUDGETS = {
    "tiny": {
        "episodes": 2,
        "env_kwargs": {"max_cycles": 20},
        "agents": {"ppo": 256, "sac": 96, "ppo_ma": 128},
        "hyperparams": {
            "ppo": {"n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1},
            "sac": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
        },
    },
    "quick": {
        "episodes": 10,
        "env_kwargs": {},
        "agents": {"ppo": 200_000, "sac": 10_000, "ppo_ma": 60_000},
        "hyperparams": {},
    },
    "full": {
        "episodes": 20,
        "env_kwargs": {},
        "agents": {"ppo": 1_000_000, "sac": 100_000, "td3": 100_000, "ppo_ma": 400_000, "sac_ma": 100_000},
        "hyperparams": {},
    },
}

COLUMNS = [
    ("return", "return"),
    ("final_tracking_error", "final err"),
    ("rms_estimation_error", "RMS est err"),
    ("control_effort", "effort"),
]


def _train_or_load(env, key, steps, seed, out, env_kwargs, hp_over, progress, tensorboard):
    from .train import load_agent, train

    algo, multi, _ = AGENTS[key]
    path = os.path.join(out, "models", key)
    cfg_path = os.path.join(path, "config.json")
    if os.path.exists(cfg_path) and os.path.exists(os.path.join(path, "model.zip")):
        with open(cfg_path) as fh:
            cfg = json.load(fh)
        if (cfg.get("timesteps") == steps and cfg.get("seed") == seed and cfg.get("env") == env
                and cfg.get("env_kwargs") == dict(env_kwargs) and cfg.get("overrides", {}) == (hp_over or {})):
            return load_agent(path), 0.0, True
    t0 = time.perf_counter()
    res = train(env, algo, multi_agent=multi, timesteps=steps, seed=seed, out=path, progress=progress,
                hyperparams=hp_over or None, env_kwargs=env_kwargs, tensorboard=tensorboard)
    # remember the overrides so a cache hit needs the same budget
    cfg = dict(res.config, overrides=hp_over or {})
    with open(cfg_path, "w") as fh:
        json.dump(cfg, fh, indent=2, default=str)
    return load_agent(path), time.perf_counter() - t0, False


def _analytic(penv):
    from baselines.policies import SeparationPolicy
    from baselines.references import DecentralizedPolicy, OraclePolicy, ZeroInputPolicy

    return [
        ("paper (separation)", SeparationPolicy(penv)),
        ("oracle (full state)", OraclePolicy(penv)),
        ("decentralised (no comm.)", DecentralizedPolicy(penv)),
        ("zero input", ZeroInputPolicy(penv)),
    ]


def format_table(rows: list[dict]) -> str:
    head = f"{'policy':26s} | " + " | ".join(f"{lab:>21s}" for _, lab in COLUMNS) + " | fail"
    lines = [head, "-" * len(head)]
    for r in rows:
        cells = []
        for key, _ in COLUMNS:
            m, s = r[f"{key}_mean"], r[f"{key}_std"]
            cells.append(f"{m:>10.4g} +- {s:<7.3g}")
        lines.append(f"{r['policy']:26s} | " + " | ".join(cells) + f" | {r['failure_rate']:4.0%}")
    return "\n".join(lines)


def _plot(curves: dict, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for name, (t, te, ee) in curves.items():
        axes[0].plot(t, te, lw=1.2, label=name)
        axes[1].plot(t, ee, lw=1.2, label=name)
    axes[0].set_ylabel(r"mean $\|x - x_r\|$ over episodes")
    axes[1].set_ylabel(r"mean RMS$_i$ $\|\hat x_i - x\|$ (env observers)")
    for ax in axes:
        ax.set_yscale("log")
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _mean_curve(results):
    """Mean over episodes; episodes that ended early are held at their last value."""
    L = max(len(r.t) for r in results)
    t = max(results, key=lambda r: len(r.t)).t
    def pad(a):
        return np.concatenate([a, np.full(L - len(a), a[-1])]) if len(a) < L else a
    te = np.mean([pad(r.tracking_error) for r in results], axis=0)
    ee = np.mean([pad(r.estimation_error) for r in results], axis=0)
    return t, te, ee


def run_benchmark(env: str = "tracking", budget: str = "quick", out: str = "runs/benchmark", *, seed: int = 0,
                  eval_seed: int = 10_000, episodes: int | None = None, timesteps: int | None = None,
                  agents: list[str] | None = None, progress: bool = True, tensorboard: str | None = None,
                  threads: int | None = 1) -> dict:
    """Run the benchmark (see module doc); returns the JSON document it writes."""
    from .train import set_threads

    if budget not in BUDGETS:
        raise ValueError(f"unknown budget {budget!r}; choose from {sorted(BUDGETS)}")
    t_start = time.perf_counter()
    set_threads(threads)
    B = BUDGETS[budget]
    episodes = int(episodes or B["episodes"])
    env_kwargs = dict(B["env_kwargs"])
    plan = dict(B["agents"])
    if agents is not None:
        unknown = set(agents) - set(AGENTS)
        if unknown:
            raise ValueError(f"unknown agents {sorted(unknown)}; choose from {sorted(AGENTS)}")
        plan = {k: plan.get(k, timesteps or B["agents"].get("ppo", 10_000)) for k in agents}
    if timesteps is not None:
        plan = {k: int(timesteps) for k in plan}
    os.makedirs(out, exist_ok=True)

    timings, trained = {}, {}
    for key, steps in plan.items():
        algo = AGENTS[key][0]
        hp = dict(B["hyperparams"].get(algo, {}))
        agent, secs, cached = _train_or_load(env, key, steps, seed, out, env_kwargs, hp, progress, tensorboard)
        trained[key] = agent
        timings[f"train_{key}"] = secs
        if progress:
            print(f"{AGENTS[key][2]}: {'loaded cached model' if cached else f'trained {steps} steps in {secs:.0f} s'}")

    t_eval = time.perf_counter()
    penv = parallel_factory(env, env_kwargs)()
    genv = gym_factory(env, env_kwargs)()
    rows, curves, episodes_json = [], {}, {}
    policies = []
    for key, agent in trained.items():
        label = AGENTS[key][2]
        if agent.multi_agent:
            policies.append((label, agent.parallel_policy(penv), penv, True))
        else:
            policies.append((label, agent.central_policy(), genv, False))
    for label, pol in _analytic(penv):
        policies.append((label, pol, penv, True))
    for label, pol, e, parallel in policies:
        res = evaluate_policy(e, pol, episodes, eval_seed, parallel=parallel, progress=progress, desc=label)
        summ = {"policy": label, **summarise(res)}
        rows.append(summ)
        curves[label] = _mean_curve(res)
        episodes_json[label] = [r.as_dict() for r in res]
    penv.close()
    genv.close()
    timings["evaluate"] = time.perf_counter() - t_eval
    timings["total"] = time.perf_counter() - t_start

    table = format_table(rows)
    doc = {
        "env": env, "budget": budget, "seed": seed, "eval_seeds": [eval_seed + k for k in range(episodes)],
        "episodes": episodes, "env_kwargs": env_kwargs, "train_steps": plan, "timings_s": timings,
        "metrics_doc": {
            "return": "sum of the team reward -(e'Qe + u'Ru) * period",
            "final_tracking_error": "||x - x_r|| (||x|| without reference) at the last step",
            "rms_estimation_error": "RMS over time and nodes of ||xhat_i - x|| of the env's distributed observer",
            "control_effort": "int ||u||^2 dt of the applied (clipped) input",
            "failure_rate": "fraction of episodes terminated early (state bound exceeded / non-finite)",
        },
        "results": rows, "episodes_detail": episodes_json, "table": table,
    }
    with open(os.path.join(out, "results.json"), "w") as fh:
        json.dump(doc, fh, indent=2)
    keys = ["policy", "episodes"] + [f"{k}_{s}" for k, _ in COLUMNS + [("length", "")] for s in ("mean", "std")] + [
        "failure_rate", "rms_policy_estimation_error_mean"]
    with open(os.path.join(out, "results.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    _plot(curves, os.path.join(out, "error_norms.png"), f"{env}: {budget} budget, {episodes} episodes")
    return doc
