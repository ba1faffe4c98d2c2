"""Speed of one control period (50 Euler substeps) of the NE2 closed loop.

Usage: python benchmarks/bench_sim.py [--substeps 50] [--batch 1]

Prints microseconds per control period for the compiled kernel alone, for
``step_env`` (kernel + state handling) and for the pure-numpy reference, each
the best of several repeats (the machines are shared and noisy), plus their ratio.
Goal (issue 3): <= 100 us per control period for one environment.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from dobs_envs.scenarios.paper import ne2
from dobs_envs.sim import step_env
from dobs_envs.sim.period_kernel import control_period_compiled


def best_of(fn, inner: int, repeats: int = 15) -> float:
    fn()
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        best = min(best, (time.perf_counter() - t0) / inner)
    return best * 1e6


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--substeps", type=int, default=50)
    ap.add_argument("--batch", type=int, default=1)
    args = ap.parse_args(argv)
    sc = ne2()
    params = sc.sim_params(substeps=args.substeps)
    state = sc.initial_state(params, batch=args.batch)
    rng = np.random.default_rng(0)
    u = rng.normal(size=(args.batch, params.n_inputs))
    r = rng.normal(size=(args.batch, params.n_inputs))

    k = best_of(lambda: control_period_compiled(state.x, state.z, state.gamma, state.gamma_s, state.v, state.x_r, u, r, params), 300)
    s = best_of(lambda: step_env(state, u, params, r, validate=False), 300)
    npy = best_of(lambda: step_env(state, u, params, r, backend="numpy", validate=False), 5, repeats=5)
    N, n = params.n_nodes, params.n_states
    print(f"NE2 closed loop: n={n}, N={N} observer nodes, batch={args.batch}, {args.substeps} substeps per control period")
    print(f"  compiled kernel : {k:8.1f} us / control period")
    print(f"  step_env (numba): {s:8.1f} us / control period   (goal <= 100 us)")
    print(f"  step_env (numpy): {npy:8.1f} us / control period   ({npy / s:.0f}x slower)")


if __name__ == "__main__":
    main()
