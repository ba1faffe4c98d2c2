"""Issue 22: a large network's design serially and on Ray, and wall-time projections to 32 and 128 cores.

Usage::

    python benchmarks/bench_design_ray.py [--part design|benchmark|all] [--nodes 1000] [--states 60]
        [--seed 0] [--no-one-cpu] [--results DIR | --base REF|PATH] [--json FILE]

``--part design``
    One seeded random network from the project's generator
    (:func:`dobs_envs.scenarios.random.random_plant_scenario` with ``n_states``, ``n_observers`` =
    ``--states``, ``--nodes`` and the ``random_network`` env's other defaults: 3 channels, each node
    knows 1-2, selection outputs), verified as the env's are (``verify=True``: the generator builds the
    design once, serially, and redraws from the same stream a candidate that fails, e.g. a node whose
    Lemma 2 is too ill-conditioned; seed 0 at N = 1000, n = 60 has such a node in its first draw).
    Generation time includes that first design. Designed with ``design_distributed_observer`` (the arguments
    ``Scenario.design`` passes) three ways, one after the other:

    1. ``backend="serial"``, per-node durations recorded by wrapping
       :func:`dobs_envs.design.node_tasks.node_design` (the serial path looks it up per call);
    2. ``backend="ray"`` on ``ray.init(num_cpus=2)`` (start-up timed separately), a first (cold:
       workers import the package) and a second (warm) call; per-task ``task:execute`` durations
       from ``ray.timeline()``;
    3. unless ``--no-one-cpu``: the same on ``ray.init(num_cpus=1)``, to calibrate the overhead on one
       worker and predict two (an out-of-sample check of the model).

    Every array of the Ray designs is compared with the serial one by ``np.array_equal`` (bitwise:
    both backends run ``node_design`` on the same arrays with single-threaded BLAS on one machine).
    Projection (``benchmarks/projection.py``): the serial run's per-node durations ``d_i``, its
    driver-side part ``S = T_serial - sum d_i`` (validation, ``B_{-i}``, Assumption 6, eq. barEFGB
    assembly) and a per-task overhead ``o`` fitted to a Ray wall time, list-scheduled in submission
    order on ``P`` workers; ``o`` either on the workers or serial in the driver (the two bracket it).

``--part benchmark``
    ``dobs-envs benchmark --env all --budget full`` projected from stored run records: the run list is
    :func:`agents.benchmark.plan.plan_runs` (its order is the submission order); each run's training time
    is, in this order of preference, (a) its own full-budget record (``train_seconds``) at the
    budget's steps, (b) the mean seconds per env step of the same (env, agent)'s records (other
    seeds, or another step count), times the budget's steps, (c) the same from a proxy agent of the same env
    (``ppo_sqrt`` <- ``ppo``, ``ppo_res_ma`` <- ``ppo_ma``: same algorithm and network layout), (d) for the
    off-policy agents (SAC, TD3, CrossQ at 600k steps) without a full-budget record on that env: the
    env's PPO seconds per step times the agent's / PPO's seconds per step on tracking, from their
    full-budget tracking records (the shipped recipes, trained by the same benchmark command, 2 workers
    on 2 cores); without tracking records, PPO's / the agent's env-steps per second measured side by
    side in ``results/offpolicy_throughput_tracking.json`` (SBX with the shipped recipe's copies and
    gradient steps, :func:`throughput_row`). (b)-(d) assume training time proportional to env steps,
    and (d) that the off-policy / PPO cost ratio carries over from tracking to the other envs. As the
    off-policy agents' cost is mostly their gradient updates, which do not depend on the env, a second
    table (the other bracket, "update-bound") takes (d)'s runs at their agent's own seconds per step on
    tracking.
    Evaluation and the analytic baselines are not in ``train_seconds`` and not projected.
    The records are read from ``--results DIR`` (default: this checkout's ``results/``) or from the
    ``results/`` of ``--base``: a directory, or a git ref of this repository checked out in a temporary
    ``git worktree`` for the run and removed afterwards (``benchmarks/checkouts.py``).

BLAS threads are pinned to one before numpy is imported (see ``bench_design.py``: on this loaded
2-core machine multi-threaded OpenBLAS made the design ~30x slower); Ray workers inherit the
environment. ``--json FILE`` writes every figure (refuses an existing file).
"""
from __future__ import annotations

import os

if __name__ == "__main__":  # before numpy is imported: env vars are read at load
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[_var] = "1"

