"""Environment throughput in one run: single env, native vector env at B = 1, 64, 1024, and a base checkout.

Usage: python benchmarks/bench_envs.py [--base REF|PATH] [--repeats 7] [--seconds 0.4] [--no-base]
       [--env-id dobs_envs/Tracking-v0] [--batches 1,64,1024] [--faults lossy|none|JSON] [--clock wall|cpu]

Everything is measured side by side in one run, interleaved (config A, B, C, ..., A, B, C,
...), best of ``--repeats`` short runs of about ``--seconds`` each (the machines are shared
with training runs: only ratios measured this way mean anything):

- single env: ``gym.make("dobs_envs/Tracking-v0")`` control steps/s (random actions from a
  pool drawn beforehand, resets included) and the PettingZoo ``tracking_v0.parallel_env``;
- vector env: ``gym.make_vec("dobs_envs/Tracking-v0", num_envs=B)`` env-steps/s
  (``B`` x steps/s) at B = 1, 64, 1024, serial (``threads=1``) and with one thread per core
  (``threads=None``, the default: ranges of copies advanced concurrently, GIL released);
- the same single envs of another checkout (``--base``: a directory, or a git ref of this repository
  checked out in a temporary ``git worktree`` for the run and removed afterwards, ``benchmarks/checkouts.py``;
  default the branch ``main``) in a worker process started with that checkout first on ``sys.path`` (and
  its own numba cache directory, so nothing is written into it), timed in the same interleaved loop,
  and that checkout's serial vector env at the largest ``--batches`` size;
- communication faults (issue 23): the vector env at the largest ``--batches`` size with the option
  ``faults=`` (``--faults``: ``lossy``, the default, is ``tracking_lossy_v0``'s setting; a JSON dict;
  ``none`` skips it), serial and threaded, and its ratio to the same env without faults (target
  >= 0.7x).

``--clock cpu`` times the single-threaded runs (single envs, ``threads=1`` vector envs, the other
checkout's worker) by their process's CPU time (``time.process_time``) instead of the wall clock: on a
machine busy with other work, the time the run computes, not the time it waits for a core. The
threaded runs stay on the wall clock (the CPU time of several threads is not their throughput).

It also reports the floating-point operations of one control step (simulation kernel +
features/reward, counted from the kernels' loops) and the fraction of the 2-core FMA peak the
B = 1024 vector env reaches: peak = cores x FMA units (2) x doubles per vector (8 with
AVX-512, 4 with AVX2) x 2 flops x clock (``cpu MHz`` of /proc/cpuinfo).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checkouts import add_base_argument, checkout  # noqa: E402

ENV_ID = "dobs_envs/Tracking-v0"
POOL = 512

WORKER = r'''
import importlib, json, sys, time
import numpy as np
import gymnasium as gym
import dobs_envs
from dobs_envs.registry import ENVIRONMENTS
ENV_ID = sys.argv[1]
now = time.process_time if sys.argv[2] == "cpu" else time.perf_counter
genv = gym.make(ENV_ID)
penv = importlib.import_module(next(e.module for e in ENVIRONMENTS.values() if e.gym_id == ENV_ID)).parallel_env()
rng = np.random.default_rng(0)
gpool = [genv.action_space.low + (genv.action_space.high - genv.action_space.low) * rng.random(5).astype(np.float32)
         for _ in range(512)]
ppool = [{a: g[k:k + 1] for k, a in enumerate(penv.possible_agents)} for g in gpool]
genv.reset(seed=0); penv.reset(seed=0)
def run_gym(n):
    t0 = now()
    for k in range(n):
        _, _, te, tr, _ = genv.step(gpool[k % 512])
        if te or tr:
            genv.reset()
    return n / (now() - t0)
def run_pz(n):
    t0 = now()
    for k in range(n):
        if not penv.agents:
            penv.reset()
        penv.step(ppool[k % 512])
    return n / (now() - t0)
vecs = {}
def run_vec(B, n):
    if B not in vecs:
        v = gym.make_vec(ENV_ID, num_envs=B, threads=1)
        v.reset(seed=0)
        r = np.random.default_rng(1)
        vecs[B] = (v, [v.action_space.low + (v.action_space.high - v.action_space.low)
                       * r.random(v.action_space.shape).astype(np.float32) for _ in range(8)])
    v, acts = vecs[B]
    t0 = now()
    for k in range(n):
        v.step(acts[k % 8])
    return n * B / (now() - t0)
run_gym(500); run_pz(500)
print(json.dumps({"file": dobs_envs.__file__}), flush=True)
for line in sys.stdin:
    what, n = line.split()
    if what.startswith("vec"):
        print(json.dumps(run_vec(int(what[3:]), int(n))), flush=True)
    else:
        print(json.dumps((run_gym if what == "gym" else run_pz)(int(n))), flush=True)
'''


class Worker:
    """The single envs of a checkout in a subprocess (that checkout first on sys.path)."""

    def __init__(self, checkout: str, env_id: str = ENV_ID, clock: str = "wall"):
        env = dict(os.environ, PYTHONPATH=checkout, PYTHONDONTWRITEBYTECODE="1",
                   NUMBA_CACHE_DIR=os.path.join(tempfile.gettempdir(), "dobs_bench_numba_" + checkout.strip("/").replace("/", "_")))
        self.proc = subprocess.Popen([sys.executable, "-c", WORKER, env_id, clock], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE,
                                     text=True, env=env, cwd=tempfile.gettempdir())
        self.file = json.loads(self.proc.stdout.readline())["file"]

    def run(self, what: str, n: int) -> float:
        self.proc.stdin.write(f"{what} {n}\n")
        self.proc.stdin.flush()
        return float(json.loads(self.proc.stdout.readline()))

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def peak_flops() -> tuple[float, str]:
    flags, mhz = "", 0.0
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("flags") and not flags:
                    flags = line
                elif line.startswith("cpu MHz") and not mhz:
                    mhz = float(line.split(":")[1])
    except OSError:
        pass
    lanes = 8 if " avx512f" in flags else (4 if " fma" in flags else 2)
    cores = os.cpu_count() or 1
    peak = cores * 2 * lanes * 2 * mhz * 1e6
    return peak, f"{cores} cores x 2 FMA units x {lanes} doubles x 2 flops x {mhz / 1000:.2f} GHz"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_base_argument(ap, what="checkout to compare the single envs with")
    ap.add_argument("--no-base", action="store_true", help="time this checkout only")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seconds", type=float, default=0.4, help="length of one timed run")
    ap.add_argument("--batches", default="1,64,1024")
    ap.add_argument("--env-id", default=ENV_ID, help="registered Gymnasium id of the env to time")
    ap.add_argument("--faults", default="lossy", help="fault setting of the faulted vector env: 'lossy' "
                    "(tracking_lossy_v0's), 'none' (not timed) or a JSON dict of faults keys")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="time the single-threaded runs by the wall clock or by the process's CPU time "
                         "(process_time: on a loaded machine, not the time a run waits for a core); threaded "
                         "runs always by the wall clock")
    args = ap.parse_args(argv)
    if args.no_base:
        return _run(args, None)
    with contextlib.ExitStack() as stack:
        try:
            base = stack.enter_context(checkout(args.base))
        except ValueError as exc:
            ap.error(str(exc))
        return _run(args, base)


def _run(args, base):
    env_id = args.env_id
    now = time.process_time if args.clock == "cpu" else time.perf_counter

    import gymnasium as gym

    import dobs_envs  # noqa: F401
    import importlib

    from dobs_envs.envs.features import flops_per_row
    from dobs_envs.registry import ENVIRONMENTS
    from dobs_envs.sim.period_kernel import flops_per_period

    # ---------------------------------------------------------------- contestants
    rng = np.random.default_rng(0)
    genv = gym.make(env_id)
    lo, hi = genv.action_space.low, genv.action_space.high
    gpool = [lo + (hi - lo) * rng.random(lo.shape).astype(np.float32) for _ in range(POOL)]
    penv = importlib.import_module(next(e.module for e in ENVIRONMENTS.values() if e.gym_id == env_id)).parallel_env()
    ppool = [{a: g[k:k + 1] for k, a in enumerate(penv.possible_agents)} for g in gpool]
    genv.reset(seed=0)
    penv.reset(seed=0)

    def run_gym(n):
        t0 = now()
        for k in range(n):
            _, _, te, tr, _ = genv.step(gpool[k % POOL])
            if te or tr:
                genv.reset()
        return n / (now() - t0)

    def run_pz(n):
        t0 = now()
        for k in range(n):
            if not penv.agents:
                penv.reset()
            penv.step(ppool[k % POOL])
        return n / (now() - t0)

    from dobs_envs.envs.tracking import TRACKING_LOSSY_FAULTS

    faults = None if args.faults == "none" else (dict(TRACKING_LOSSY_FAULTS) if args.faults == "lossy"
                                                 else json.loads(args.faults))
    batches = [int(b) for b in args.batches.split(",")]
    vec = {}
    keys = [(B, par, None) for B in batches for par in (False, True)]
    if faults is not None:
        keys += [(batches[-1], par, "faults") for par in (False, True)]
    for B, par, f in keys:
        v = gym.make_vec(env_id, num_envs=B, threads=None if par else 1, **({} if f is None else {"faults": faults}))
        v.reset(seed=0)
        acts = [v.action_space.low + (v.action_space.high - v.action_space.low)
                * rng.random(v.action_space.shape).astype(np.float32) for _ in range(8)]
        vec[(B, par, f)] = (v, acts)

    def run_vec(key, n):
        v, acts = vec[key]
        clock = time.perf_counter if key[1] else now  # threaded: wall clock
        t0 = clock()
        for k in range(n):
            v.step(acts[k % 8])
        return n * key[0] / (clock() - t0)

    worker = None if base is None else Worker(base, env_id, args.clock)
    configs = {"gym single (this checkout)": ("gym", None), "PettingZoo single (this checkout)": ("pz", None)}
    if worker is not None:
        configs["gym single (base)"] = ("gym", "main")
        configs["PettingZoo single (base)"] = ("pz", "main")
    for key in vec:
        configs[f"vector B={key[0]}{' threads' if key[1] else ''}{' faults' if key[2] else ''}"] = ("vec", key)
    if worker is not None:
        configs[f"vector B={batches[-1]} (base)"] = (f"vec{batches[-1]}", "main")

    # ---------------------------------------------------------------- calibrate run lengths, warm up
    steps = {}
    for name, (kind, key) in configs.items():
        fn = {"gym": run_gym, "pz": run_pz}.get(kind)
        if kind == "vec":
            rate = run_vec(key, 3) / key[0]
        elif key == "main":
            rate = worker.run(kind, 3) / batches[-1] if kind.startswith("vec") else worker.run(kind, 300)
        else:
            rate = fn(300)
        steps[name] = max(3, int(rate * args.seconds))
    best = dict.fromkeys(configs, 0.0)
    for _ in range(args.repeats):  # interleaved
        for name, (kind, key) in configs.items():
            if kind == "vec":
                r = run_vec(key, steps[name])
            elif key == "main":
                r = worker.run(kind, steps[name])
            else:
                r = {"gym": run_gym, "pz": run_pz}[kind](steps[name])
            best[name] = max(best[name], r)
    if worker is not None:
        main_file = worker.file
        worker.close()

    # ---------------------------------------------------------------- report
    core = vec[(batches[-1], False, None)][0].core
    flops = flops_per_period(core.params) + flops_per_row(core)
    peak, peak_desc = peak_flops()
    single = best["gym single (this checkout)"]
    print(f"{env_id} ({core.scenario.name}, n={core.n_states}, N={core.n_nodes}, {core.substeps} Euler substeps per control step), "
          f"best of {args.repeats} interleaved runs of ~{args.seconds:g} s"
          + (" (CPU time of the single-threaded runs, wall clock of the threaded ones)" if args.clock == "cpu" else ""))
    print(f"{'configuration':36s} {'env-steps/s':>13s} {'x gym single':>13s}")
    for name in configs:
        print(f"{name:36s} {best[name]:13,.0f} {best[name] / single:13.2f}")
    if worker is not None:
        print(f"base checkout ({args.base}) imported from {main_file}")
        print(f"single env vs base: gym {single / best['gym single (base)']:.2f}x, PettingZoo "
              f"{best['PettingZoo single (this checkout)'] / best['PettingZoo single (base)']:.2f}x; "
              f"vector B={batches[-1]} (serial) vs base: "
              f"{best[f'vector B={batches[-1]}'] / best[f'vector B={batches[-1]} (base)']:.2f}x")
    if faults is not None:
        Bm = batches[-1]
        print(f"faults {json.dumps(faults)} vs none, vector B={Bm}: serial "
              f"{best[f'vector B={Bm} faults'] / best[f'vector B={Bm}']:.2f}x, threads "
              f"{best[f'vector B={Bm} threads faults'] / best[f'vector B={Bm} threads']:.2f}x (target >= 0.7x)")
    top = max((k for k in configs if k.startswith(f"vector B={batches[-1]}") and not k.endswith("(base)")
               and "faults" not in k),
              key=lambda k: best[k])
    print(f"best B={batches[-1]}: {top} = {best[top] / single:.1f}x the gym single env (target >= 8x)")
    print(f"flops per control step: {flops:,} ({flops_per_period(core.params):,} simulation + "
          f"{flops_per_row(core):,} features/reward)")
    for name in configs:
        if name.startswith(f"vector B={batches[-1]}") and not name.endswith("(base)") and "faults" not in name:
            print(f"{name}: {best[name] * flops / 1e9:.1f} GFLOP/s = {best[name] * flops / peak:.1%} of the peak "
                  f"{peak / 1e9:.0f} GFLOP/s ({peak_desc})")


if __name__ == "__main__":
    main()
