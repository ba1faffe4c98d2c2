"""CPU seconds per run of a jitted agent's seeds vmapped in one compiled call against one seed alone.

What the benchmark's jitted rows run (:func:`agents.training.jax.vmap_seeds.train_jax_seeds`): the run that
:data:`agents.training.jax.vmap_seeds.BUILDERS` builds from the shipped recipe (``resolve_recipe(algo, env,
trainer="jax")``, the learning curve's snapshots included), compiled once as ``jax.jit(train)`` (one seed: what the
benchmark runs for an algorithm without a vmapped builder, seed after seed) and once as ``jax.jit(jax.vmap(train))``
over ``--seeds`` keys. Both in this process, one XLA thread: the single program compiled and run, then the vmapped
one, then the two alternately up to ``--repeats`` runs each (the same inputs: a repeat recomputes the same run).
Figures: CPU (``time.process_time``) and wall seconds of each compilation and run; the ratio of the target is the
vmapped run's CPU per seed over the single run's CPU (below 1: vmapping is cheaper per run), with and without the
compilations (a run of the benchmark pays one compilation per task: one vmapped, or one single run per seed).
Peak resident memory (``ru_maxrss``) after the single run and after the vmapped one (the replay buffers: ``--seeds``
of them at once).

    PYTHONPATH=. python benchmarks/bench_vmap_seeds.py [--algo sac] [--env tracking] [--steps 20000] [--seeds 10]
        [--repeats 2] [--out x.json]

The machine may be shared: the load averages before and after are printed (and recorded with ``--out``; an
existing file is kept unless ``--overwrite``).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time

from bench_args import add_record_args, check_args


def _load() -> list:
    return [round(x, 2) for x in os.getloadavg()]


def _peak_mb() -> float:
    """This process's peak resident memory so far (MB; Linux reports ``ru_maxrss`` in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _timed(fn):
    c0, w0 = time.process_time(), time.perf_counter()
    out = fn()
    return out, time.process_time() - c0, time.perf_counter() - w0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--algo", default="sac", help="a jitted algorithm with a centralised vmapped builder (default sac)")
    ap.add_argument("--env", default="tracking")
    ap.add_argument("--steps", type=int, default=20_000, help="env steps of each run (default 20000)")
    ap.add_argument("--seeds", type=int, default=10, help="seeds vmapped in one call (default 10)")
    ap.add_argument("--repeats", type=int, default=2, help="alternate runs of each compiled function (default 2)")
    add_record_args(ap)
    args = ap.parse_args(argv)
    check_args(ap, args, ("steps", "seeds", "repeats"))

    from agents.training.xla import xla_threads

    xla_threads(1)  # before JAX's first computation
    import jax
    import jax.numpy as jnp

    from agents.training.jax.run import CURVE_EPISODES, CURVE_POINTS, CURVE_SEED, jax_env
    from agents.training.jax.vmap_seeds import BUILDERS

    builder = BUILDERS.get((args.algo, False))
    if builder is None:
        ap.error(f"--algo {args.algo}: no centralised vmapped builder; those of "
                 f"{sorted(a for a, m in BUILDERS if not m)}")
    env, gid = jax_env(args.env)
    record = {"algo": args.algo, "env": env, "steps": args.steps, "seeds": args.seeds, "repeats": args.repeats,
              "cpu_count": os.cpu_count(), "PJRT_NPROC": os.environ.get("PJRT_NPROC"),
              "XLA_FLAGS": os.environ.get("XLA_FLAGS"), "jax_version": jax.__version__, "load_before": _load()}
    run = builder(env, gid, None, args.steps, CURVE_POINTS, list(range(CURVE_SEED, CURVE_SEED + CURVE_EPISODES)))
    record["steps_done"] = run.steps_done
    key = jax.random.PRNGKey(0)
    keys = jnp.stack([jax.random.PRNGKey(s) for s in range(args.seeds)])
    single = jax.jit(run.train)
    vmapped = jax.jit(jax.vmap(run.train, in_axes=(0, None)))
    for name in ("single_cpu", "single_wall", "vmapped_cpu", "vmapped_wall"):
        record[name] = []

    def run_single():
        _, c, w = _timed(lambda: jax.block_until_ready(one(key, run.hp)))
        record["single_cpu"].append(c)
        record["single_wall"].append(w)
        return c

    def run_vmapped():
        _, c, w = _timed(lambda: jax.block_until_ready(many(keys, run.hp)))
        record["vmapped_cpu"].append(c)
        record["vmapped_wall"].append(w)
        return c

    # the single run's phases first (its peak memory before the vmapped program exists), then alternately
    one, record["compile_single_cpu"], record["compile_single_wall"] = _timed(
        lambda: single.lower(key, run.hp).compile())
    run_single()
    record["peak_mb_single"] = _peak_mb()
    many, record["compile_vmapped_cpu"], record["compile_vmapped_wall"] = _timed(
        lambda: vmapped.lower(keys, run.hp).compile())
    run_vmapped()
    record["peak_mb_with_vmapped"] = _peak_mb()
    print(f"{args.algo} {env}, {run.steps_done} env steps per run: compiled single in "
          f"{record['compile_single_cpu']:.1f} s CPU, {args.seeds} seeds vmapped in "
          f"{record['compile_vmapped_cpu']:.1f} s CPU; peak memory {record['peak_mb_single']:.0f} MB after the "
          f"single run, {record['peak_mb_with_vmapped']:.0f} MB after the vmapped one", file=sys.stderr, flush=True)
    for r in range(args.repeats):
        s_cpu = record["single_cpu"][-1] if r == 0 else run_single()
        c = record["vmapped_cpu"][-1] if r == 0 else run_vmapped()
        print(f"repeat {r}: single {s_cpu:.1f} s CPU, {args.seeds} vmapped {c:.1f} s CPU "
              f"({c / args.seeds:.2f} s per run)", file=sys.stderr, flush=True)
    record["load_after"] = _load()
    n = args.seeds
    s, v = min(record["single_cpu"]), min(record["vmapped_cpu"])
    record["ratio_run_cpu_per_run"] = v / n / s
    record["ratio_with_compile_per_run"] = ((record["compile_vmapped_cpu"] / n + v / n)
                                            / (record["compile_single_cpu"] + s))
    print(f"{args.algo} on {env}, {run.steps_done} env steps, one XLA thread, load {record['load_before']} -> "
          f"{record['load_after']} (best of {args.repeats}):\n"
          f"  one seed alone:      run {s:.1f} s CPU, compile {record['compile_single_cpu']:.1f} s CPU\n"
          f"  {n} seeds vmapped:    run {v:.1f} s CPU ({v / n:.2f} s per run), compile "
          f"{record['compile_vmapped_cpu']:.1f} s CPU\n"
          f"  vmapped / alone, CPU per run: {record['ratio_run_cpu_per_run']:.3f} (run), "
          f"{record['ratio_with_compile_per_run']:.3f} (compile + run)")
    if args.out:
        with open(args.out, "x") as fh:
            json.dump(record, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