import argparse  # noqa: E402
import contextlib  # noqa: E402
import dataclasses  # noqa: E402
import glob  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tarfile  # noqa: E402
import time  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import projection as proj  # noqa: E402
from checkouts import REPO, checkout  # noqa: E402

CORES = (2, 32, 128)
OFF_POLICY = ("sac", "td3", "crossq")
PROXY = {"ppo_sqrt": "ppo", "ppo_res_ma": "ppo_ma"}


def throughput_row(agent: str) -> str:
    """The row of ``offpolicy_throughput_tracking.json`` measured with ``agent``'s shipped tracking recipe:
    PPO's, or SBX with the recipe's environment copies and gradient steps per collect."""
    if agent == "ppo":
        return "ppo SB3 (recipe)"
    from agents.training.recipes import resolve_recipe

    r = resolve_recipe(agent, "tracking")
    g = r.algo_kwargs.get("gradient_steps", 1)
    return f"{agent} SBX 1 env" if r.n_envs == 1 else f"{agent} SBX {r.n_envs} env G={g}"


def _load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


def _stats(d) -> dict:
    d = sorted(d)
    q = statistics.quantiles(d, n=20) if len(d) > 1 else [d[0]] * 19
    return {"n": len(d), "sum": sum(d), "mean": statistics.fmean(d), "median": statistics.median(d),
            "p5": q[0], "p95": q[-1], "min": d[0], "max": d[-1]}


def _fmt_stats(s: dict, unit: float = 1e3, u: str = "ms") -> str:
    return (f"n={s['n']}, sum {s['sum']:.2f} s, mean {s['mean'] * unit:.2f} {u}, median {s['median'] * unit:.2f} {u}, "
            f"p5-p95 {s['p5'] * unit:.2f}-{s['p95'] * unit:.2f} {u}, max {s['max'] * unit:.2f} {u}")


# ---------------------------------------------------------------------- the design
def _design_arrays(design) -> dict:
    out = {}
    for f in dataclasses.fields(design):
        v = getattr(design, f.name)
        if hasattr(v, "shape"):
            out[f.name] = v
        elif isinstance(v, tuple) and v and all(hasattr(x, "shape") for x in v):
            for i, x in enumerate(v):
                out[f"{f.name}[{i}]"] = x
    return out


def _unequal(a, b) -> list[str]:
    import numpy as np

    A, B = _design_arrays(a), _design_arrays(b)
    if A.keys() != B.keys():
        return sorted(set(A) ^ set(B))
    return [k for k in A if not np.array_equal(A[k], B[k])]


def _ray_task_durations(ray, t_from: float, t_to: float) -> dict:
    """Per-task figures of the ``_ray_node_design`` tasks that ran between two ``time.time()`` stamps,
    from ``ray.timeline()``: ``execute`` (the function), ``task`` (with argument deserialisation and
    result storage), and the span from the first task start to the last task end."""
    time.sleep(1.0)  # task events reach the GCS in batches
    ev = ray.timeline()
    lo, hi = t_from * 1e6, t_to * 1e6
    tasks = [e for e in ev if str(e.get("name", "")).endswith("_ray_node_design") and lo <= e["ts"] <= hi]
    execs = [e for e in ev if e.get("name") == "task:execute" and lo <= e["ts"] <= hi]
    if not tasks:
        return {}
    start = min(e["ts"] for e in tasks)
    end = max(e["ts"] + e["dur"] for e in tasks)
    return {"execute": [e["dur"] * 1e-6 for e in execs], "task": [e["dur"] * 1e-6 for e in tasks],
            "span": (end - start) * 1e-6, "first_start_after_call": start * 1e-6 - t_from,
            "after_last_end": t_to - end * 1e-6}


