"""Issue 40's first target: a 600k-step jitted PPO run on tracking beside SB3 PPO's, one core each
(``--algo sac`` / ``td3``: the jitted SAC / TD3 beside SBX's, the project's off-policy rows).

Both train PPO with their shipped tracking recipe (``agents/config/hyperparams/ppo.yaml``, read through
``agents.training.recipes.resolve_recipe``; the jitted trainer's with the file's ``-jax`` sections, its own tuned
recipe where the file has one, ``trainer="jax"``): the jitted trainer (``agents.training.jax``, one compiled function
on ``dobs_envs.jax``, float32) in this process, then SB3 PPO through the project's SB3 training entry
(``agents.training.train.train``, what ``dobs-envs train --algo ppo --env tracking`` calls, torch on one thread)
in a child process of this script. One core each: XLA on one thread (``PJRT_NPROC=1``,
``--xla_cpu_multi_thread_eigen=false``, set before JAX is imported), torch ``set_num_threads(1)``; the
runs are sequential.

Figures: CPU seconds (``time.process_time`` for this process; the child's user + system time from
``resource.getrusage(RUSAGE_CHILDREN)``, its imports and env construction included) and wall seconds.
The jitted run's set-up (the environment's construction), compilation and run are given apart. The
ratio of the target is the jitted run's CPU time over SB3's (with and without its compilation).
Learning curves at equal steps: both record the raw (un-normalised) return of every training episode
(SB3: its ``Monitor`` infos; JAX: the trainer's curve), binned by rollout (``n_envs n_steps`` steps; SAC: a
collect of ``n_envs train_freq`` steps).

    PYTHONPATH=. python benchmarks/bench_jax_train.py [--algo ppo|sac|td3] [--steps 600000] [--seed 0] [--out x.json]

``--algo sac`` (``td3``) trains the shipped recipe (``agents/config/hyperparams/sac.yaml``, ``td3.yaml``) with
the jitted trainer (``agents.training.jax.sac``, ``.td3``) and, in the child, through the same SB3 entry, which
uses SBX when the ``jax`` extra is installed (``agents.training.algos``; the record's ``sb3.library``); SBX's XLA
runs on one thread too (the child inherits ``PJRT_NPROC`` / ``XLA_FLAGS``; ``train(threads=1)``).

``--steps 16384`` is a smoke test (a few minutes with compilation). The JSON record is written only with
``--out`` (an existing file is kept unless ``--overwrite``). Measured on a machine shared with other
work: the load averages before and after each phase are in the record.
"""
from __future__ import annotations

import os

os.environ.setdefault("PJRT_NPROC", "1")
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

import argparse  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

ENV, ENV_ID = "tracking", "dobs_envs/Tracking-v0"
TAIL_ROLLOUTS = 10  # "final" return: the mean over the episodes that ended in the last 10 rollouts (PPO) or in
#                     the last tenth of the collects (SAC, TD3: collects of 32 or 8 steps hold few episode ends)


def _load() -> list:
    return [round(x, 2) for x in os.getloadavg()]


