"""Where the CPU time of a jitted PPO run goes: the environment, the rest of the rollout, the updates.

Issue 40's first target asks a 600k-step jitted PPO run on tracking to take at most 0.1x the CPU of SB3 PPO's.
This script splits the jitted run's time, one XLA thread, in one process, timed side by side (alternating
``--repeats`` times; medians), on ``--steps`` steps scaled to a 600k-step run:

- ``recipe``: the shipped jitted recipe (``resolve_recipe("ppo", env, trainer="jax")``);
- ``one_epoch``: the same recipe with ``n_epochs: 1`` (the same rollouts, one pass of minibatches);
- ``env``: the environment alone, ``n_envs`` vmapped copies stepped in a ``lax.scan`` with zero actions (and with
  ``--seeds S``: vmapped over ``S`` runs as the trainer's copies are, ``(S, n_envs)``).

One epoch of minibatch updates costs ``(recipe - one_epoch) / (n_epochs - 1)``, the updates ``n_epochs`` times that,
the rollout (environment, policy, normaliser, GAE) the rest; the environment's own share is the ``env`` row. With
``--seeds S`` the runs are vmapped in one compiled call, as ``agents.training.jax.vmap_seeds`` trains them; the
figures are per run.

    PYTHONPATH=. python benchmarks/jax_ppo_cost.py [--env tracking] [--steps 40960] [--seeds 1] [--repeats 3]
        [--out results/jax_ppo_cost.json]

The JSON record is written only with ``--out`` (an existing file is kept unless ``--overwrite``).
"""
from __future__ import annotations

import os

os.environ.setdefault("PJRT_NPROC", "1")
if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from bench_args import add_record_args, check_args, jax_runtime, write_record  # noqa: E402

FULL = 600_000  # the full budget's steps per run


def _compiled_runs(env: str, steps: int, seeds: int) -> tuple[dict, dict]:
    """``{name: (compiled, args, steps_done)}`` for the recipe and its one-epoch twin, and the recipe's config."""
    import jax

    from agents.config.envs import gym_id
    from agents.training.jax.ppo import make_train, ppo_config
    from agents.training.recipes import resolve_recipe

    recipe = dict(resolve_recipe("ppo", env, trainer="jax").hyperparams)
    runs, cfg0 = {}, None
    for name, over in (("recipe", {}), ("one_epoch", {"n_epochs": 1})):
        cfg, hp = ppo_config({**recipe, **over}, gym_id(env), total_timesteps=steps)
        cfg0 = cfg0 or cfg
        train, key = make_train(cfg), jax.random.PRNGKey(0)
        if seeds > 1:
            train, key = jax.vmap(train, in_axes=(0, None)), jax.random.split(key, seeds)
        runs[name] = (jax.jit(train).lower(key, hp).compile(), (key, hp), cfg.steps_done)
    return runs, {"recipe": recipe, "n_envs": cfg0.n_envs, "n_steps": cfg0.n_steps, "n_epochs": cfg0.n_epochs,
                  "batch_size": cfg0.batch_size, "net_arch": list(cfg0.net_arch), "cfg": cfg0}


def _compiled_env(cfg, seeds: int, length: int):
    """The environment alone: ``length`` steps of ``n_envs`` copies (vmapped over ``seeds`` runs), zero actions."""
    import jax
    import jax.numpy as jnp

    from agents.training.jax.ppo import gymnax_slots, make_env

    env, params = make_env(cfg)
    slots = gymnax_slots(env, params, cfg.n_envs)

    def run(key):
        _, state = slots.reset(key)

        def body(state, k):
            _, state, reward, *_ = slots.step(k, state, jnp.zeros((cfg.n_envs, slots.act_dim), jnp.float32))
            return state, reward
        return jax.lax.scan(body, state, jax.random.split(key, length))[1]

    key = jax.random.PRNGKey(0)
    if seeds > 1:
        run, key = jax.vmap(run), jax.random.split(key, seeds)
    return jax.jit(run).lower(key).compile(), (key,)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="tracking", help="environment short name (default tracking)")
    ap.add_argument("--steps", type=int, default=40_960, help="env steps per run timed (default 40960: 10 rollouts "
                                                                 "of the tracking recipe); figures scaled to 600k")
    ap.add_argument("--seeds", type=int, default=1, help="runs vmapped in one call (default 1)")
    ap.add_argument("--repeats", type=int, default=3, help="timed calls of each (alternating; default 3)")
    add_record_args(ap)
    args = ap.parse_args(argv)
    check_args(ap, args, ("steps", "seeds", "repeats"))
    from agents.config.envs import ENVS, env_key

    args.env = env_key(args.env)
    if args.env not in ENVS:
        ap.error(f"--env must be one of {sorted(ENVS)}, got {args.env!r}")
    import jax

    runs, info = _compiled_runs(args.env, args.steps, args.seeds)
    cfg = info.pop("cfg")
    if cfg.n_epochs < 2:
        ap.error(f"the recipe of {args.env} has n_epochs {cfg.n_epochs}: nothing to split")
    vec_steps = -(-args.steps // cfg.n_envs)
    env_fn = _compiled_env(cfg, args.seeds, vec_steps)
    calls = {**runs, "env": (env_fn[0], env_fn[1], vec_steps * cfg.n_envs)}
    times = {k: [] for k in calls}
    for c, a, _ in calls.values():  # warm: the first call of a compiled function allocates
        jax.block_until_ready(c(*a))
    for _ in range(args.repeats):
        for name, (c, a, done) in calls.items():
            t0 = time.process_time()
            jax.block_until_ready(c(*a))
            times[name].append((time.process_time() - t0) * FULL / done / args.seeds)
    med = {k: float(np.median(v)) for k, v in times.items()}
    epoch = (med["recipe"] - med["one_epoch"]) / (cfg.n_epochs - 1)
    split = {"run": med["recipe"], "updates": epoch * cfg.n_epochs, "rollout": med["one_epoch"] - epoch,
             "environment": med["env"]}
    split["rollout_without_environment"] = split["rollout"] - split["environment"]
    record = {"env": args.env, "steps_timed": args.steps, "seeds": args.seeds, "repeats": args.repeats, **info,
              "cpu_s_per_600k_run": times, "median": med, "split_cpu_s_per_600k_run": split,
              **jax_runtime()}
    print(f"{args.env}, {args.seeds} run(s) vmapped, CPU s per 600k-step run (medians of {args.repeats}): "
          + ", ".join(f"{k} {v:.1f}" for k, v in split.items()))
    write_record(args, record)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