def _ray_runs(num_cpus: int, args_kw, serial_design, calls: int = 2) -> dict:
    import ray

    from dobs_envs.design import design_distributed_observer

    t0 = time.perf_counter()
    ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False,
             object_store_memory=256 * 2**20)
    out = {"num_cpus": num_cpus, "init_seconds": time.perf_counter() - t0, "calls": []}
    try:
        for c in range(calls):
            w0 = time.time()
            t0 = time.perf_counter()
            d = design_distributed_observer(*args_kw[0], **args_kw[1], backend="ray")
            wall = time.perf_counter() - t0
            w1 = time.time()
            unequal = _unequal(serial_design, d)
            tl = _ray_task_durations(ray, w0, w1)
            rec = {"call": "cold" if c == 0 else "warm", "wall_seconds": wall, "equal_bitwise": not unequal,
                   "unequal_arrays": unequal[:10], "load_avg": _load()}
            if tl:
                rec.update(task_execute=_stats(tl["execute"]), task_total=_stats(tl["task"]), span=tl["span"],
                           driver_before_first_task=tl["first_start_after_call"],
                           driver_after_last_task=tl["after_last_end"])
            out["calls"].append(rec)
            print(f"  ray num_cpus={num_cpus} {rec['call']}: {wall:.2f} s, equal to serial bitwise: "
                  f"{rec['equal_bitwise']}, load {rec['load_avg']}", flush=True)
            if tl:
                print(f"    tasks (timeline, task:execute): {_fmt_stats(rec['task_execute'])}\n"
                      f"    first task start {tl['first_start_after_call']:.2f} s after the call, tasks span "
                      f"{tl['span']:.2f} s, driver after the last task {tl['after_last_end']:.2f} s", flush=True)
    finally:
        ray.shutdown()
    return out


def run_design(N: int, n: int, seed: int, one_cpu: bool) -> dict:
    import dobs_envs.design.node_tasks as node_tasks
    from dobs_envs.design import design_distributed_observer
    from dobs_envs.scenarios.random import random_plant_scenario

    print(f"== design: random_plant_scenario(n_states={n}, n_observers={N}, seed={seed}); "
          f"load {_load()}", flush=True)
    t0 = time.perf_counter()
    sc = random_plant_scenario(n_states=n, n_observers=N, seed=seed)
    gen = time.perf_counter() - t0
    args = (sc.A, sc.channels, sc.C, sc.known, sc.graph)
    kw = {"B_v": sc.B_v if sc.B_v.shape[1] else None}
    p_i = [c.shape[0] for c in sc.C]
    print(f"  generated and verified (draw {sc.metadata['attempt']}) in {gen:.2f} s: n={n}, N={N}, {len(sc.channels)} channels, p_i in [{min(p_i)}, {max(p_i)}], "
          f"{int(sc.graph.adjacency.sum() // 2)} O-O edges", flush=True)

    # warm-up (first calls load scipy's LAPACK wrappers and fill caches), not timed
    random_plant_scenario(n_states=min(n, 20), n_observers=min(N, 10), seed=seed + 1, verify=False).design  # noqa: B018
    durations = []
    orig = node_tasks.node_design

    def timed(*a):
        t = time.perf_counter()
        r = orig(*a)
        durations.append(time.perf_counter() - t)
        return r

    node_tasks.node_design = timed
    try:
        t0 = time.perf_counter()
        serial = design_distributed_observer(*args, **kw)
        t_serial = time.perf_counter() - t0
    finally:
        node_tasks.node_design = orig
    S = t_serial - sum(durations)
    delta = serial.delta
    out = {"network": {"generator": "dobs_envs.scenarios.random.random_plant_scenario", "n_states": n,
                       "n_observers": N, "seed": seed, "verify": True, "attempt": sc.metadata["attempt"],
                       "generation_seconds": gen,
                       "n_channels": len(sc.channels), "p_i_range": [min(p_i), max(p_i)],
                       "delta_range": [int(delta.min()), int(delta.max())], "delta_mean": float(delta.mean())},
           "serial": {"wall_seconds": t_serial, "node_durations": _stats(durations), "driver_serial_part": S,
                      "load_avg": _load(), "node_durations_seconds": list(durations)}}
    print(f"  serial: {t_serial:.2f} s (delta_i in [{delta.min()}, {delta.max()}], mean {delta.mean():.2f}); "
          f"per node {_fmt_stats(out['serial']['node_durations'])}; driver-side part S = {S:.2f} s; "
          f"load {out['serial']['load_avg']}", flush=True)

    out["ray2"] = _ray_runs(2, (args, kw), serial)
    print(f"  ray start-up (num_cpus=2): {out['ray2']['init_seconds']:.2f} s (not in the wall times)", flush=True)
    if one_cpu:
        out["ray1"] = _ray_runs(1, (args, kw), serial)
        print(f"  ray start-up (num_cpus=1): {out['ray1']['init_seconds']:.2f} s", flush=True)

    # ---- projection
    warm2 = out["ray2"]["calls"][-1]["wall_seconds"]
    model = {"durations": "serial run's per-node durations", "serial_part": S, "order": "submission",
             "calibrated_on": "ray num_cpus=2, warm call", "overhead": {}, "table": {}}
    for m in proj.OVERHEAD_MODELS:
        o = proj.calibrate_overhead(durations, 2, warm2, serial=S, model=m)
        fit = proj.design_wall_time(durations, 2, serial=S, overhead=o, model=m)
        model["overhead"][m] = {"seconds_per_task": o, "fit_at_2": fit}
        model["table"][m] = {P: proj.design_wall_time(durations, P, serial=S, overhead=o, model=m) for P in CORES}
    model["no_overhead"] = {P: proj.design_wall_time(durations, P, serial=S) for P in CORES}
    model["lower_bound"] = {P: S + proj.lower_bound(durations, P) for P in CORES}
    if one_cpu:
        warm1 = out["ray1"]["calls"][-1]["wall_seconds"]
        val = {"measured_ray_1cpu": warm1, "measured_ray_2cpu": warm2, "predicted_2cpu": {}}
        for m in proj.OVERHEAD_MODELS:
            o1 = proj.calibrate_overhead(durations, 1, warm1, serial=S, model=m)
            pred = proj.design_wall_time(durations, 2, serial=S, overhead=o1, model=m)
            val["predicted_2cpu"][m] = {"overhead_1cpu": o1, "predicted": pred, "ratio_to_measured": pred / warm2}
            model["table"][f"{m}, o from 1 CPU"] = {P: proj.design_wall_time(durations, P, serial=S, overhead=o1,
                                                                             model=m) for P in CORES}
        model["validation"] = val
    cold = out["ray2"]["calls"][0]["wall_seconds"]
    model["repeat_check"] = {"cold": cold, "warm": warm2}
    out["projection"] = model

    print(f"\n  projection of the design (S = {S:.2f} s serial in the driver, {N} tasks, sum {sum(durations):.2f} s, "
          f"longest {max(durations) * 1e3:.1f} ms; overhead fitted to the warm 2-CPU Ray call {warm2:.2f} s):")
    print(f"  {'cores':>6} {'no overhead':>12} {'o on workers':>13} {'o in driver':>12} {'lower bound':>12}")
    for P in CORES:
        print(f"  {P:6d} {model['no_overhead'][P]:12.2f} {model['table']['worker'][P]:13.2f} "
              f"{model['table']['driver'][P]:12.2f} {model['lower_bound'][P]:12.2f}")
    print(f"  overhead per task: on workers {model['overhead']['worker']['seconds_per_task'] * 1e3:.2f} ms, "
          f"in the driver {model['overhead']['driver']['seconds_per_task'] * 1e3:.2f} ms; serial design "
          f"{t_serial:.2f} s; speed-up of the 2-CPU Ray call over serial {t_serial / warm2:.2f}x")
    if one_cpu:
        t1 = model["table"]["worker, o from 1 CPU"]
        print("  with the overhead fitted to the warm 1-CPU call instead (on workers): "
              + ", ".join(f"{P} cores {t1[P]:.2f} s" for P in CORES))
        for m, v in model["validation"]["predicted_2cpu"].items():
            print(f"  validation ({m} model): calibrated on 1 CPU ({model['validation']['measured_ray_1cpu']:.2f} s, "
                  f"o = {v['overhead_1cpu'] * 1e3:.2f} ms), predicts {v['predicted']:.2f} s on 2 CPUs; "
                  f"measured {warm2:.2f} s (ratio {v['ratio_to_measured']:.2f})")
    return out