def sb3_worker(steps: int, seed: int, out_json: str, run_dir: str, algo: str = "ppo") -> None:
    """Child process: SB3 PPO (SBX SAC) through agents.training.train.train, recording every training episode's
    return."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from agents.training.train import train

    torch.set_num_threads(1)
    episodes = []

    class Episodes(BaseCallback):
        def _on_step(self) -> bool:
            for info in self.locals["infos"]:
                if "episode" in info:
                    episodes.append((int(self.num_timesteps), float(info["episode"]["r"]), int(info["episode"]["l"])))
            return True

    res = train(ENV, algo, timesteps=steps, seed=seed, out=run_dir, progress=False, threads=1,
                callbacks=[Episodes()])
    record = {"train_seconds": res.seconds, "timesteps_done": res.config["timesteps_done"],
              "episodes": episodes, "library": res.config.get("library"),
              "library_version": res.config.get("library_version"), "recipe": res.config.get("hyperparams")}
    with open(out_json, "w") as fh:
        json.dump(record, fh)


def run_jax(steps: int, seed: int, policy_dir: str, n_seeds: int = 1, algo: str = "ppo") -> dict:
    """The jitted PPO (SAC) run (``n_seeds > 1``: that many runs vmapped in one compiled call, keys
    ``split(PRNGKey(seed), n_seeds)``): set-up, compile and run timed apart; the first run's curve and
    policy (exported to ``policy_dir``)."""
    t0, w0 = time.process_time(), time.perf_counter()
    import jax

    from agents.training.recipes import resolve_recipe
    from agents.training.jax.export import save_policy
    if algo == "sac":
        from agents.training.jax.sac import make_env, make_train, sac_config as read_config
    elif algo == "td3":
        from agents.training.jax.td3 import make_env, make_train, td3_config as read_config
    else:
        from agents.training.jax.ppo import make_env, make_train, ppo_config as read_config

    recipe = dict(resolve_recipe(algo, ENV, trainer="jax").hyperparams)
    cfg, hp = read_config(recipe, ENV_ID, total_timesteps=steps)
    env, env_params = make_env(cfg)
    train = make_train(cfg, env, env_params)
    key = jax.random.PRNGKey(seed)
    if n_seeds > 1:
        train, key = jax.vmap(train, in_axes=(0, None)), jax.random.split(key, n_seeds)
    train = jax.jit(train)
    setup = (time.process_time() - t0, time.perf_counter() - w0)
    t0, w0 = time.process_time(), time.perf_counter()
    compiled = train.lower(key, hp).compile()
    comp = (time.process_time() - t0, time.perf_counter() - w0)
    t0, w0 = time.process_time(), time.perf_counter()
    out = jax.block_until_ready(compiled(key, hp))
    run = (time.process_time() - t0, time.perf_counter() - w0)
    out = jax.device_get(out)
    if n_seeds > 1:
        out = jax.tree.map(lambda a: a[0], out)
    c = out["curve"]
    save_policy(policy_dir, out, cfg, hp, env, env_params, extra={"seed": seed, "steps": steps, "n_seeds": n_seeds})
    return {"setup_cpu": setup[0], "setup_wall": setup[1], "compile_cpu": comp[0], "compile_wall": comp[1],
            "run_cpu": run[0], "run_wall": run[1], "n_seeds": n_seeds, "run_cpu_per_run": run[0] / n_seeds, "steps_done": cfg.steps_done,
            "rollout": cfg.n_envs * cfg.n_steps if algo == "ppo" else cfg.rollout,
            "curve": {"steps": c["steps"].tolist(), "episodes": c["episodes"].tolist(),
                      "return_sum": np.nan_to_num(c["episode_return"] * c["episodes"]).tolist()},
            "jax_version": jax.__version__, "dtype": cfg.dtype, "recipe": recipe}


def run_sb3(steps: int, seed: int, run_dir: str, algo: str = "ppo") -> dict:
    """SB3 PPO in a child process (this script with --sb3-worker; the run saved in ``run_dir``): its CPU
    and wall time and episodes."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "sb3.json")
        env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        w0 = time.perf_counter()
        subprocess.run([sys.executable, os.path.abspath(__file__), "--sb3-worker", path, run_dir, "--steps",
                        str(steps), "--seed", str(seed), "--algo", algo], check=True, env=env)
        wall = time.perf_counter() - w0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        with open(path) as fh:
            rec = json.load(fh)
    rec["cpu"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    rec["wall"] = wall
    return rec


def evaluate(policy_dir: str, run_dir: str | None, episodes: int) -> dict:
    """J / J_paper of both trained policies on the benchmark's evaluation episodes (seeds 10000..), with
    the existing harness: :func:`agents.evaluate.evaluate_policy` on the task's own environment
    (``agents.config.envs.gym_factory``, as ``dobs-envs evaluate``: no training-only options), the SB3 agent
    through ``agents.training.loading.load_agent(...).policy_for`` (``evaluate_model``'s path), and the paper
    controller's costs on the same seeds (:func:`agents.training.curves.paper_costs`). A run's score is the mean of
    its per-episode ratios (the benchmark's)."""
    from agents.config.envs import gym_factory
    from agents.training.curves import paper_costs
    from agents.evaluate import evaluate_policy
    from agents.training.loading import load_agent
    from agents.training.seeds import EVALUATION
    from agents.training.jax.numpy_policy import NumpyPolicy

    first = EVALUATION.start
    j_paper = paper_costs(ENV, {}, range(first, first + episodes))
    out = {"seeds": [first, first + episodes - 1], "J_paper": j_paper.tolist()}
    policies = {"jax": lambda env: NumpyPolicy(policy_dir)}
    if run_dir is not None:
        policies["sb3"] = lambda env: load_agent(run_dir).policy_for(env)
    for name, make in policies.items():
        env = gym_factory(ENV, {})()
        costs = np.array([r.cost for r in evaluate_policy(env, make(env), episodes, first, parallel=False)])
        env.close()
        out[f"J_{name}"] = costs.tolist()
        out[f"{name}_J_over_J_paper"] = float(np.mean(costs / j_paper))
    return out


def binned(episodes: list, rollout: int, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """``(count, return sum)`` per rollout bin of ``(step, return, length)`` episodes (step: after it ended)."""
    count, total = np.zeros(n_bins, int), np.zeros(n_bins)
    for step, ret, _ in episodes:
        b = min((step - 1) // rollout, n_bins - 1)
        count[b] += 1
        total[b] += ret
    return count, total


#: the stored curves keep at most this many bins (SAC / TD3 collect every 32 / 8 steps: consecutive collects merged)
MAX_STORED_BINS = 200


def coarsen(record: dict) -> dict:
    """``record`` with its per-rollout curves (``jax.curve``, ``sb3_curve``) merged into at most
    :data:`MAX_STORED_BINS` bins of consecutive rollouts (episode counts and return sums added, ``steps`` the
    last of each bin; ``curve_bin_rollouts`` records the factor): the file stays small for off-policy runs."""
    curve = record["jax"]["curve"]
    n = len(curve["steps"])
    k = -(-n // MAX_STORED_BINS)
    record["curve_bin_rollouts"] = k
    if k == 1:
        return record

    def add(xs):
        return [float(sum(xs[i:i + k])) for i in range(0, n, k)]

    record["jax"]["curve"] = {"steps": [curve["steps"][min(i + k, n) - 1] for i in range(0, n, k)],
                              "episodes": [int(x) for x in add(curve["episodes"])],
                              "return_sum": add(curve["return_sum"])}
    if "sb3_curve" in record:
        record["sb3_curve"] = {"episodes": [int(x) for x in add(record["sb3_curve"]["episodes"])],
                               "return_sum": add(record["sb3_curve"]["return_sum"])}
    return record


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--algo", choices=("ppo", "sac", "td3"), default="ppo",
                    help="ppo (default): jitted PPO vs SB3 PPO; sac, td3: jitted vs SBX (shipped recipes)")
    ap.add_argument("--steps", type=int, default=600_000, help="env steps of each run (default 600000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="write the JSON record here (e.g. results/bench_jax_train.json)")
    ap.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    ap.add_argument("--skip-sb3", action="store_true", help="time the jitted run only")
    ap.add_argument("--jax-seeds", type=int, default=1,
                    help="jitted runs vmapped in one call (their CPU time is shared; default 1)")
    ap.add_argument("--eval-episodes", type=int, default=20,
                    help="evaluation episodes (seeds 10000..) for J/J_paper of both policies; 0: none")
    ap.add_argument("--sb3-worker", nargs=2, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.steps < 1:
        ap.error(f"--steps must be a positive integer, got {args.steps}")
    if args.jax_seeds < 1:
        ap.error(f"--jax-seeds must be a positive integer, got {args.jax_seeds}")
    if args.eval_episodes < 0:
        ap.error(f"--eval-episodes must be >= 0, got {args.eval_episodes}")
    if args.sb3_worker:
        sb3_worker(args.steps, args.seed, *args.sb3_worker, algo=args.algo)
        return 0
    if args.out and os.path.exists(args.out) and not args.overwrite:
        ap.error(f"--out {args.out} exists; pass --overwrite to replace it")

    work = tempfile.TemporaryDirectory()
    policy_dir, run_dir = os.path.join(work.name, "jax_policy"), os.path.join(work.name, "sb3_run")
    record = {"algo": args.algo, "steps": args.steps, "seed": args.seed, "env": ENV_ID, "cpu_count": os.cpu_count(),
              "PJRT_NPROC": os.environ.get("PJRT_NPROC"), "XLA_FLAGS": os.environ.get("XLA_FLAGS"),
              "load_before_jax": _load()}
    jx = run_jax(args.steps, args.seed, policy_dir, args.jax_seeds, args.algo)
    name = args.algo.upper()
    record["load_after_jax"] = _load()
    record["jax"] = jx
    print(f"jitted {name}, {args.jax_seeds} x {jx['steps_done']} steps: set-up {jx['setup_cpu']:.1f} s CPU, compile {jx['compile_cpu']:.1f} s "
          f"CPU ({jx['compile_wall']:.1f} s wall), run {jx['run_cpu']:.1f} s CPU ({jx['run_wall']:.1f} s wall; "
          f"{jx['run_cpu_per_run']:.1f} s CPU per run)")
    n_bins, rollout = len(jx["curve"]["steps"]), jx["rollout"]
    j_count, j_sum = np.asarray(jx["curve"]["episodes"]), np.asarray(jx["curve"]["return_sum"])
    n_tail = TAIL_ROLLOUTS if args.algo == "ppo" else max(1, n_bins // 10)
    tail = slice(max(0, n_bins - n_tail), n_bins)
    record["tail_bins"] = n_tail

    def mean_return(count, total):  # NaN when no episode ended there
        return float(total.sum() / count.sum()) if count.sum() else float("nan")

    record["jax_final_return"] = mean_return(j_count[tail], j_sum[tail])
    if not args.skip_sb3:
        record["load_before_sb3"] = _load()
        sb = run_sb3(args.steps, args.seed, run_dir, args.algo)
        record["load_after_sb3"] = _load()
        s_count, s_sum = binned(sb.pop("episodes"), rollout, n_bins)
        record["sb3"] = sb
        record["sb3_curve"] = {"episodes": s_count.tolist(), "return_sum": s_sum.tolist()}
        record["sb3_final_return"] = mean_return(s_count[tail], s_sum[tail])
        record["ratio_run_cpu"] = jx["run_cpu"] / sb["cpu"]
        record["ratio_run_cpu_per_run"] = jx["run_cpu_per_run"] / sb["cpu"]
        record["ratio_compile_and_run_cpu"] = (jx["compile_cpu"] + jx["run_cpu"]) / sb["cpu"]
        record["ratio_run_wall"] = jx["run_wall"] / sb["wall"]
        print(f"{sb.get('library')} {name}, {sb['timesteps_done']} steps: {sb['cpu']:.1f} s CPU, {sb['wall']:.1f} s wall "
              f"(learn {sb['train_seconds']:.1f} s wall)")
        print(f"ratio jitted / SB3 (CPU): run {record['ratio_run_cpu']:.3f} (per run "
              f"{record['ratio_run_cpu_per_run']:.3f}), compile + run "
              f"{record['ratio_compile_and_run_cpu']:.3f}; wall: run {record['ratio_run_wall']:.3f}")
        print("mean training episode return per tenth of the run (JAX | SB3):")
        for part in np.array_split(np.arange(n_bins), min(10, n_bins)):
            jr = j_sum[part].sum() / max(j_count[part].sum(), 1)
            sr = s_sum[part].sum() / max(s_count[part].sum(), 1)
            print(f"  up to {int(jx['curve']['steps'][part[-1]]):>7d} steps: {jr:12.1f} | {sr:12.1f}")
        print(f"final (last {n_tail} rollouts / collects): JAX {record['jax_final_return']:.1f}, "
              f"SB3 {record['sb3_final_return']:.1f}")
    if args.eval_episodes:
        ev = evaluate(policy_dir, None if args.skip_sb3 else run_dir, args.eval_episodes)
        record["evaluation"] = ev
        print(f"J/J_paper on evaluation episodes {ev['seeds'][0]}-{ev['seeds'][1]}: JAX {ev['jax_J_over_J_paper']:.3f}"
              + (f", SB3 {ev['sb3_J_over_J_paper']:.3f}" if "sb3_J_over_J_paper" in ev else ""))
    work.cleanup()
    print(f"load averages: {record.get('load_before_jax')} -> {_load()}")
    if args.out:
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with open(args.out, "w") as fh:
            json.dump(coarsen(record), fh, indent=1)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
