"""RL and hybrid agents versus the paper's controllers, over training seeds, with confidence intervals.

``dobs-envs benchmark --env tracking --budget quick --out runs/benchmark``
(``--env all``: tracking, disturbance_rejection, hetero_mas, random_network)

1. **Train** every agent of the budget with several training seeds, in parallel
   worker processes (``--workers``, one per core by default): pure RL (centralised PPO,
   parameter-shared PPO; ``full`` adds SAC, TD3 and PPO trained on the sqrt cost) and the hybrids (residual PPO, centralised and shared; PPO warm-started by
   behaviour cloning), each with the recipe of ``agents/hyperparams/<algo>.yaml``.
   Each run records its learning curve (:mod:`agents.curves`). A finished run is
   reused when its configuration is identical (``<out>/models/<env>/<budget>/<agent>/s<seed>``),
   so an interrupted benchmark resumes where it stopped.
2. **Evaluate** every policy -- the trained agents, the paper's separation
   controller, the full-state oracle, the no-communication decentralised controller
   and zero input -- on the *same* ``K`` episodes of the task's own environment
   (reset with seeds ``eval_seed + k``, recorded with each episode's ``x(0)``).
3. **Aggregate** as rliable defines it, with the training run as the unit (:mod:`agents.stats`):
   a run's score is the mean over the episodes of the cost ratio ``J_policy / J_paper`` on the
   same episode (< 1: cheaper than the paper's controller); the IQM and the mean of the run
   scores with 95 % percentile-bootstrap CIs that resample whole runs, the probability of
   improvement ``P(J < J_paper)`` over matched (run, episode) pairs, and the transient cost
   (first 2 s), the steady-state error (RMS of the task error over the last 5 s) and the
   failure rate; each row states its budget and the information its policy acts on.
4. **Write** ``<out>/<env>/results.{json,csv}``, ``error_norms.png``,
   ``learning_curves.png`` and ``<out>/summary.{json,png}`` (every env's cost ratios
   with their CIs).

Budgets (environment steps per agent and seed; wall times on a 2-core CPU in the README):

- ``tiny``: a few hundred steps, 20-step episodes (tests);
- ``quick``: the README's main job (3 training seeds);
- ``full``: 10 training seeds, longer training, SAC/TD3, shared residual PPO and the
  sqrt-cost PPO (hours per env on 2 cores).
"""
from __future__ import annotations

import csv
import json
import multiprocessing
import os
import shutil
import signal
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from .config import ENVS, gym_factory, parallel_factory
from .evaluate import STEADY_S, TRANSIENT_S, evaluate_policy
from .seeds import EVALUATION, TUNING, check_episode_seeds, check_training_seeds
from .stats import improvement_estimate, interval_estimate, iqm, mean_estimate, run_scores

__all__ = ["AGENTS", "BUDGETS", "run_benchmark", "plan_runs", "pending_runs", "reevaluated_runs", "replaced_runs",
           "BenchmarkPlan", "RunConflictError", "format_table", "AgentSpec"]


@dataclass(frozen=True)
class AgentSpec:
    """A benchmark agent: algorithm, parameter sharing, hybrid kind, label, extra training env options."""

    algo: str
    multi_agent: bool
    hybrid: str | None
    label: str
    train_env_kwargs: tuple = ()

    @property
    def kind(self) -> str:
        return "hybrid" if self.hybrid else "RL"

    @property
    def information(self) -> str:
        """What the agent observes (the table's information column)."""
        return INFO_OWN_NODE if self.multi_agent else INFO_POOLED


AGENTS = {
    "ppo": AgentSpec("ppo", False, None, "PPO (centralised)"),
    "ppo_ma": AgentSpec("ppo", True, None, "PPO (shared, per node)"),
    "sac": AgentSpec("sac", False, None, "SAC (centralised)"),
    "td3": AgentSpec("td3", False, None, "TD3 (centralised)"),
    "crossq": AgentSpec("crossq", False, None, "CrossQ (centralised)"),
    "sac_ma": AgentSpec("sac", True, None, "SAC (shared, per node)"),
    "ppo_log": AgentSpec("ppo", False, None, "PPO (centralised, log-cost training)", (("reward", "log"),)),
    "ppo_sqrt": AgentSpec("ppo", False, None, "PPO (centralised, sqrt-cost training)", (("reward", "sqrt"),)),
    "ppo_res": AgentSpec("ppo", False, "residual", "residual PPO (centralised) [hybrid]"),
    "ppo_res_ma": AgentSpec("ppo", True, "residual", "residual PPO (shared) [hybrid]"),
    "ppo_bc": AgentSpec("ppo", False, "bc", "BC-warm-started PPO (centralised) [hybrid]"),
}

