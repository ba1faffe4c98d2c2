"""Off-policy training throughput on a dobs_envs task, side by side with PPO (issue 21, item 1).

Candidates (all in one process, on the same machine and run, each from the shipped recipe of its
algorithm on the task, ``agents/config/hyperparams/<algo>.yaml``, with the overrides named in its label):

- ``ppo SB3``: the reference (its recipe: 8 copies on the batched core);
- ``sac SB3 1 env``: SB3 SAC as shipped (1 copy, one gradient step per env step);
- ``sac SB3 {N} env G={G}``: SB3 SAC on ``N`` copies of the batched core, ``G`` gradient steps per
  collect of ``--train-freq`` steps of every copy (default 1: ``G`` per ``N`` env steps);
- ``sac|td3|crossq SBX ...``: SBX (Stable Baselines Jax) on the CPU, 1 copy and ``N`` copies;
- ``td3 SB3 1 env``, ``crossq sb3-contrib 1 env``, ``tqc sb3-contrib 1 env`` (TQC with the SAC recipe).

Throughput: each model is built and warmed up first (``learning_starts`` random steps plus
``--warmup`` steps of training: every compiled function -- numba kernels of the env, XLA functions
of SBX -- is compiled then; the warm-up time is reported separately), then the timed windows of
``--steps`` env steps alternate between the candidates for ``--repeats`` rounds and the best window
of each is kept (the machine is shared: the best window is the least disturbed). Env-steps/s count
environment steps (all copies), the ratio is to PPO's.

``--curve STEPS``: also train every candidate for STEPS env steps from scratch (training seeds
``--seed``, ``--seed + 1``, ...) and score it at ``--points`` checkpoints on ``--episodes`` episodes of
the tuning range (agents/training/seeds.py; never evaluation episodes): the cost ratio J / J_paper of the
deterministic policy on the task's own env (:func:`agents.training.curves.make_curve_callback`, the
benchmark's learning-curve code), mean over the training runs. The learning curves compare the
candidates at equal env steps.

    python benchmarks/offpolicy_throughput.py [--env tracking] [--steps 2000] [--warmup 500] [--repeats 2]
        [--n-envs 8] [--gradient-steps 2] [--train-freq 1] [--set JSON] [--only sac,crossq] [--xla-threads 1]
        [--curve 50000 --seeds 3 [--no-reference-curve]]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field


@dataclass
class Candidate:
    label: str
    recipe: str                     # the recipe file (algorithm name) the candidate trains with
    library: str                    # sbx-rl | stable-baselines3 | sb3-contrib
    class_name: str
    overrides: dict = field(default_factory=dict)

    def backend(self):
        from agents.training.algos import AlgoBackend, flax_policy_kwargs, torch_policy_kwargs

        jax = self.library == "sbx-rl"
        module = {"sbx-rl": "sbx", "stable-baselines3": "stable_baselines3", "sb3-contrib": "sb3_contrib"}[self.library]
        return AlgoBackend(self.class_name.lower(), library=self.library, module=module, class_name=self.class_name,
                           policy_kwargs=flax_policy_kwargs if jax else torch_policy_kwargs,
                           extra="jax" if jax else "rl")


def candidates(n: int, g: int, train_freq: int = 1, extra: dict | None = None) -> list[Candidate]:
    many = {"n_envs": n, "gradient_steps": g, "train_freq": train_freq, **(extra or {})}
    tag = f"{n} env G={g}" + (f" every {train_freq}" if train_freq != 1 else "")
    if extra:
        tag += " " + " ".join(f"{k}={v}" for k, v in extra.items())
    return [
        Candidate("ppo SB3 (recipe)", "ppo", "stable-baselines3", "PPO"),
        Candidate("sac SB3 1 env (recipe)", "sac", "stable-baselines3", "SAC"),
        Candidate(f"sac SB3 {tag}", "sac", "stable-baselines3", "SAC", many),
        Candidate("sac SBX 1 env", "sac", "sbx-rl", "SAC"),
        Candidate(f"sac SBX {tag}", "sac", "sbx-rl", "SAC", many),
        Candidate("td3 SB3 1 env (recipe)", "td3", "stable-baselines3", "TD3"),
        Candidate("td3 SBX 1 env", "td3", "sbx-rl", "TD3"),
        Candidate(f"td3 SBX {tag}", "td3", "sbx-rl", "TD3", many),
        Candidate("crossq SBX 1 env", "crossq", "sbx-rl", "CrossQ"),
        Candidate(f"crossq SBX {tag}", "crossq", "sbx-rl", "CrossQ", many),
        Candidate("crossq sb3-contrib 1 env", "crossq", "sb3-contrib", "CrossQ"),
        Candidate("tqc sb3-contrib 1 env (sac recipe)", "sac", "sb3-contrib", "TQC"),
    ]


def build(c: Candidate, env: str, seed: int, timesteps: int):
    """``(model, backend, venv, run config)`` of candidate ``c`` (the training env of ``agents.training.train``)."""
    from agents.training.recipes import resolve_recipe
    from agents.training.train import _setup

    b = c.backend()
    recipe = resolve_recipe(c.recipe, env, overrides=c.overrides or None)
    s = _setup(env, env, b, multi_agent=False, hybrid=None, recipe=recipe, timesteps=timesteps, seed=seed,
               env_kwargs=None, checkpoint_freq=0)
    model = b.make(recipe, s.venv, seed=seed)
    b.quiet_logger(model)
    return model, b, s.venv, s.config


def _learn(model, steps: int) -> float:
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False)
    return time.perf_counter() - t0


def throughput(cands: list[Candidate], env: str, steps: int, warmup: int, repeats: int) -> dict:
    """Best env-steps/s of each candidate over ``repeats`` alternating timed windows, after a warm-up."""
    out = {}
    models = {}
    for c in cands:
        t0 = time.perf_counter()
        model, b, venv, cfg = build(c, env, seed=0, timesteps=10 ** 9)
        built = time.perf_counter() - t0
        starts = int(getattr(model, "learning_starts", 0) or 0)
        n = model.n_envs
        # PPO learns in whole rollouts: a window is at least two of them
        rollout = getattr(model, "n_steps", 1) * n if c.recipe == "ppo" else n
        window = max(steps, 2 * rollout)
        warm = _learn(model, starts + max(warmup, rollout))
        models[c.label] = (model, window)
        out[c.label] = {"library": f"{b.library} {b.library_version()}", "n_envs": n,
                        "gradient_steps": getattr(model, "gradient_steps", None), "build_s": built, "warmup_s": warm,
                        "warmup_steps": int(model.num_timesteps), "steps_per_s": 0.0, "windows": []}
        print(f"built {c.label}: {built:.1f} s, warm-up {model.num_timesteps} steps in {warm:.1f} s", flush=True)
    for r in range(repeats):
        for c in cands:
            model, window = models[c.label]
            before = model.num_timesteps
            dt = _learn(model, window)
            sps = (model.num_timesteps - before) / dt
            out[c.label]["windows"].append(sps)
            out[c.label]["steps_per_s"] = max(out[c.label]["steps_per_s"], sps)
            print(f"round {r}: {c.label:38s} {sps:8.0f} env-steps/s ({model.num_timesteps - before} steps)", flush=True)
    for model, _ in models.values():
        model.get_env().close()
    return out


def curves(cands: list[Candidate], env: str, steps: int, seeds: list[int], points: int, episodes: int) -> dict:
    """J / J_paper of each candidate at ``points`` checkpoints of a ``steps``-step run per training seed."""
    from agents.training.curves import make_curve_callback
    from agents.training.seeds import TUNING, check_episode_seeds

    eval_seeds = check_episode_seeds(TUNING.start, episodes, TUNING)
    every = max(1, steps // points)
    out = {}
    for c in cands:
        runs = []
        for seed in seeds:
            model, b, venv, cfg = build(c, env, seed=seed, timesteps=steps)
            cb = make_curve_callback(env, {}, eval_seeds, every)
            cb.agent_config = cfg
            t0 = time.perf_counter()
            model.learn(total_timesteps=steps, callback=cb)
            runs.append({"seed": seed, "seconds": time.perf_counter() - t0, "points": cb.points})
            venv.close()
            print(f"{c.label} seed {seed}: " + ", ".join(
                f"{p['env_steps']}: {sum(p['cost_ratio']) / len(p['cost_ratio']):.3g}" for p in cb.points), flush=True)
        out[c.label] = runs
    return out


def _mean_curve(runs: list[dict]) -> list[tuple[int, float]]:
    """(env steps, mean over runs of the run's mean J / J_paper) at the points every run has."""
    import numpy as np

    steps = sorted(set.intersection(*[{p["env_steps"] for p in r["points"]} for r in runs]))
    return [(s, float(np.mean([np.mean(next(p["cost_ratio"] for p in r["points"] if p["env_steps"] == s))
                               for r in runs]))) for s in steps]


def markdown(tp: dict, cv: dict | None, ref: str) -> str:
    base = tp[ref]["steps_per_s"] if ref in tp else float("nan")
    lines = ["| candidate | library | copies | grad. steps per collect | env-steps/s (best window) | ratio to PPO "
             "| warm-up s (steps) |", "|---|---|---|---|---|---|---|"]
    for label, r in tp.items():
        lines.append(f"| {label} | {r['library']} | {r['n_envs']} | {r['gradient_steps'] if r['gradient_steps'] is not None else '-'} "
                     f"| {r['steps_per_s']:.0f} | {r['steps_per_s'] / base:.3f} | {r['warmup_s']:.1f} ({r['warmup_steps']}) |")
    if cv:
        lines += ["", "J / J_paper (tuning episodes; mean over training runs) at env steps:", ""]
        pts = {label: _mean_curve(runs) for label, runs in cv.items()}
        cols = sorted({s for p in pts.values() for s, _ in p})
        lines.append("| candidate | " + " | ".join(str(s) for s in cols) + " |")
        lines.append("|---|" + "---|" * len(cols))
        for label, p in pts.items():
            d = dict(p)
            lines.append(f"| {label} | " + " | ".join(f"{d[s]:.3g}" if s in d else "" for s in cols) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="tracking")
    ap.add_argument("--steps", type=int, default=2000, help="env steps per timed window (PPO: at least 2 rollouts)")
    ap.add_argument("--warmup", type=int, default=500, help="training steps after learning_starts before timing")
    ap.add_argument("--repeats", type=int, default=2, help="alternating timed windows; the best of each is kept")
    ap.add_argument("--n-envs", type=int, default=8, help="environment copies of the multi-copy candidates")
    ap.add_argument("--gradient-steps", type=int, default=2, help="gradient steps per collect of the multi-copy "
                                                                   "candidates (one collect = n_envs env steps)")
    ap.add_argument("--train-freq", type=int, default=1, help="steps of every copy per collect of the multi-copy "
                                                               "candidates (gradient steps G after each collect)")
    ap.add_argument("--set", default=None, metavar="JSON",
                    help="more recipe overrides of the multi-copy candidates, a JSON object in the recipe files' "
                         "vocabulary (e.g. '{\"learning_rate\": \"lin_1e-3\", \"batch_size\": 512}'); named in "
                         "their labels")
    ap.add_argument("--no-reference-curve", action="store_true",
                    help="--curve mode: do not train the PPO reference's curve (its throughput is still measured)")
    ap.add_argument("--only", default=None, help="comma-separated substrings: candidates whose label holds one "
                                                 "(the PPO reference is always kept)")
    ap.add_argument("--xla-threads", type=int, default=None,
                    help="threads of XLA's CPU client (PJRT_NPROC, set before JAX computes); default: as "
                         "agents.training.train.set_threads does (1 with --threads 1; else XLA's own: all cores)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (agents' default 1)")
    ap.add_argument("--curve", type=int, default=None, metavar="STEPS",
                    help="also train each candidate STEPS env steps and score it on tuning episodes")
    ap.add_argument("--seeds", type=int, default=3, help="training runs per candidate in --curve mode")
    ap.add_argument("--seed", type=int, default=0, help="first training seed in --curve mode")
    ap.add_argument("--points", type=int, default=5, help="checkpoints of the --curve runs")
    ap.add_argument("--episodes", type=int, default=5, help="tuning episodes per checkpoint")
    ap.add_argument("--json", default=None, help="write the measurements to this (new) file")
    args = ap.parse_args(argv)
    if args.xla_threads is not None:
        if args.xla_threads < 1:
            ap.error(f"--xla-threads must be >= 1, got {args.xla_threads}")
        os.environ["PJRT_NPROC"] = str(args.xla_threads)  # set_threads keeps it
    if args.json and os.path.exists(args.json):
        print(f"offpolicy_throughput: error: --json {args.json!r} exists", file=sys.stderr)
        return 2
    from agents.training.train import set_threads

    set_threads(args.threads)
    extra = None
    if args.set:
        try:
            extra = json.loads(args.set)
        except json.JSONDecodeError as e:
            extra = e
        if not isinstance(extra, dict):
            print(f"offpolicy_throughput: error: --set must be a JSON object, got {args.set!r}", file=sys.stderr)
            return 2
    cands = candidates(args.n_envs, args.gradient_steps, args.train_freq, extra)
    ref = cands[0].label
    if args.only:
        keys = [k.strip() for k in args.only.split(",") if k.strip()]
        cands = [cands[0]] + [c for c in cands[1:] if any(k in c.label for k in keys)]
    unavailable = [(c, c.backend().unavailable()) for c in cands]
    for c, why in unavailable:
        if why:
            print(f"skipped {c.label}: {c.library} not importable ({why})", file=sys.stderr)
    cands = [c for c, why in unavailable if not why]
    t0 = time.perf_counter()
    tp = throughput(cands, args.env, args.steps, args.warmup, args.repeats)
    cv = None
    if args.curve:
        cv = curves(cands[1:] if args.no_reference_curve else cands, args.env, args.curve, list(range(args.seed, args.seed + args.seeds)), args.points,
                    args.episodes)
    print()
    print(f"{args.env}: {args.steps} env steps per window, best of {args.repeats}; torch threads {args.threads}, "
          f"XLA threads {os.environ.get('PJRT_NPROC', 'default (all cores)')}; {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f}; {time.perf_counter() - t0:.0f} s in all")
    print(markdown(tp, cv, ref))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"args": vars(args), "xla_threads": os.environ.get("PJRT_NPROC"), "throughput": tp, "curves": cv},
                      fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