# ---------------------------------------------------------------------- the four-environment benchmark
def _records(results_dir: str) -> dict:
    """``{(env, budget, agent): [(seed, steps, train_seconds, archive)]}`` from every ``*.tar.gz`` in
    ``results_dir`` (read in memory, never extracted)."""
    recs: dict = {}
    for path in sorted(glob.glob(os.path.join(results_dir, "*.tar.gz"))):
        with tarfile.open(path) as tf:
            for m in tf.getmembers():
                parts = m.name.split("/")
                if len(parts) != 6 or parts[0] != "models" or parts[-1] != "result.json":
                    continue
                r = json.load(tf.extractfile(m))
                ts = r.get("train_seconds")
                if not isinstance(ts, (int, float)):
                    continue
                key = (parts[1], parts[2], parts[3])
                recs.setdefault(key, []).append((int(r["seed"]), int(r["signature"]["steps"]), float(ts),
                                                 os.path.basename(path)))
    return recs


def _per_step(recs: dict, env: str, agent: str):
    """Mean seconds per env step over (env, agent)'s full-budget records if any, else over its records
    of the other budgets; and where they come from."""
    rows = [(b, r) for (e, b, a), rs in recs.items() if e == env and a == agent for r in rs]
    if any(b == "full" for b, _ in rows):
        rows = [(b, r) for b, r in rows if b == "full"]
    if not rows:
        return None, None
    groups = sorted({(b, steps, arc) for b, (_, steps, _, arc) in rows})
    where = "; ".join(f"{sum(1 for b2, r in rows if (b2, r[1], r[3]) == g)} {g[0]} at {g[1]} steps in {g[2]}"
                      for g in groups)
    return statistics.fmean(ts / steps for _, (_, steps, ts, _) in rows), f"{agent}: {where}"