BUDGETS = {
    "tiny": {
        "episodes": 2, "seeds": 2, "env_kwargs": {"max_cycles": 20}, "curve_points": 2, "curve_episodes": 1,
        "agents": {"ppo": 256, "ppo_ma": 128, "ppo_res": 128, "ppo_bc": 128},
        "hyperparams": {
            "ppo": {"n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1, "bc": {"episodes": 1, "epochs": 1}},
            "sac": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
            "td3": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
            "crossq": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
        },
    },
    "quick": {
        "episodes": 10, "seeds": 3, "env_kwargs": {}, "curve_points": 6, "curve_episodes": 3,
        "agents": {"ppo": 400_000, "ppo_ma": 120_000, "ppo_res": 150_000, "ppo_bc": 150_000},
        "hyperparams": {},
    },
    "full": {
        "episodes": 20, "seeds": 10, "env_kwargs": {}, "curve_points": 10, "curve_episodes": 5,
        # sac_ma (SAC per node: 5 samples and gradient steps per env step, ~50 env steps/s) and
        # ppo_log (J/J_paper 21x and 67x at 400k on tracking) are available through --agents
        # the off-policy agents at PPO's env steps (issue 21: equal budgets)
        "agents": {"ppo": 600_000, "ppo_ma": 300_000, "ppo_sqrt": 600_000, "sac": 600_000, "td3": 600_000,
                   "crossq": 600_000, "ppo_res": 300_000, "ppo_res_ma": 150_000, "ppo_bc": 300_000},
        "hyperparams": {},
    },
}

#: the information columns (what a policy observes)
INFO_POOLED = "pooled: every node's obs"
INFO_OWN_NODE = "own node + neighbours"
ANALYTIC_INFO = {"paper (separation)": "own observer's estimate",
                 "Kalman on pooled obs + paper law": INFO_POOLED,
                 "LQG on pooled obs (task's Q, R)": INFO_POOLED,
                 "oracle (full state)": "full state (privileged)",
                 "decentralised (no comm.)": "own measurement, no comm.", "zero input": "none"}
ANALYTIC = tuple(ANALYTIC_INFO)
PAPER = ANALYTIC[0]
#: what the "paper (separation)" row is where the paper prints no controller for the task
PAPER_NOTES = {
    "hetero_mas": ("hetero_mas: the paper prints no controller for this task (NE1's input is prescribed); the "
                   "reference is this project's rendezvous law u^k = K^k xhat (an LQR rendezvous gain, "
                   "dobs_envs/scenarios/mas_tasks.py) on the paper's distributed estimates: the paper's separation "
                   "principle, not a controller printed in the paper"),
}
STATISTICS_DOC = (
    "rliable definitions with the training run as the statistical unit: a run's score is the mean over its "
    "evaluation episodes of J / J_paper (a failed episode at its cost with the termination penalty); IQM = "
    "25%-trimmed mean of the run scores; 95% CI: percentile bootstrap over runs (50000 replicates; over several "
    "envs, runs resampled within each env); mean J / J_paper with the same CI; P(J < J_paper): probability of "
    "improvement over the matched (run, episode) pairs (rliable's Mann-Whitney form, ties 1/2), CI by resampling "
    "whole runs; transient cost and errors: IQM over runs of the run means; analytic controllers are "
    "deterministic (one run: no interval)")
CURVE_SEED = TUNING.start  # learning-curve episodes use seeds CURVE_SEED + k (the tuning range, agents/seeds.py)


# ---------------------------------------------------------------------- one training run (worker process)
def _ignore_sigint() -> None:
    """Worker initializer: Ctrl-C reaches the whole process group; the main process alone handles it
    (and terminates the workers), so workers print no tracebacks and start no new job."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _terminate_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel the queued jobs and end the running ones (their runs have no result.json, so the next
    invocation trains them again; finished runs are kept)."""
    pool.shutdown(wait=False, cancel_futures=True)
    terminate = getattr(pool, "terminate_workers", None)  # Python >= 3.14
    procs = list((getattr(pool, "_processes", None) or {}).values())
    if terminate is not None:
        terminate()
    else:
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
    for proc in procs:
        proc.join(timeout=10)


def _run_signature(spec: dict) -> dict:
    return {k: spec[k] for k in ("env", "agent", "seed", "steps", "hp", "env_kwargs", "eval_seeds", "curve_seeds",
                                 "curve_every")}


def _mean_trajectory(series) -> np.ndarray:
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
            "tracking_error_mean": _mean_trajectory([r.tracking_error for r in res]).tolist() if res else [],
            "estimation_error_mean": _mean_trajectory([r.estimation_error for r in res]).tolist() if res else []}


def _run_means(run: dict, key: str) -> np.ndarray:
    """A run's mean trajectory of ``key`` (results stored before 2026-12-02 hold every episode's)."""
    return np.asarray(run[f"{key}_mean"]) if f"{key}_mean" in run else _mean_trajectory(run[key])


TRAINING_KEYS = ("env", "agent", "seed", "steps", "hp", "env_kwargs", "curve_seeds", "curve_every")
"""The part of a run's signature that defines its training (the rest, ``eval_seeds``, its evaluation)."""


def _finished_run(path: str, sig: dict, hyperparams: dict, *, training_only: bool = False) -> dict | None:
    """The stored result of the run in ``path`` if it finished with this signature *and* was trained
    with these merged hyperparameters (its ``config.json``): editing a recipe file retrains the
    affected runs instead of reusing results of the old recipe. None otherwise.

    ``training_only``: compare only the signature's :data:`TRAINING_KEYS` (the run was trained as
    ``sig`` asks, perhaps evaluated on other episodes)."""
    try:
        with open(os.path.join(path, "result.json")) as fh:
            prev = json.load(fh)
        with open(os.path.join(path, "config.json")) as fh:
            trained_with = json.load(fh).get("hyperparams")
    except (OSError, ValueError):
        return None
    old = prev.get("signature")
    if not isinstance(old, dict) or trained_with != json.loads(json.dumps(hyperparams)):
        return None
    keys = TRAINING_KEYS if training_only else tuple(sig)
    if set(old) != set(sig) or any(old[k] != sig[k] for k in keys):
        return None
    prev["cached"] = True
    return prev


def _training_overrides(spec: dict) -> dict:
    """The budget's hyperparameter overrides of a run plus its agent's training-only env options."""
    a = AGENTS[spec["agent"]]
    hp = dict(spec["hp"])
    if a.train_env_kwargs:
        hp["env_kwargs"] = {**hp.get("env_kwargs", {}), **dict(a.train_env_kwargs)}
    return hp


def _stored_result(spec: dict, *, training_only: bool = False) -> dict | None:
    """The finished result of ``spec``'s run if it can be reused with today's recipe, else None
    (``training_only``: see :func:`_finished_run`)."""
    from .recipes import resolve_recipe

    a = AGENTS[spec["agent"]]
    recipe = resolve_recipe(a.algo, spec["env"], multi_agent=a.multi_agent, hybrid=a.hybrid,
                            overrides=_training_overrides(spec) or None)
    return _finished_run(spec["path"], _run_signature(spec), recipe.hyperparams, training_only=training_only)


