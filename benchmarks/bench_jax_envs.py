"""Throughput of the JAX environments beside the compiled core's vector env, in one run.

For every batch size B: env-steps/s of

- ``gym.make_vec(id, num_envs=B)`` (the compiled core, numba, one thread) stepped with random actions;
- a jitted ``lax.scan`` of ``jax.vmap(env.step)`` (gymnax view with auto-reset) over ``steps`` control
  steps with random actions drawn inside the scan, in float64 and in float32.

Figures are CPU seconds of this process (``time.process_time``: robust to other processes on a shared
machine) and wall seconds; XLA runs on one thread (``PJRT_NPROC=1``, set before JAX is imported
unless already set) and the compiled core on one thread, so the ratio compares one core with one
core. Compilation is excluded (one warm-up call). The lock-step cost of the split Euler steps under
``vmap`` (``--lockstep G ...``): the same rollout (float64) when one copy of the batch has gains ``G`` so
large that every one of its Euler steps is split.

    python benchmarks/bench_jax_envs.py --env tracking --batch 1 64 1024 4096 --out results/bench_jax_envs.json
    python benchmarks/bench_jax_envs.py --env tracking_lossy --batch 1 1024 --out results/bench_jax_envs_faults.json
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

os.environ.setdefault("PJRT_NPROC", "1")


def _time(fn, repeats: int):
    """``(min CPU seconds, min wall seconds)`` of ``fn()`` over ``repeats`` calls after one warm-up."""
    fn()
    cpu, wall = [], []
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    return min(cpu), min(wall)


def bench_core(env_id: str, B: int, steps: int, repeats: int) -> dict:
    import gymnasium as gym

    import dobs_envs  # noqa: F401

    env = gym.make_vec(env_id, num_envs=B)
    env.reset(seed=0)
    acts = [env.action_space.sample() for _ in range(8)]

    def run():
        for k in range(steps):
            env.step(acts[k % 8])

    cpu, wall = _time(run, repeats)
    env.close()
    return {"cpu_s": cpu, "wall_s": wall, "steps_per_s_cpu": B * steps / cpu, "steps_per_s_wall": B * steps / wall}


def bench_jax(env_id: str, B: int, steps: int, repeats: int, dtype: str, lockstep: float = 0.0,
              faults: bool = False) -> dict:
    import jax

    from dobs_envs.jax import make

    # communication faults draw in 64-bit integers (dobs_envs.jax.faults): x64 on, the simulation in ``dtype``
    with jax.enable_x64(dtype == "float64" or faults):
        env, params = make(env_id, dtype=dtype)
        m = env.structure.m
        _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(0), B), params)
        if lockstep:  # copy 0 splits every Euler step: its gains beyond 1 / (2 deg dt)
            state = state.replace(gamma=state.gamma.at[0].set(lockstep))
        lo, hi = params.action_low, params.action_high

        @jax.jit
        def rollout(state, key):
            def body(s, k):
                ka, ks = jax.random.split(k)
                a = jax.random.uniform(ka, (B, m), lo.dtype, lo, hi)
                obs, s, r, term, trunc, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                    jax.random.split(ks, B), s, a, params)
                return s, r
            return jax.lax.scan(body, state, jax.random.split(key, steps))

        t0 = time.perf_counter()
        jax.block_until_ready(rollout(state, jax.random.PRNGKey(1)))
        compile_s = time.perf_counter() - t0
        cpu, wall = _time(lambda: jax.block_until_ready(rollout(state, jax.random.PRNGKey(2))), repeats)
    return {"cpu_s": cpu, "wall_s": wall, "steps_per_s_cpu": B * steps / cpu, "steps_per_s_wall": B * steps / wall,
            "first_call_s": compile_s}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default="tracking", help="short name (tracking, disturbance_rejection, ...)")
    ap.add_argument("--batch", type=int, nargs="+", default=[1, 64, 1024, 4096])
    ap.add_argument("--steps", type=int, default=0, help="control steps per timed call (default: 2e5 / B, 20..400)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--lockstep", type=float, nargs="*", default=[],
                    help="also time the rollout with copy 0's gains gamma_i set to each of these values (its Euler "
                         "steps then split: at gamma_i = 1e3 on tracking into about 4, at 1e4 into about 40)")
    ap.add_argument("--out", help="write the figures as JSON (refuses to overwrite)")
    a = ap.parse_args(argv)
    if a.out and os.path.exists(a.out):
        print(f"bench_jax_envs: --out {a.out} exists; remove it or choose another path", file=sys.stderr)
        return 2
    from dobs_envs.registry import ENVIRONMENTS

    if a.env not in ENVIRONMENTS:
        print(f"bench_jax_envs: unknown --env {a.env!r}; choose from {sorted(ENVIRONMENTS)}", file=sys.stderr)
        return 2
    env_id = ENVIRONMENTS[a.env].gym_id
    faults = ENVIRONMENTS[a.env].load_class().make_core(1).faults is not None
    rows = []
    for B in a.batch:
        steps = a.steps or int(min(400, max(20, 200_000 // B)))
        row = {"B": B, "steps": steps, "core": bench_core(env_id, B, steps, a.repeats)}
        for dt in ("float64", "float32"):
            row[f"jax_{dt}"] = bench_jax(env_id, B, steps, a.repeats, dt, faults=faults)
        for g in a.lockstep if B > 1 else ():
            row[f"jax_float64_lockstep_{g:g}"] = bench_jax(env_id, B, steps, a.repeats, "float64", lockstep=g,
                                                           faults=faults)
        rows.append(row)
        c = row["core"]["steps_per_s_cpu"]
        msg = " | ".join(f"{k} {v['steps_per_s_cpu']:,.0f}/s ({v['steps_per_s_cpu'] / c:.2f}x)"
                         for k, v in row.items() if isinstance(v, dict) and k != "core")
        print(f"B={B:5d} core {c:,.0f}/s | {msg}", flush=True)
    import jax

    out = {"env": a.env, "rows": rows, "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                                                    "load_avg": os.getloadavg(), "jax": jax.__version__,
                                                    "PJRT_NPROC": os.environ.get("PJRT_NPROC")},
           "units": "env-steps per CPU second of this process (and per wall second); compilation excluded"}
    if a.out:
        with open(a.out, "x") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
