"""The arithmetic of the jitted SAC's gradient steps: FLOPs (XLA's cost analysis), FLOPs per CPU second, and the
CPU time a full run's gradient steps need at that rate.

The jitted SAC is most of the CPU time of the four environments' jitted rows (docs/results/index.md). Per env, with
its shipped jitted recipe (``resolve_recipe("sac", env, trainer="jax")``; 600k env steps unless ``--timesteps``):
one gradient step (``agents.training.jax.sac.update_step``: critics, target, actor, temperature) on a minibatch of
the recipe's size, ``jax.vmap``ped over ``--seeds`` runs as the benchmark trains them, with the env's observation and
action sizes and the recipe's network. Timed as ``--steps`` such steps in one ``lax.scan`` (one XLA thread, CPU time
of this process, best of ``--repeats`` after a warm-up; random data: the FLOPs and the time do not depend on the
values). ``--processes 2`` runs that many copies of this measurement at once, each timing its own process: what
one core delivers while the other core does the same work.

    PYTHONPATH=. python benchmarks/jax_sac_flops.py [--env tracking disturbance_rejection ...] [--seeds 10]
        [--steps 200] [--repeats 3] [--processes 1] [--out results/jax_sac_flops.json]

The JSON record is written only with ``--out`` (an existing file is kept unless ``--overwrite``).
"""
from __future__ import annotations

import os

os.environ.setdefault("PJRT_NPROC", "1")
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from bench_args import add_record_args, check_args, jax_runtime, write_record  # noqa: E402

ENVS_DEFAULT = ("tracking", "disturbance_rejection", "random_network", "hetero_mas")


def measure(env: str, seeds: int, steps: int, repeats: int, timesteps: int) -> dict:
    """One env's figures (module doc)."""
    import jax
    import jax.numpy as jnp

    from agents.config.envs import gym_id
    from agents.training.jax import sac
    from agents.training.recipes import resolve_recipe

    recipe = dict(resolve_recipe("sac", env, trainer="jax").hyperparams)
    cfg, _ = sac.sac_config(recipe, gym_id(env), total_timesteps=timesteps)
    jenv, params = sac.make_env(cfg)
    obs_dim = int(jenv.observation_space(params).shape[0])
    act_dim = int(jenv.action_space(params).shape[0])
    B, S = cfg.batch_size, seeds

    hooks = sac.SACHooks(cfg, obs_dim, act_dim)  # the trainer's own learner state (alpha 1)
    keys = jax.random.split(jax.random.PRNGKey(0), S)
    state = jax.vmap(lambda key: hooks.init(key, {"ent_coef": jnp.float32(1.0)}))(keys)
    k = jax.random.split(jax.random.PRNGKey(1), 5)
    batch = (jax.random.normal(k[0], (S, B, obs_dim)), jax.random.uniform(k[1], (S, B, act_dim), minval=-1.0,
                                                                           maxval=1.0),
             jax.random.normal(k[2], (S, B, obs_dim)), jax.random.normal(k[3], (S, B)), jnp.zeros((S, B)))

    def step(st, b, key):
        return sac.update_step(st, b, jax.random.split(key), lr=1e-3, lr_alpha=1e-3, gamma=0.99, tau=0.02,
                               target_entropy=-float(act_dim), activation=cfg.activation, ent_auto=cfg.ent_auto)

    one = jax.jit(jax.vmap(step)).lower(state, batch, jax.random.split(k[4], S)).compile()
    cost = one.cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    flops = float(cost["flops"])

    def many(st, key):
        def body(c, kk):
            return jax.vmap(step)(c, batch, jax.random.split(kk, S))[0], None
        return jax.lax.scan(body, st, jax.random.split(key, steps))[0]

    f = jax.jit(many)
    jax.block_until_ready(f(state, k[4]))
    best = float("inf")
    for r in range(repeats):
        t0 = time.process_time()
        jax.block_until_ready(f(state, jax.random.PRNGKey(10 + r)))
        best = min(best, time.process_time() - t0)
    per = best / steps
    grad_steps = cfg.n_updates * cfg.gradient_steps  # every collect's gradient steps (learning_starts ignored)
    return {"env": env, "obs_dim": obs_dim, "act_dim": act_dim, "batch_size": B, "net_arch": list(cfg.net_arch),
            "seeds": S, "gradient_steps_per_run": grad_steps, "flops_per_step": flops,
            "flops_per_step_per_run": flops / S, "cpu_s_per_step": per, "gflops_per_cpu_s": flops / per / 1e9,
            "cpu_s_for_the_runs_gradient_steps": per * grad_steps,
            "tflops_for_the_runs_gradient_steps": flops * grad_steps / 1e12}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", nargs="+", default=list(ENVS_DEFAULT), help="environment short names")
    ap.add_argument("--seeds", type=int, default=10, help="runs vmapped (default 10, the full budget's)")
    ap.add_argument("--steps", type=int, default=200, help="gradient steps timed (default 200)")
    ap.add_argument("--repeats", type=int, default=3, help="timed calls (default 3; the best counts)")
    ap.add_argument("--timesteps", type=int, default=600_000, help="env steps of a run (default 600000)")
    ap.add_argument("--processes", type=int, default=1, help="copies of the measurement run at once (default 1)")
    ap.add_argument("--json-lines", action="store_true", help=argparse.SUPPRESS)  # a copy started by --processes
    add_record_args(ap)
    args = ap.parse_args(argv)
    check_args(ap, args, ("seeds", "steps", "repeats", "timesteps", "processes"))
    from agents.config.envs import ENVS, env_key

    envs = [env_key(e) for e in args.env]
    bad = [e for e in envs if e not in ENVS]
    if bad:
        ap.error(f"--env must be among {sorted(ENVS)}, got {bad}")
    if args.processes > 1:  # the same measurement in that many processes at once, one JSON line each
        cmd = [sys.executable, os.path.abspath(__file__), "--env", *envs, "--seeds", str(args.seeds), "--steps",
               str(args.steps), "--repeats", str(args.repeats), "--timesteps", str(args.timesteps), "--json-lines"]
        procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True) for _ in range(args.processes)]
        outs = [p.communicate()[0] for p in procs]
        if any(p.returncode for p in procs):
            print("a measuring process failed", file=sys.stderr)
            return 1
        rows = [dict(json.loads(line), process=i) for i, o in enumerate(outs) for line in o.splitlines() if line]
    else:
        rows = [measure(e, args.seeds, args.steps, args.repeats, args.timesteps) for e in envs]
    if args.json_lines:
        for r in rows:
            print(json.dumps(r))
        return 0
    for r in rows:
        print(f"{r['env']:22s}{' p' + str(r['process']) if 'process' in r else ''}: {r['flops_per_step_per_run'] / 1e6:.0f} "
              f"MFLOP per gradient step per run, {r['gflops_per_cpu_s']:.1f} GFLOP per CPU s, "
              f"{r['cpu_s_for_the_runs_gradient_steps']:.0f} CPU s for {r['seeds']} runs' "
              f"{r['gradient_steps_per_run']} gradient steps ({r['tflops_for_the_runs_gradient_steps']:.1f} TFLOP)")
    write_record(args, {"processes": args.processes, "steps_timed": args.steps, "repeats": args.repeats,
                        "rows": rows, **jax_runtime()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