def _stored_model(spec: dict) -> dict | None:
    """The stored result of a run trained exactly as ``spec`` asks but evaluated on other episodes,
    if its model is kept (``model.zip``, and ``vecnormalize.pkl`` when it normalises): the benchmark
    evaluates that model again instead of training it again. None otherwise."""
    import zipfile

    prev = _stored_result(spec, training_only=True)
    if prev is None or prev["signature"] == _run_signature(spec):
        return None
    path = spec["path"]
    try:
        with open(os.path.join(path, "config.json")) as fh:
            normalize = bool(json.load(fh).get("normalize"))
    except (OSError, ValueError):
        return None
    model = os.path.join(path, "model.zip")
    if not (os.path.isfile(model) and zipfile.is_zipfile(model)):
        return None
    if normalize and not os.path.isfile(os.path.join(path, "vecnormalize.pkl")):
        return None
    return prev


def _evaluate_and_record(spec: dict, train_s: float, curve: list) -> dict:
    """Evaluate the model in ``spec['path']`` on the spec's episodes and write ``result.json`` (atomically)."""
    from .loading import load_agent

    a = AGENTS[spec["agent"]]
    agent = load_agent(spec["path"])
    eval_env = (parallel_factory if a.multi_agent else gym_factory)(spec["env"], spec["env_kwargs"])()
    res = evaluate_policy(eval_env, agent.policy_for(eval_env), len(spec["eval_seeds"]), spec["eval_seeds"][0],
                          parallel=a.multi_agent)
    eval_env.close()
    out = {"signature": _run_signature(spec), "agent": spec["agent"], "seed": spec["seed"], "train_seconds": train_s,
           "curve": curve, **_episode_payload(res), "cached": False}
    done_path = os.path.join(spec["path"], "result.json")
    with open(done_path + ".tmp", "w") as fh:
        json.dump(out, fh)
    os.replace(done_path + ".tmp", done_path)  # atomic: a half-written result is never taken as finished
    return out


def _train_and_evaluate(spec: dict) -> dict:
    """Train one (agent, seed) and evaluate it; reuse a finished identical run, or evaluate a kept
    model again when only the evaluation episodes changed. Runs in a worker."""
    from .curves import make_curve_callback
    from .train import set_threads, train

    set_threads(spec["threads"])
    prev = _stored_result(spec)
    if prev is not None:
        return prev
    prev = _stored_model(spec)
    if prev is not None:  # trained as asked: evaluate it on the new episodes (its training time counts as 0)
        out = _evaluate_and_record(spec, prev["train_seconds"], prev["curve"])
        return {**out, "reevaluated": True}
    path = spec["path"]
    a = AGENTS[spec["agent"]]
    env, env_kwargs = spec["env"], spec["env_kwargs"]
    os.makedirs(path, exist_ok=True)
    n_agents = len(parallel_factory(env, env_kwargs)().possible_agents) if a.multi_agent else 1
    curve = make_curve_callback(env, env_kwargs, spec["curve_seeds"], spec["curve_every"], n_agents=n_agents,
                                path=os.path.join(path, "curve.json"))
    t0 = time.perf_counter()
    train(env, a.algo, multi_agent=a.multi_agent, timesteps=spec["steps"], seed=spec["seed"], out=path,
          progress=False, hyperparams=_training_overrides(spec) or None, env_kwargs=env_kwargs, hybrid=a.hybrid,
          callbacks=[curve], checkpoint_freq=0)
    return _evaluate_and_record(spec, time.perf_counter() - t0, curve.points)


# ---------------------------------------------------------------------- analytic controllers (main process)
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


def _analytic_results(env: str, env_kwargs: dict, eval_seed: int, episodes: int) -> dict:
    penv = parallel_factory(env, env_kwargs)()
    out = {label: _episode_payload(evaluate_policy(penv, pol, episodes, eval_seed, parallel=True))
           for label, pol in zip(ANALYTIC, _analytic_policies(penv))}
    penv.close()
    return out


def _compile_kernels(env_names: list[str], env_kwargs: dict) -> None:
    """Compile (or load from numba's on-disk cache) the compiled steps every worker needs, once, in
    this process before the workers start: on a cold cache (a fresh install) each worker would
    otherwise compile the same kernels concurrently (measured on 2 cores, the tiny budget: 195 s
    cold against 14 s warm with the workers compiling; one compilation takes ~90 s)."""
    from baselines.policies import SeparationPolicy

    for e in env_names:
        penv = parallel_factory(e, env_kwargs)()
        obs, _ = penv.reset(seed=0)
        penv.step(SeparationPolicy(penv)(obs))
        penv.close()


# ---------------------------------------------------------------------- aggregation
def _matrix(runs: list[dict], key: str) -> np.ndarray:
    return np.array([[e[key] for e in r["episodes"]] for r in runs], dtype=np.float64)


def _aggregate(label: str, kind: str, runs: list[dict], paper_cost: np.ndarray, *, information: str,
               steps: int | None = None) -> dict:
    """Row of the results table from ``runs`` (one payload per training run; one for a deterministic
    analytic controller).

    The training run is the statistical unit (:mod:`agents.stats`): a run's score is the mean of its
    per-episode values (cost ratio ``J / J_paper``, failed episodes at their penalty cost; likewise the
    transient cost and the errors); the row gives the IQM of the run scores with a 95 % percentile
    bootstrap CI over runs, the mean cost ratio with its CI (a failure cannot be trimmed away), the
    probability of improvement ``P(J < J_paper)`` over the matched (run, episode) pairs with its CI
    over runs, and the failure rate over every episode. ``cost_ratio_episode_iqm`` is the IQM over
    every (run, episode): the spread over episodes, reported for reference only."""
    cost = _matrix(runs, "cost")
    ratio = cost / paper_cost[None, :]
    row = {"policy": label, "kind": kind, "information": information, "runs": len(runs), "episodes": cost.shape[1],
           "env_steps": steps, "train_seconds_median": None}
    if steps is not None:
        row["train_seconds_median"] = float(np.median([r["train_seconds"] for r in runs]))
    ratio_scores = run_scores(ratio)
    for key, scores in (("cost_ratio", ratio_scores), ("transient_cost", run_scores(_matrix(runs, "transient_cost"))),
                        ("steady_state_error", run_scores(_matrix(runs, "steady_state_error"))),
                        ("final_tracking_error", run_scores(_matrix(runs, "final_tracking_error")))):
        est = interval_estimate(scores)
        row[f"{key}_iqm"], row[f"{key}_ci_low"], row[f"{key}_ci_high"] = est["iqm"], est["ci_low"], est["ci_high"]
    mean = mean_estimate(ratio_scores)
    row["cost_ratio_mean"], row["cost_ratio_mean_ci_low"], row["cost_ratio_mean_ci_high"] = \
        mean["mean"], mean["ci_low"], mean["ci_high"]
    poi = improvement_estimate(cost, paper_cost)
    row["poi"], row["poi_ci_low"], row["poi_ci_high"] = poi["poi"], poi["ci_low"], poi["ci_high"]
    row["cost_ratio_episode_iqm"] = float(iqm(ratio))
    row["failure_rate"] = float(np.mean(_matrix(runs, "failed")))
    row["run_scores"] = ratio_scores.tolist()
    flat = [e for r in runs for e in r["episodes"]]
    row.update(summarise_dicts(flat))
    return row


