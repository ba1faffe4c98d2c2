"""Single-environment control steps per second of ``tracking_v0`` and ``gym.make("dobs_envs/Tracking-v0")``.

Usage: python benchmarks/bench_envs.py [--steps 20000] [--substeps 50] [--profile]

Random actions (a pool drawn beforehand from the action spaces, so sampling is
not timed), default options, episodes reset when they end (resets included),
after a warm-up; ``--steps`` are split into ``--repeats`` interleaved short runs of the
kernel, the parallel env and the Gymnasium env, and the best run of each is reported
(shared machines are noisy). Also
prints the cost of ``step_env`` alone for the same control period, i.e. the
floor the environment's Python layer adds to. ``--profile`` prints the top of
a cProfile of the parallel env loop.
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def run_parallel(env, pool, steps):
    obs, _ = env.reset(seed=0)
    n = len(pool)
    t0 = time.perf_counter()
    for k in range(steps):
        if not env.agents:
            env.reset()
        env.step(pool[k % n])
    return steps / (time.perf_counter() - t0)


def run_gym(env, pool, steps):
    env.reset(seed=0)
    n = len(pool)
    t0 = time.perf_counter()
    for k in range(steps):
        _, _, term, trunc, _ = env.step(pool[k % n])
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--substeps", type=int, default=50)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args(argv)

    import gymnasium as gym

    import dobs_envs  # noqa: F401  (registers the Gymnasium ids)
    from dobs_envs import tracking_v0
    from dobs_envs.sim import step_env

    penv = tracking_v0.parallel_env(substeps=args.substeps)
    penv.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = [{a: penv.action_space(a).low + (penv.action_space(a).high - penv.action_space(a).low)
             * rng.random(penv.action_space(a).shape).astype(np.float32) for a in penv.possible_agents}
            for _ in range(1000)]
    genv = gym.make("dobs_envs/Tracking-v0", substeps=args.substeps)
    gpool = [genv.action_space.sample() for _ in range(1000)]

    # step_env alone (the floor)
    st, p = penv.sim_state, penv.params
    u = np.zeros((1, p.n_inputs)); r = np.zeros((1, p.n_inputs))

    def run_kernel(steps):
        t0 = time.perf_counter()
        for _ in range(steps):
            step_env(st, u, p, r, validate=False)
        return steps / (time.perf_counter() - t0)

    run_kernel(500)
    run_parallel(penv, pool, 2000)  # warm-up
    run_gym(genv, gpool, 2000)
    # interleaved short runs, best of each: robust to load bursts on shared machines
    chunk = max(200, args.steps // args.repeats)
    best_k = par = gy = 0.0
    for _ in range(args.repeats):
        best_k = max(best_k, run_kernel(chunk))
        par = max(par, run_parallel(penv, pool, chunk))
        gy = max(gy, run_gym(genv, gpool, chunk))
    best_k = 1.0 / best_k
    period = penv.control_period
    print(f"tracking_v0 (NE2, dt={penv.dt:g}, substeps={penv.substeps}, control period {period:g} s), single env, random actions:")
    print(f"  step_env alone             : {best_k * 1e6:7.1f} us/step  -> {1 / best_k:9,.0f} steps/s (ceiling)")
    print(f"  PettingZoo parallel_env    : {1e6 / par:7.1f} us/step  -> {par:9,.0f} control steps/s"
          f"  ({par * period:,.0f} simulated s per wall s)")
    print(f"  gym.make('dobs_envs/Tracking-v0'): {1e6 / gy:7.1f} us/step  -> {gy:9,.0f} control steps/s")
    print(f"  Python overhead over step_env: parallel {1e6 / par - best_k * 1e6:.1f} us, gym {1e6 / gy - best_k * 1e6:.1f} us")

    if args.profile:
        import cProfile
        import pstats

        pr = cProfile.Profile()
        pr.enable()
        run_parallel(penv, pool, args.steps)
        pr.disable()
        pstats.Stats(pr).sort_stats("tottime").print_stats(15)


if __name__ == "__main__":
    main()