def run_benchmark_projection(results_dir: str) -> dict:
    from agents.benchmark.plan import BUDGETS, plan_runs

    print(f"\n== full four-environment benchmark, projected from the records in {results_dir}; load {_load()}",
          flush=True)
    plan = plan_runs(env="all", budget="full", out="/nonexistent/projection-only")
    recs = _records(results_dir)
    with open(os.path.join(results_dir, "offpolicy_throughput_tracking.json")) as fh:
        thr = json.load(fh)["throughput"]
    ratios = {}  # agent -> (its seconds per env step / PPO's, where that comes from)
    own = {}  # agent -> its own seconds per env step on tracking (the update-bound bracket)
    ppo_tracking, ppo_src = _per_step(recs, "tracking", "ppo")
    for agent in OFF_POLICY:
        if recs.get(("tracking", "full", agent)):
            ps, src = _per_step(recs, "tracking", agent)
            own[agent] = ps
            ratios[agent] = (ps / ppo_tracking, f"tracking full-budget records ({src}; {ppo_src})")
            continue
        rows = {a: throughput_row(a) for a in ("ppo", agent)}
        missing = [row for row in rows.values() if row not in thr]
        if missing:
            raise SystemExit(f"{agent} has no full-budget tracking record in {results_dir} and "
                             f"offpolicy_throughput_tracking.json has no row {missing[0]!r} (its shipped recipe): "
                             f"measure it with benchmarks/offpolicy_throughput.py or train its tracking runs")
        sps = {a: float(thr[row]["steps_per_s"]) for a, row in rows.items()}
        ratios[agent] = (sps["ppo"] / sps[agent], f"side-by-side throughput on tracking ({rows[agent]!r}, "
                                                  f"offpolicy_throughput_tracking.json)")
    runs, sources = [], {}
    upper = {}  # run index -> the update-bound estimate of an off-policy run (its tracking s/step x steps)
    for sp in plan.specs:
        env, agent, seed, steps = sp["env"], sp["agent"], sp["seed"], sp["steps"]
        full = {s: (st, ts) for s, st, ts, _ in recs.get((env, "full", agent), [])}
        if seed in full and full[seed][0] == steps:
            t, how = full[seed][1], "measured (full-budget record)"
        elif agent in OFF_POLICY and not recs.get((env, "full", agent)):  # else: scaled from its own runs
            ps, src = _per_step(recs, env, "ppo")
            t = ps * steps * ratios[agent][0]
            how = f"PPO's s/step on {env} ({src}) x {agent}/PPO cost ratio {ratios[agent][0]:.1f} ({ratios[agent][1]})"
            if agent in own:  # the other bracket: the updates cost the same on every env
                upper[len(runs)] = own[agent] * steps
        else:
            ps, src = _per_step(recs, env, agent)
            how = f"scaled by env steps from {src}"
            if ps is None and agent in PROXY:
                ps, src = _per_step(recs, env, PROXY[agent])
                how = f"proxy {PROXY[agent]}, scaled by env steps from {src}"
            if ps is None:
                raise SystemExit(f"no record for {env}/{agent} or its proxy in {results_dir}")
            t = ps * steps
        runs.append({"env": env, "agent": agent, "seed": seed, "steps": steps, "train_seconds": t, "source": how})
        sources.setdefault((env, agent), (how, []))[1].append(t)

    print(f"  {len(runs)} runs (plan_runs('all', 'full'): {len(plan.envs)} envs x {len(plan.steps)} agents x "
          f"{len(plan.training_seeds)} seeds); per (env, agent) mean training time and its source:")
    for (env, agent), (how, ts) in sources.items():
        print(f"    {env:22s} {agent:11s} {statistics.fmean(ts):8.0f} s  {how}")
    dur = [r["train_seconds"] for r in runs]
    groups = {"all runs": dur,
              "all runs, off-policy estimates update-bound": [upper.get(i, t) for i, t in enumerate(dur)],
              "without the off-policy estimates": [r["train_seconds"] for r in runs if r["agent"] not in OFF_POLICY]}
    if upper:
        print(f"  update-bound bracket: {len(upper)} off-policy runs estimated instead at their agent's own s/step on "
              f"tracking (the gradient updates, not the env, set their cost): mean "
              f"{statistics.fmean(upper.values()):.0f} s against {statistics.fmean(dur[i] for i in upper):.0f} s")
    table = {}
    for label, d in groups.items():
        table[label] = {}
        print(f"\n  {label}: {len(d)} runs, total {sum(d) / 3600:.1f} process-hours, longest {max(d) / 3600:.2f} h")
        print(f"  {'cores':>6} {'submission order':>17} {'LPT':>8} {'lower bound':>12}   (hours)")
        for P in CORES:
            sub = proj.list_schedule(d, P, "submission")[0]
            lpt = proj.list_schedule(d, P, "lpt")[0]
            lb = proj.lower_bound(d, P)
            table[label][P] = {"submission": sub, "lpt": lpt, "lower_bound": lb}
            print(f"  {P:6d} {sub / 3600:17.2f} {lpt / 3600:8.2f} {lb / 3600:12.2f}")
    # cross-check of the two brackets on every other env with full-budget off-policy records: the agent's
    # cost ratio to PPO there (the first bracket's rule) and its own s/step there against tracking's (the second's)
    check = {}
    for (env, budget, agent), rs in sorted(recs.items()):
        if budget != "full" or agent not in own or env == "tracking" or not rs:
            continue
        rec_ps, _ = _per_step(recs, env, agent)
        ppo_ps, _ = _per_step(recs, env, "ppo")
        check[f"{env}/{agent}"] = {"records": len(rs), "steps": sorted({st for _, st, _, _ in rs}),
                                   "seconds_per_step": rec_ps, "ratio_to_ppo": rec_ps / ppo_ps,
                                   "ratio_to_ppo_tracking": ratios[agent][0],
                                   "seconds_per_step_tracking": own[agent]}
        print(f"  cross-check {env}/{agent} ({len(rs)} full-budget runs): {rec_ps / ppo_ps:.1f}x PPO's s/step there "
              f"(on tracking {ratios[agent][0]:.1f}x); its s/step {rec_ps * 1e3:.2f} ms against "
              f"{own[agent] * 1e3:.2f} ms on tracking")
    for i, t in upper.items():
        runs[i]["train_seconds_update_bound"] = t
    return {"runs": runs, "table": table, "offpolicy_cost_ratio_to_ppo": ratios, "offpolicy_crosscheck": check,
            "budget": {k: BUDGETS["full"][k] for k in ("agents", "seeds")},
            "records": {"/".join(k): len(v) for k, v in sorted(recs.items())}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--part", choices=("design", "benchmark", "all"), default="all")
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--states", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-one-cpu", action="store_true", help="skip the 1-CPU Ray run (the out-of-sample check)")
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--results", default=os.path.join(REPO, "results"),
                     help="directory of the stored run archives (default: this checkout's results/)")
    src.add_argument("--base", metavar="REF|PATH",
                     help="read the run archives from the results/ of this checkout: a directory, or a git ref "
                          "checked out in a temporary git worktree for the run")
    ap.add_argument("--json", help="write every figure here (refuses an existing file)")
    args = ap.parse_args(argv)
    if args.json and os.path.exists(args.json):
        ap.error(f"--json {args.json} exists; choose another file")
    out = {"argv": sys.argv[1:] if argv is None else list(argv), "load_avg_start": _load(),
           "cpu_count": os.cpu_count(), "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS")}
    if args.part in ("design", "all"):
        out["design"] = run_design(args.nodes, args.states, args.seed, not args.no_one_cpu)
    if args.part in ("benchmark", "all"):
        with contextlib.ExitStack() as stack:
            results = args.results
            if args.base is not None:
                try:
                    results = os.path.join(stack.enter_context(checkout(args.base)), "results")
                except ValueError as exc:
                    ap.error(str(exc))
            out["benchmark"] = run_benchmark_projection(results)
    out["load_avg_end"] = _load()
    print(f"\nload average (1, 5, 15 min): start {out['load_avg_start']}, end {out['load_avg_end']} on "
          f"{os.cpu_count()} cores")
    if args.json:
        with open(args.json, "x") as fh:
            json.dump(out, fh, indent=1, default=str)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