def summarise_dicts(episodes: list[dict]) -> dict:
    """Mean and std over episodes of the per-episode metrics (as :func:`agents.evaluate.summarise`)."""
    out = {}
    for key in ("return", "cost", "transient_cost", "steady_state_error", "final_tracking_error",
                "rms_estimation_error", "control_effort", "length"):
        a = np.array([e[key] for e in episodes], dtype=np.float64)
        out[f"{key}_mean"], out[f"{key}_std"] = float(a.mean()), float(a.std())
    return out


def aggregate_over_envs(per_env: dict) -> list[dict]:
    """Every policy present on all of ``per_env``'s environments with the same number of runs:
    IQM and mean of its run scores over the ``(runs, envs)`` matrix, with rliable's stratified
    bootstrap (runs resampled within each environment)."""
    envs = list(per_env)
    out = []
    if len(envs) < 2:
        return out
    for label in dict.fromkeys(r["policy"] for r in per_env[envs[0]]):
        rows = [next((r for r in per_env[e] if r["policy"] == label), None) for e in envs]
        if any(r is None for r in rows) or len({len(r["run_scores"]) for r in rows}) != 1:
            continue
        m = np.array([r["run_scores"] for r in rows]).T  # (runs, envs)
        est, mean = interval_estimate(m), mean_estimate(m)
        out.append({"policy": label, "kind": rows[0]["kind"], "envs": envs, "runs": m.shape[0],
                    "cost_ratio_iqm": est["iqm"], "cost_ratio_ci_low": est["ci_low"], "cost_ratio_ci_high": est["ci_high"],
                    "cost_ratio_mean": mean["mean"], "cost_ratio_mean_ci_low": mean["ci_low"],
                    "cost_ratio_mean_ci_high": mean["ci_high"]})
    return out


def _curve_stats(runs: list[dict]) -> dict | None:
    """IQM and CI over runs of the learning curves (a run's score at a point: the mean of its cost
    ratios over the curve episodes), at the points all runs share."""
    curves = [r.get("curve") or [] for r in runs]
    if not curves or not all(curves):
        return None
    n = min(len(c) for c in curves)
    steps, iq, lo, hi = [], [], [], []
    for i in range(n):
        est = interval_estimate(np.array([np.mean(c[i]["cost_ratio"]) for c in curves]), reps=5_000)
        steps.append(int(np.median([c[i]["env_steps"] for c in curves])))
        iq.append(est["iqm"]); lo.append(est["ci_low"]); hi.append(est["ci_high"])
    return {"env_steps": steps, "iqm": iq, "ci_low": lo, "ci_high": hi}


def _overlaps(rows: list[dict]) -> list[list[str]]:
    """Pairs of policies whose cost-ratio CIs overlap (a secondary remark; the paired comparison with
    the paper's controller is the probability of improvement)."""
    out = []
    for i, a in enumerate(rows):
        for b in rows[i + 1:]:
            if a["cost_ratio_ci_low"] <= b["cost_ratio_ci_high"] and b["cost_ratio_ci_low"] <= a["cost_ratio_ci_high"]:
                out.append([a["policy"], b["policy"]])
    return out


def _interval(r: dict, value: str, prefix: str, fmt: str = ".3g") -> str:
    """``r[value] [r[prefix_ci_low], r[prefix_ci_high]]``, or the value alone for a deterministic
    controller (one run: the interval is the point)."""
    m = f"{r[value]:{fmt}}"
    return m if r["runs"] == 1 else f"{m} [{r[f'{prefix}_ci_low']:{fmt}}, {r[f'{prefix}_ci_high']:{fmt}}]"


def _cells(r: dict) -> dict:
    """The table's cells of a row (shared by the text and the Markdown tables)."""
    n = r.get("env_steps")
    steps = "-" if n is None else (f"{n // 1000}k" if n >= 1000 and n % 1000 == 0 else str(n))
    secs = "-" if r.get("train_seconds_median") is None else f"{r['train_seconds_median']:.0f} s"
    return {"policy": r["policy"], "kind": r["kind"], "information": r["information"], "runs": str(r["runs"]),
            "steps": steps, "time": secs, "iqm": _interval(r, "cost_ratio_iqm", "cost_ratio"),
            "mean": _interval(r, "cost_ratio_mean", "cost_ratio_mean"), "poi": _interval(r, "poi", "poi", ".2f"),
            "transient": f"{r['transient_cost_iqm']:.4g}", "steady": f"{r['steady_state_error_iqm']:.3g}",
            "fail": f"{r['failure_rate']:.0%}"}


TABLE_COLUMNS = (("policy", "policy"), ("kind", "kind"), ("information", "information"), ("runs", "runs"),
                 ("steps", "env steps per run"), ("time", "train time per run (median)"),
                 ("iqm", "J / J_paper: IQM over runs [95% CI]"), ("mean", "mean J / J_paper [95% CI]"),
                 ("poi", "P(J < J_paper) [95% CI]"), ("transient", f"transient cost (first {TRANSIENT_S:g} s)"),
                 ("steady", f"steady-state error (RMS, last {STEADY_S:g} s)"), ("fail", "failures"))


def format_table(rows: list[dict]) -> str:
    """Text table of :data:`TABLE_COLUMNS`."""
    cells = [_cells(r) for r in rows]
    width = {k: max(len(h), *(len(c[k]) for c in cells)) for k, h in TABLE_COLUMNS}
    head = " | ".join(f"{h:{width[k]}s}" for k, h in TABLE_COLUMNS)
    lines = [head, "-" * len(head)]
    lines += [" | ".join(f"{c[k]:{width[k]}s}" for k, _ in TABLE_COLUMNS) for c in cells]
    return "\n".join(lines)


def format_markdown(rows: list[dict], overlaps: list[list[str]] | None = None, note: str | None = None) -> str:
    """The :data:`TABLE_COLUMNS` as a Markdown table (``results.md``), then the note on the paper's row
    (if any) and, as a secondary remark, the pairs of policies whose cost-ratio CIs overlap."""
    lines = ["| " + " | ".join(h for _, h in TABLE_COLUMNS) + " |", "|" + "---|" * len(TABLE_COLUMNS)]
    lines += ["| " + " | ".join(c[k] for k, _ in TABLE_COLUMNS) + " |" for c in map(_cells, rows)]
    if note:
        lines += ["", f"Note: {note}."]
    if overlaps is not None:
        lines += ["", "Overlapping 95% CIs of the IQM of J / J_paper: " +
                  ("; ".join(f"{a} / {b}" for a, b in overlaps) if overlaps else "none") + "."]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- figures
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plot_error_norms(payloads: dict, path: str, title: str, task_label: str) -> None:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for name, runs in payloads.items():
        # the mean over every (run, episode): runs of one benchmark have the same episodes, so the mean
        # of the runs' means (padded as the episodes are) is that mean
        t = max((np.asarray(r["t"]) for r in runs), key=len)
        axes[0].plot(t, _mean_trajectory([_run_means(r, "tracking_error") for r in runs]), lw=1.2, label=name)
        axes[1].plot(t, _mean_trajectory([_run_means(r, "estimation_error") for r in runs]), lw=1.2, label=name)
    axes[0].set_ylabel(f"mean {task_label} over episodes")
    axes[1].set_ylabel(r"mean RMS$_i$ $\|\hat x_i - x\|$ (env observers)")
    for ax in axes:
        ax.set_yscale("log")
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=6)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_curves(curves: dict, path: str, title: str) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4))
    for name, c in curves.items():
        if c is None:
            continue
        line, = ax.plot(c["env_steps"], c["iqm"], marker="o", ms=3, lw=1.3, label=name)
        ax.fill_between(c["env_steps"], c["ci_low"], c["ci_high"], color=line.get_color(), alpha=0.2)
    ax.axhline(1.0, color="k", lw=1, ls="--", label="paper controller")
    ax.set_yscale("log")
    ax.set_xlabel("environment steps")
    ax.set_ylabel(r"$J / J_{paper}$ (IQM, 95% CI over runs)")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


SUMMARY_XMAX = 10.0  # the summary figure's axis ends here; larger cost ratios are marked at the edge


def _plot_summary(per_env: dict, path: str, title: str) -> None:
    """Per env, every policy's IQM cost ratio and its 95 % CI on a log axis from below the best ratio
    to :data:`SUMMARY_XMAX`; a ratio beyond the axis is drawn as an arrow at its edge. Each row is
    labelled with its figures, so the CIs near 1 stay readable next to failures at 1e4."""
    plt = _plt()
    envs = list(per_env)
    from matplotlib.ticker import NullFormatter

    labels = list(dict.fromkeys(r["policy"] for rows in per_env.values() for r in rows))  # every env's, in order
    ypos = {label: len(labels) - 1 - k for k, label in enumerate(labels)}
    ncols = min(2, len(envs))  # four envs: a 2 x 2 grid
    nrows = -(-len(envs) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.6 * ncols + 3.0, (0.42 * len(labels) + 1.3) * nrows + 0.5),
                             squeeze=False, sharey=True)
    for ax in axes.flat[len(envs):]:
        ax.set_visible(False)
    x_lo = min(0.25, 0.8 * min(r["cost_ratio_ci_low"] for rows in per_env.values() for r in rows))
    for ax, env in zip(axes.flat, envs):
        for r in per_env[env]:
            yi = ypos[r["policy"]]
            color = {"RL": "tab:blue", "hybrid": "tab:green"}.get(r["kind"], "tab:gray")
            lo, hi, m = r["cost_ratio_ci_low"], r["cost_ratio_ci_high"], r["cost_ratio_iqm"]
            if lo < SUMMARY_XMAX:
                ax.plot([lo, min(hi, SUMMARY_XMAX)], [yi, yi], color=color, lw=6, alpha=0.45, solid_capstyle="butt")
            if m < SUMMARY_XMAX:
                ax.plot([m], [yi], "|", color="k", ms=12)
            else:
                ax.plot([SUMMARY_XMAX], [yi], ">", color=color, ms=7, clip_on=False)
            text = f"{m:.3g}" if lo == hi else f"{m:.3g} [{lo:.3g}, {hi:.3g}]"
            if r.get("failure_rate"):
                text += f", {100 * r['failure_rate']:.0f}% fail"
            ax.annotate(text, (1.0, yi), xycoords=("axes fraction", "data"), ha="left", va="center", fontsize=6.5,
                        xytext=(8, 0), textcoords="offset points", annotation_clip=False)
        ax.axvline(1.0, color="k", ls="--", lw=1)
        ax.set_yticks([ypos[label] for label in labels], labels, fontsize=7)
        ax.set_xscale("log")
        ax.set_xlim(x_lo, SUMMARY_XMAX)
        ax.set_ylim(-0.6, len(labels) - 0.4)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(r"$J / J_{paper}$ (IQM, 95% CI)")
        ax.set_title(env)
        ax.grid(alpha=0.3, axis="x")
    fig.suptitle(f"{title}\n(< 1: cheaper than the paper's controller; bars: 95% CI, whole training runs resampled; "
                 f"> {SUMMARY_XMAX:g}: arrow at the edge)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------- driver
def _plan(budget: str, agents: list[str] | None, timesteps: int | None, seeds: int | None) -> tuple[dict, int]:
    B = BUDGETS[budget]
    plan = dict(B["agents"])
    if agents is not None:
        unknown = sorted(set(agents) - set(AGENTS))
        if unknown:
            raise ValueError(f"unknown agents {unknown}; choose from {sorted(AGENTS)}")
        default = max(B["agents"].values())
        plan = {k: plan.get(k, default) for k in agents}
    if timesteps is not None:
        if timesteps < 1:
            raise ValueError(f"timesteps must be >= 1, got {timesteps}")
        plan = {k: int(timesteps) for k in plan}
    n_seeds = int(seeds if seeds is not None else B["seeds"])
    if n_seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    return plan, n_seeds


@dataclass(frozen=True)
class BenchmarkPlan:
    """What a benchmark invocation trains and evaluates (:func:`plan_runs`).

    ``specs`` holds one training run per (env, agent, training seed), longest first; a run's
    ``path`` is ``<out>/models/<env>/<budget>/<agent>/s<seed>``.
    """

    envs: list
    budget: str
    steps: dict
    training_seeds: list
    eval_seeds: list
    curve_seeds: list
    env_kwargs: dict
    specs: list


def plan_runs(env: str = "tracking", budget: str = "quick", out: str = "runs/benchmark", *, seed: int = 0,
              eval_seed: int = 10_000, episodes: int | None = None, timesteps: int | None = None,
              agents: list[str] | None = None, seeds: int | None = None, threads: int | None = 1) -> BenchmarkPlan:
    """The runs :func:`run_benchmark` would train with these arguments (it validates them; nothing is
    written). With :func:`pending_runs` it tells which of them a stored result already answers."""
    if budget not in BUDGETS:
        raise ValueError(f"unknown budget {budget!r}; choose from {sorted(BUDGETS)}")
    env_names = list(ENVS) if env == "all" else [env]
    for e in env_names:
        if e not in ENVS:
            raise ValueError(f"unknown env {e!r}; choose from {sorted(ENVS)} or 'all'")
    B = BUDGETS[budget]
    plan, n_seeds = _plan(budget, agents, timesteps, seeds)
    episodes = int(episodes or B["episodes"])
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    # the three seed ranges (agents/seeds.py): training seeds, evaluation episodes, tuning episodes
    check_training_seeds(seed, n_seeds, name="seed")
    eval_seeds = check_episode_seeds(eval_seed, episodes, EVALUATION, name="eval_seed")
    curve_seeds = check_episode_seeds(CURVE_SEED, B["curve_episodes"], TUNING, name="learning-curve seed")
    env_kwargs = dict(B["env_kwargs"])
    specs = []
    for e in env_names:
        for key, steps in plan.items():
            a = AGENTS[key]
            hp = dict(B["hyperparams"].get(a.algo, {}))
            for s in range(seed, seed + n_seeds):
                specs.append({"env": e, "agent": key, "seed": s, "steps": int(steps), "hp": hp,
                              "env_kwargs": env_kwargs, "eval_seeds": eval_seeds, "curve_seeds": curve_seeds,
                              "curve_every": max(1, int(steps) // B["curve_points"]), "threads": threads,
                              "path": os.path.join(out, "models", e, budget, key, f"s{s}")})
    # longest jobs first: better packing on the workers
    specs.sort(key=lambda sp: -sp["steps"] * (5 if AGENTS[sp["agent"]].multi_agent else 1))
    return BenchmarkPlan(env_names, budget, plan, list(range(seed, seed + n_seeds)), eval_seeds, curve_seeds,
                         env_kwargs, specs)


class RunConflictError(ValueError):
    """Training would replace finished runs of another configuration (``paths``; pass ``overwrite=True``)."""

    def __init__(self, out: str, paths: list[str]):
        self.out, self.paths = out, list(paths)
        super().__init__(f"{len(self.paths)} finished run(s) in {os.path.join(out, 'models')} were made with another "
                         f"configuration or recipe (first: {self.paths[0]}); training would replace them: pass "
                         f"overwrite=True or choose another out")


def replaced_runs(pending: list[dict]) -> list[dict]:
    """The specs among ``pending`` whose directory holds a finished result of another configuration
    or recipe: training them replaces that run."""
    return [sp for sp in pending if os.path.exists(os.path.join(sp["path"], "result.json"))]


def pending_runs(plan: BenchmarkPlan) -> list[dict]:
    """The specs of ``plan`` that would train: those without a finished result of the same signature
    and recipe (:func:`_finished_run`) and without a kept model trained as asked
    (:func:`reevaluated_runs`). ``[]`` means the benchmark trains nothing."""
    return [sp for sp in plan.specs if _stored_result(sp) is None and _stored_model(sp) is None]


def reevaluated_runs(plan: BenchmarkPlan) -> list[dict]:
    """The specs of ``plan`` whose kept model was trained as asked but evaluated on other episodes
    (another ``eval_seed`` or ``episodes``): the benchmark evaluates it again, without training."""
    return [sp for sp in plan.specs if _stored_model(sp) is not None]


# ---------------------------------------------------------------------- what an --out directory may hold
#: written into ``out`` by every benchmark run (before anything else): the directory is the benchmark's
MARKER = ".dobs-envs-benchmark"
#: files the benchmark writes at the top level of ``out`` and in ``out/<env>``
_TOP_FILES = ("summary.json", "summary.png")
_ENV_FILES = ("results.json", "results.md", "results.csv", "error_norms.png", "learning_curves.png")
#: files a training run (``agents.train``) and the benchmark write in a run directory
_RUN_FILES = ("config.json", "model.zip", "vecnormalize.pkl", "replay_buffer.pkl", "curve.json", "result.json")


class OutDirError(ValueError):
    """``out`` holds entries the benchmark did not write (``entries``, paths relative to ``out``), or is a file."""

    def __init__(self, out: str, entries: list[str], detail: str | None = None):
        self.out, self.entries = out, list(entries)
        shown = ", ".join(self.entries[:5]) + (f" and {len(self.entries) - 5} more" if len(self.entries) > 5 else "")
        super().__init__(detail or f"{out!r} holds {len(self.entries)} entr{'y' if len(self.entries) == 1 else 'ies'} "
                                   f"the benchmark did not write ({shown}); the benchmark would overwrite or delete "
                                   f"files there: pass --overwrite (overwrite=True) or choose another out")


def _run_dir_foreign(path: str, rel: str) -> list[str]:
    """Entries of a run directory ``<out>/models/<env>/<budget>/<agent>/s<seed>`` no run writes."""
    bad = []
    for f in sorted(os.listdir(path)):
        name = f[:-4] if f.endswith(".tmp") else f  # atomic writes leave <file>.tmp behind when killed
        if name == "checkpoints" and os.path.isdir(os.path.join(path, f)):
            continue
        if name not in _RUN_FILES or not os.path.isfile(os.path.join(path, f)):
            bad.append(f"{rel}/{f}")
    return bad


def _models_foreign(out: str) -> tuple[list[str], int]:
    """``(entries of out/models outside the layout models/<env>/<budget>/<agent>/s<seed>/<run files>, runs)``."""
    bad, runs = [], 0
    root = os.path.join(out, "models")
    levels = (set(ENVS), set(BUDGETS), set(AGENTS))
    def walk(path: str, rel: str, depth: int) -> None:  # noqa: E306
        nonlocal runs
        for f in sorted(os.listdir(path)):
            p, r = os.path.join(path, f), f"{rel}/{f}"
            if not os.path.isdir(p):
                bad.append(r)
            elif depth < 3:
                if f in levels[depth]:
                    walk(p, r, depth + 1)
                else:
                    bad.append(r)
            elif f.startswith("s") and f[1:].isdigit():
                runs += os.path.isfile(os.path.join(p, "config.json"))
                bad.extend(_run_dir_foreign(p, r))
            else:
                bad.append(r)
    walk(root, "models", 0)
    return bad, runs


def foreign_entries(out: str) -> list[str]:
    """The entries of ``out`` (paths relative to it) that the benchmark did not write; ``[]``: the
    benchmark may write there. ``out`` missing or empty: ``[]``.

    The rule. The benchmark writes ``out/{MARKER}`` first, then only the layout
    ``models/<env>/<budget>/<agent>/s<seed>/`` (run files: config.json, model.zip,
    vecnormalize.pkl, replay_buffer.pkl, curve.json, result.json, checkpoints/), ``<env>/results.{json,md,csv}``,
    ``<env>/error_norms.png``, ``<env>/learning_curves.png``, ``summary.json`` and ``summary.png``
    (``<env>``, ``<budget>``, ``<agent>``: the known names). An entry outside that layout is foreign.
    The output files (``summary.*``, ``<env>/*``) are the benchmark's only when the marker is there,
    or, in a directory of a benchmark older than the marker, when ``models/`` holds at least one run
    of the layout (with its ``config.json``); without either, they are the user's (foreign).
    """
    if not os.path.isdir(out):
        return []
    top = sorted(os.listdir(out))
    bad, runs = [], 0
    if "models" in top:
        if os.path.isdir(os.path.join(out, "models")):
            bad, runs = _models_foreign(out)
        else:
            bad.append("models")
    ours = MARKER in top or runs > 0
    for f in top:
        p = os.path.join(out, f)
        if f in (MARKER, "models"):
            continue
        if f in _TOP_FILES and os.path.isfile(p) and ours:
            continue
        if f in ENVS and os.path.isdir(p) and ours:
            bad.extend(f"{f}/{g}" for g in sorted(os.listdir(p))
                       if g not in _ENV_FILES or not os.path.isfile(os.path.join(p, g)))
            continue
        bad.append(f)
    return bad


def claim_out_dir(out: str, *, overwrite: bool = False) -> None:
    """Check ``out`` with :func:`foreign_entries` and write the marker: the benchmark's first write.

    Raises :class:`OutDirError` when ``out`` is a file, or holds foreign entries and not ``overwrite``
    (then nothing is written)."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise OutDirError(out, [], f"{out!r} is a file, not a directory")
    bad = foreign_entries(out)
    if bad and not overwrite:
        raise OutDirError(out, bad)
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, MARKER), "w") as fh:
        fh.write("written by `dobs-envs benchmark`: this directory holds its runs and results "
                 "(agents.benchmark.foreign_entries)\n")


def run_benchmark(env: str = "tracking", budget: str = "quick", out: str = "runs/benchmark", *, seed: int = 0,
                  eval_seed: int = 10_000, episodes: int | None = None, timesteps: int | None = None,
                  agents: list[str] | None = None, seeds: int | None = None, workers: int | None = None,
                  progress: bool = True, threads: int | None = 1, overwrite: bool = False) -> dict:
    """Run the benchmark (see module doc) on ``env`` (a name or ``"all"``); returns the summary document.

    Training seeds are ``seed, seed + 1, ...`` (``seeds`` of them, default the budget's);
    ``workers`` processes train in parallel (default: the number of CPU cores, at most 8).
    :func:`plan_runs` and :func:`pending_runs` tell beforehand what it would train.

    Raises
    ------
    RunConflictError
        if a run to train would replace a finished run of another configuration (other training
        steps, evaluation seeds or recipe) in its directory, unless ``overwrite`` (which removes
        those runs first).
    """
    t_start = time.perf_counter()
    P = plan_runs(env, budget, out, seed=seed, eval_seed=eval_seed, episodes=episodes, timesteps=timesteps,
                  agents=agents, seeds=seeds, threads=threads)
    claim_out_dir(out, overwrite=overwrite)  # refuses a directory holding files the benchmark did not write
    clash = replaced_runs(pending_runs(P))
    if clash and not overwrite:
        raise RunConflictError(out, [sp["path"] for sp in clash])
    for sp in clash:
        shutil.rmtree(sp["path"])
    env_names, plan, specs, env_kwargs = P.envs, P.steps, P.specs, P.env_kwargs
    episodes, eval_seeds, curve_seeds = len(P.eval_seeds), P.eval_seeds, P.curve_seeds
    n_seeds = len(P.training_seeds)
    os.makedirs(out, exist_ok=True)
    n_workers = int(workers or min(os.cpu_count() or 1, 8))
    results: dict[tuple, dict] = {}
    t_train = time.perf_counter()
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(specs), desc=f"train+evaluate ({n_workers} workers)", unit="run")
    if n_workers > 1 and len(specs) > 1:
        _compile_kernels(env_names, env_kwargs)
        ctx = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx, initializer=_ignore_sigint)
        try:
            futs = {pool.submit(_train_and_evaluate, sp): sp for sp in specs}
            analytic = {e: _analytic_results(e, env_kwargs, eval_seed, episodes) for e in env_names}
            for f in as_completed(futs):
                sp = futs[f]
                results[(sp["env"], sp["agent"], sp["seed"])] = f.result()
                if bar is not None:
                    bar.update(1)
        except BaseException:  # Ctrl-C (or a failed job): no worker outlives the benchmark
            _terminate_workers(pool)
            raise
        pool.shutdown()
    else:
        analytic = {e: _analytic_results(e, env_kwargs, eval_seed, episodes) for e in env_names}
        for sp in specs:
            results[(sp["env"], sp["agent"], sp["seed"])] = _train_and_evaluate(sp)
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    train_wall = time.perf_counter() - t_train

    per_env_rows, docs = {}, {}
    for e in env_names:
        edir = os.path.join(out, e)
        os.makedirs(edir, exist_ok=True)
        paper = analytic[e][PAPER]
        paper_cost = np.array([ep["cost"] for ep in paper["episodes"]])
        payloads, rows, curves, detail, train_s = {}, [], {}, {}, {}
        for key in plan:
            a = AGENTS[key]
            runs = [results[(e, key, s)] for s in range(seed, seed + n_seeds)]
            payloads[a.label] = runs
            rows.append(_aggregate(a.label, a.kind, runs, paper_cost, information=a.information, steps=plan[key]))
            curves[a.label] = _curve_stats(runs)
            detail[a.label] = {f"s{r['seed']}": r["episodes"] for r in runs}
            train_s[key] = [0.0 if r.get("cached") or r.get("reevaluated") else r["train_seconds"] for r in runs]
        for label in analytic[e]:
            payloads[label] = [analytic[e][label]]
            rows.append(_aggregate(label, "analytic", [analytic[e][label]], paper_cost,
                                   information=ANALYTIC_INFO[label]))
            detail[label] = {"deterministic": analytic[e][label]["episodes"]}
        table = format_table(rows)
        task_label = r"disagreement $\|p - \bar p 1\|$" if e == "hetero_mas" else r"task error $\|x - x_r\|$ or $\|x\|$"
        _plot_error_norms(payloads, os.path.join(edir, "error_norms.png"), f"{e}: {budget} budget", task_label)
        _plot_curves(curves, os.path.join(edir, "learning_curves.png"), f"{e}: learning curves ({budget})")
        doc = {
            "env": e, "budget": budget, "training_seeds": list(range(seed, seed + n_seeds)), "eval_seeds": eval_seeds,
            "curve_seeds": curve_seeds, "episodes": episodes, "env_kwargs": env_kwargs, "train_steps": plan,
            "train_seconds": train_s, "paper_cost": paper_cost.tolist(),
            "statistics": STATISTICS_DOC,
            "metrics_doc": {
                "cost_ratio": "J_policy / J_paper on the same episode; J = -return (LQ cost incl. termination penalty)",
                "transient_cost": f"cost incurred in the first {TRANSIENT_S:g} s",
                "steady_state_error": f"RMS of the task error over the last {STEADY_S:g} s",
                "failure_rate": "fraction of episodes terminated early (state bound exceeded / non-finite)",
                "poi": "probability of improvement P(J_policy < J_paper) over matched (run, episode) pairs",
                "cost_ratio_episode_iqm": "IQM over every (run, episode): the spread over episodes, for reference",
                "train_seconds_median": "median over runs of the training wall time when the run was trained",
            },
            "paper_note": PAPER_NOTES.get(e),
            "results": rows, "ci_overlaps": _overlaps(rows), "learning_curves": curves, "episodes_detail": detail,
            "table": table,
        }
        with open(os.path.join(edir, "results.json"), "w") as fh:
            json.dump(doc, fh, indent=1)
        cols = ["policy", "kind", "information", "runs", "episodes", "env_steps", "train_seconds_median"] + [
            f"{k}_{s}" for k in ("cost_ratio", "transient_cost", "steady_state_error", "final_tracking_error")
            for s in ("iqm", "ci_low", "ci_high")] \
            + ["cost_ratio_mean", "cost_ratio_mean_ci_low", "cost_ratio_mean_ci_high", "poi", "poi_ci_low",
               "poi_ci_high", "cost_ratio_episode_iqm", "failure_rate", "return_mean", "return_std",
               "control_effort_mean", "rms_estimation_error_mean"]
        with open(os.path.join(edir, "results.md"), "w") as fh:
            fh.write(format_markdown(rows, doc["ci_overlaps"], PAPER_NOTES.get(e)))
        with open(os.path.join(edir, "results.csv"), "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
            w.writeheader()
            for r in rows:
                w.writerow(r)
        per_env_rows[e], docs[e] = rows, doc
    _plot_summary(per_env_rows, os.path.join(out, "summary.png"), f"{budget} budget: cost relative to the paper's controller")
    summary = {"budget": budget, "envs": env_names, "training_seeds": list(range(seed, seed + n_seeds)),
               "eval_seeds": eval_seeds, "workers": n_workers,
               "timings_s": {"train_and_evaluate_wall": train_wall, "total": time.perf_counter() - t_start},
               "statistics": STATISTICS_DOC,
               "tables": {e: docs[e]["table"] for e in env_names},
               "results": {e: per_env_rows[e] for e in env_names},
               "aggregate_over_envs": aggregate_over_envs(per_env_rows)}
    with open(os.path.join(out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    return summary
