"""Two checkouts side by side: bit-for-bit outputs and speed (single env, vector env B = 1024).

Usage: python benchmarks/compare_checkouts.py [--base REF|PATH] [--head REF|PATH] [--digest] [--speed]
       [--repeats 7] [--seconds 0.4] [--batch 1024] [--env-id dobs_envs/Tracking-v0]

``--base`` (default: the branch ``main``) and ``--head`` (default: this checkout) are each a directory or a
git ref of this repository, checked out in a temporary ``git worktree`` for the run and removed afterwards
(``benchmarks/checkouts.py``). Each checkout runs in its own worker process (that checkout first on ``sys.path``, its own
numba cache directory under the temp dir, nothing written into the checkouts), so both sides
are measured the same way:

- ``--digest``: SHA-256 of the outputs of deterministic runs through the public APIs -- every
  named environment's batched core (B = TILE + 77: a SIMD tile, a run-time-width tile; B = 3:
  copy by copy; two threads), observations, features, rewards, reason codes and simulation
  states over 20 steps of random (partly clipped) inputs with resets; large initial states
  (split Euler steps); the compiled closed loop (``rollout``) of every paper scenario, per-copy
  epsilon and the oracle variant; ``step_env`` on a random design; the front ends over the core
  (observations, rewards, flags, every info value, actions mapped to inputs): the PettingZoo env
  (also with ``normalized_actions``/``padded_observations``), ``gym.make`` and ``gym.make_vec`` and
  SB3 ``agents.vecenv.batched_core.CoreVecEnv`` (centralised and shared slots, agent ids, rescaled actions,
  diagnostics; skipped when the checkout has no ``agents``); communication faults (each kind alone and
  all at once on the tracking core, tiles, remainder tiles, copy by copy, two threads; every env with all
  of them; large states with them; ``tracking_lossy``; faulted ``rollout`` of NE2), the fault state
  and the C-O masks included. Prints one line per run and whether
  the two checkouts agree bit for bit.
- ``--speed`` (default): ``gym.make(env_id)`` control steps/s (single env),
  ``gym.make_vec(env_id, num_envs=B, threads=1)`` env-steps/s, and the simulation kernel alone
  (``control_period_compiled``, NE2, 50 Euler steps per period, B = 1 and B), best of ``--repeats`` runs of
  about ``--seconds`` each, interleaved (base, head, head, base, ...: the order alternates): only
  ratios measured this way mean anything on a shared machine. ``--pairs K`` repeats this with K fresh pairs
  of worker processes and reports each pair's ratios and their median (the machine code of a compiled
  kernel, and with it its speed, varies from process to process by more than a few per cent). ``--clock cpu`` times each run by
  the worker's CPU time instead of the wall clock (on a machine busy with other work: the time the
  worker computes, not the time it waits for a core; all runs are single-threaded).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checkouts import REPO, add_base_argument, checkout  # noqa: E402

WORKER = r'''
import hashlib, json, sys, time
import numpy as np

def h(*arrays):
    d = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        d.update(str((a.dtype.str, a.shape)).encode())
        d.update(a.tobytes())
    return d.hexdigest()[:16]

def digest():
    from dobs_envs.envs import DisturbanceRejectionEnv, HeteroMASEnv, RandomNetworkEnv, TrackingEnv
    from dobs_envs.rollout import rollout
    from dobs_envs.scenarios.paper import PAPER_SCENARIOS, ne3
    from dobs_envs.sim import SimParams, step_env
    try:
        from dobs_envs.sim.period_kernel import TILE
    except ImportError:  # a checkout before issue 23 named the module sim.kernel
        from dobs_envs.sim.kernel import TILE
    out = {}

    def run_core(core, seeds, steps=20, gain=1.5, seed=0, options=None):
        core.reset(None, seeds, options)
        rng = np.random.default_rng(seed)
        acc = [core.observations]
        for _ in range(steps):
            u = rng.uniform(-gain, gain, size=(core.num_envs, core.n_inputs)) * core.action_bound
            res = core.advance(u)
            s = core.sim_state
            acc += [core.observations, core.features, core.estimation_errors, core.applied_inputs, res.reward,
                    res.terminated, res.truncated, res.reason, s.t, s.x, s.z, s.gamma, s.gamma_s, s.v, s.x_r]
            ended = res.terminated | res.truncated
            if ended.any():
                core.reset(np.flatnonzero(ended))
        return h(*acc)

    envs = {"tracking": (TrackingEnv, {}), "disturbance_exo": (DisturbanceRejectionEnv, {}),
            "disturbance_random": (DisturbanceRejectionEnv, {"disturbance": "random"}),
            "hetero_mas": (HeteroMASEnv, {}), "random_network": (RandomNetworkEnv, {})}
    for name, (cls, kw) in envs.items():
        for B, threads in ((TILE + 77, 1), (3, 1), (TILE + 77, 2)):
            core = cls.make_core(B, threads=threads, max_cycles=12, **kw)
            out[f"core {name} B={B} threads={threads}"] = run_core(core, list(range(100, 100 + B)))
            core.close()
    big = DisturbanceRejectionEnv.make_core(TILE + 9, max_cycles=100, state_bound=1e4)
    rng = np.random.default_rng(7)
    x0 = rng.normal(size=(TILE + 9, big.n_states))
    x0 *= np.linspace(1.0, 900.0, TILE + 9)[:, None] / np.linalg.norm(x0, axis=1, keepdims=True)
    out["core large states (split steps)"] = run_core(big, list(range(TILE + 9)), steps=6, gain=1.0,
                                                      options={"x0": x0})
    # communication faults: every kind alone and all at once, tiles, remainder tiles, copy by copy, threads;
    # the fault state is in the digest too
    def fault_cases_of(N):
        ring = np.zeros((N, N))
        for i in range(N):
            ring[i, (i + 1) % N] = ring[(i + 1) % N, i] = 1.0
        cut = ring.copy()
        cut[0, 1] = cut[1, 0] = cut[2, 3] = cut[3, 2] = 0.0
        return fault_cases_graphs(ring, cut)

    def fault_cases_graphs(ring, cut):
        return {
        "sampled": dict(oo_period=0.01), "drifting": dict(oo_period=0.03, oo_delay=2), "loss": dict(oo_loss=0.3),
        "burst": dict(oo_burst={"p_good_bad": 0.2, "p_bad_good": 0.3, "loss_good": 0.05, "loss_bad": 0.9}),
        "delay": dict(oo_delay=3), "noise": dict(measurement_noise=0.05), "co": dict(co_loss=0.3, co_delay=2),
        "switching": dict(switching={"graphs": [ring, np.zeros_like(ring), cut],
                                     "transition": [[0.6, 0.2, 0.2], [0.3, 0.4, 0.3], [0.3, 0.3, 0.4]]}),
        "all": dict(oo_period=0.005, oo_loss=0.2, oo_delay=1, co_loss=0.3, co_delay=2, measurement_noise=0.05,
                    switching={"graphs": [ring, cut], "rate": 3.0}),
        }

    fault_cases = fault_cases_of(TrackingEnv.make_core(1).n_nodes)

    def fault_hash(core):
        return h(*core.fault_state, core.co_received)

    for fname, fk in fault_cases.items():
        for B, threads in ((TILE + 77, 1), (3, 1), (TILE + 77, 2)) if fname == "all" else ((TILE + 77, 1), (3, 1)):
            core = TrackingEnv.make_core(B, threads=threads, max_cycles=12, faults=fk)
            out[f"core tracking faults={fname} B={B} threads={threads}"] = (run_core(core, list(range(100, 100 + B)))
                                                                         + fault_hash(core))
            core.close()
    for name, (cls, kw) in envs.items():
        N = cls.make_core(1, **kw).n_nodes
        core = cls.make_core(TILE + 9, max_cycles=12, faults=fault_cases_of(N)["all"], **kw)
        out[f"core {name} faults=all B={TILE + 9}"] = run_core(core, list(range(TILE + 9))) + fault_hash(core)
    big = DisturbanceRejectionEnv.make_core(TILE + 9, max_cycles=100, state_bound=1e4,
                                            faults=fault_cases_of(big.n_nodes)["all"])
    out["core large states (split steps) faults=all"] = run_core(big, list(range(TILE + 9)), steps=6, gain=1.0,
                                                                 options={"x0": x0}) + fault_hash(big)
    from dobs_envs.registry import ENVIRONMENTS
    if "tracking_lossy" in ENVIRONMENTS:
        import importlib
        mod, _, cname = ENVIRONMENTS["tracking_lossy"].entry_point.partition(":")
        lossy = getattr(importlib.import_module(mod), cname)
        for B in (TILE + 77, 3):
            core = lossy.make_core(B, max_cycles=12)
            out[f"core tracking_lossy B={B}"] = run_core(core, list(range(100, 100 + B))) + fault_hash(core)
    for fname in ("loss", "delay", "noise", "co", "all"):
        sc2 = PAPER_SCENARIOS["ne2"]()
        trs = rollout(sc2, t_end=0.3, batch=TILE + 7, faults=fault_cases_of(sc2.n_observers)[fname], fault_seed=5)
        out[f"rollout ne2 faults={fname} B={TILE + 7}"] = h(*[getattr(tr, f) for tr in trs
                                                               for f in ("t", "x", "est_err", "gamma", "gamma_s", "u")])
    for name in sorted(PAPER_SCENARIOS):
        trs = rollout(PAPER_SCENARIOS[name](), t_end=0.3, batch=2)
        out[f"rollout {name}"] = h(*[getattr(tr, f) for tr in trs for f in ("t", "x", "est_err", "gamma", "gamma_s", "u")])
    trs = rollout(ne3(), t_end=0.5, batch=3, epsilon=[0.2, 0.05, 0.01], phi_beta=20.0)
    out["rollout ne3 per-copy epsilon"] = h(*[getattr(tr, f) for tr in trs for f in ("x", "est_err", "u", "beta")])
    trs = rollout(ne3(), t_end=0.3, oracle=True)
    out["rollout ne3 oracle"] = h(trs[0].x, trs[0].u, trs[0].beta)
    from types import SimpleNamespace
    rng = np.random.default_rng(0)
    N, n, p, m, mv = 4, 5, 2, 3, 2
    P = np.zeros((N, n, n))
    for i in range(N):
        Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        k = int(rng.integers(1, n))
        P[i] = Q[:, :k] @ Q[:, :k].T
    adj = np.triu((rng.random((N, N)) < 0.6).astype(float), 1)
    d = SimpleNamespace(A=rng.normal(size=(n, n)) * 0.3, B=rng.normal(size=(n, m)), B_v=rng.normal(size=(n, mv)),
                        C=rng.normal(size=(N, p, n)), E_bar=rng.normal(size=(N, n, n)) * 0.3,
                        F_bar=rng.normal(size=(N, n, p)), G_bar=rng.normal(size=(N, n, p)),
                        B_bar=rng.normal(size=(N, n, m)), P_u=P, adjacency=adj + adj.T)
    prm = SimParams.from_design(d, dt=1e-3, substeps=37, exosystem=np.array([[0, 0.5], [-0.5, 0]]),
                                K_ref=rng.normal(size=(3, 5)) * 0.1, sigma=0.1, sigma_s=0.05, phi=0.3, phi_s=0.7)
    for B in (3, 300):
        s = prm.initial_state(rng.normal(size=(B, 5)), z0=rng.normal(size=(B, 4, 5)), v0=[-2, 2],
                              x_r0=rng.normal(size=(B, 5)))
        u, r = rng.normal(size=(B, 3)), rng.normal(size=(B, 3))
        acc = []
        for _ in range(5):
            s = step_env(s, u, prm, r)
            acc += [s.x, s.z, s.gamma, s.gamma_s, s.v, s.x_r]
        out[f"step_env random design B={B}"] = h(*acc)
    out.update(adapters())
    return out

def _flat_info(info):
    # an info dict (or a list/dict of them) as arrays in a fixed order: keys sorted, values as float64
    if isinstance(info, dict) and info and all(isinstance(v, dict) for v in info.values()):
        return [a for k in sorted(info) for a in _flat_info(info[k])]
    if isinstance(info, list):
        return [a for i in info for a in _flat_info(i)]
    acc = []
    for k in sorted(info):
        v = info[k]
        acc.append(np.frombuffer(k.encode(), dtype=np.uint8))
        acc.append(np.asarray(v, dtype=np.float64) if not isinstance(v, np.ndarray) or v.dtype != object
                   else np.zeros(0))
    return acc

def adapters():
    # the front ends over the same core: PettingZoo, Gymnasium, Gymnasium vector, SB3 CoreVecEnv
    import gymnasium as gym
    import dobs_envs  # noqa: F401
    from dobs_envs.envs import HeteroMASEnv, RandomNetworkEnv, TrackingEnv
    out = {}
    rng = np.random.default_rng(3)
    for name, kw in (("hetero_mas", {}), ("hetero_mas normalized+padded", dict(normalized_actions=True,
                                                                             padded_observations=True))):
        env = HeteroMASEnv(max_cycles=6, **kw)
        obs, infos = env.reset(seed=5)
        acc = [a for k in sorted(obs) for a in [obs[k]]] + _flat_info(infos)
        for _ in range(8):
            if not env.agents:
                obs, infos = env.reset()
                acc += [obs[k] for k in sorted(obs)] + _flat_info(infos)
            acts = {a: (rng.uniform(-1.3, 1.3, env.action_space(a).shape) * env.action_space(a).high)
                    .astype(np.float32) for a in env.agents}
            obs, rew, term, trunc, infos = env.step(acts)
            acc += [obs[k] for k in sorted(obs)] + [np.array([rew[k], term[k], trunc[k]], float) for k in sorted(rew)]
            acc += _flat_info(infos)
        acc += list(env.actions_from_inputs(np.linspace(-1, 1, env.n_inputs)).values())
        out[f"parallel env {name}"] = h(*acc)
    for gid, kw in (("dobs_envs/HeteroMAS-v0", {}), ("dobs_envs/Tracking-v0", dict(normalized_actions=True))):
        e = gym.make(gid, max_episode_steps=5, **kw)
        o, info = e.reset(seed=9)
        acc = [o] + _flat_info(info)
        for _ in range(7):
            o, r, te, tr, info = e.step((rng.uniform(-1.3, 1.3, e.action_space.shape) * e.action_space.high)
                                        .astype(np.float32))
            acc += [o, np.array([r, te, tr], float)] + _flat_info(info)
            if te or tr:
                o, info = e.reset()
                acc += [o] + _flat_info(info)
        out[f"gym env {gid} {kw}"] = h(*acc)
        v = gym.make_vec(gid, num_envs=5, max_episode_steps=4, threads=1, **kw)
        o, info = v.reset(seed=11)
        acc = [o] + _flat_info(info)
        for _ in range(7):
            o, r, te, tr, info = v.step((rng.uniform(-1.3, 1.3, v.action_space.shape) * v.action_space.high)
                                        .astype(np.float32))
            acc += [o, r, te, tr] + _flat_info(info)
        out[f"vector env {gid} {kw}"] = h(*acc)
    try:
        from agents.core_vec_env import CoreVecEnv  # the path every checkout has (a re-export since issue 38)
    except ImportError:
        return out
    for cls, shared, agent_id, rescale, diag, kw in (
            (HeteroMASEnv, True, True, True, True, {}), (HeteroMASEnv, True, False, False, True, {}),
            (HeteroMASEnv, False, False, True, True, {}),
            (HeteroMASEnv, True, True, True, False, dict(normalized_actions=True, padded_observations=True)),
            (TrackingEnv, True, False, True, True, {}), (TrackingEnv, False, False, True, False, {}),
            (RandomNetworkEnv, True, True, True, True, {}), (RandomNetworkEnv, True, False, False, False, {})):
        ve = CoreVecEnv(cls.make_core(4, max_cycles=5, **kw), shared=shared, agent_id=agent_id,
                        rescale_actions=rescale, diagnostics=diag)
        ve.seed(21)
        acc = [ve.reset()] + _flat_info(ve.reset_infos)
        for _ in range(7):
            a = rng.uniform(-1.3, 1.3, (ve.num_envs,) + ve.action_space.shape) * (1 if rescale else 9)
            ve.step_async(a.astype(np.float32))
            o, r, d, infos = ve.step_wait()
            acc += [o, r, d] + _flat_info(infos)
        out[f"CoreVecEnv {cls.__name__} shared={shared} id={agent_id} rescale={rescale} diag={diag} {kw}"] = h(*acc)
    return out

def speed_setup(env_id, batch, clock="wall"):
    import gymnasium as gym
    now = time.process_time if clock == "cpu" else time.perf_counter
    import dobs_envs  # noqa: F401
    genv = gym.make(env_id)
    rng = np.random.default_rng(0)
    lo, hi = genv.action_space.low, genv.action_space.high
    gpool = [lo + (hi - lo) * rng.random(lo.shape).astype(np.float32) for _ in range(512)]
    genv.reset(seed=0)
    v = gym.make_vec(env_id, num_envs=batch, threads=1)
    v.reset(seed=0)
    vacts = [v.action_space.low + (v.action_space.high - v.action_space.low)
             * rng.random(v.action_space.shape).astype(np.float32) for _ in range(8)]

    def run_single(n):
        t0 = now()
        for k in range(n):
            _, _, te, tr, _ = genv.step(gpool[k % 512])
            if te or tr:
                genv.reset()
        return n / (now() - t0)

    def run_vec(n):
        t0 = now()
        for k in range(n):
            v.step(vacts[k % 8])
        return n * batch / (now() - t0)
    from dobs_envs.scenarios.paper import ne2
    try:
        from dobs_envs.sim.period_kernel import control_period_compiled
    except ImportError:  # a checkout before issue 23 named the module sim.kernel
        from dobs_envs.sim.kernel import control_period_compiled
    params = ne2().sim_params(substeps=50)
    sims = {}
    for B in (1, batch):
        st = ne2().initial_state(params, batch=B)
        u = rng.normal(size=(B, params.n_inputs))
        r = rng.normal(size=(B, params.n_inputs))
        sims[B] = (st, u, r)

    def run_sim(B, n):
        st, u, r = sims[B]
        t0 = now()
        for _ in range(n):
            control_period_compiled(st.x, st.z, st.gamma, st.gamma_s, st.v, st.x_r, u, r, params)
        return n * B / (now() - t0)
    run_single(300); run_vec(3); run_sim(1, 10); run_sim(batch, 1)
    return {"single": run_single, "vec": run_vec, "sim1": lambda n: run_sim(1, n), "simB": lambda n: run_sim(batch, n)}

import dobs_envs
print(json.dumps({"file": dobs_envs.__file__}), flush=True)
runs = None
for line in sys.stdin:
    cmd = line.split()
    if cmd[0] == "digest":
        print(json.dumps(digest()), flush=True)
    elif cmd[0] == "setup":
        runs = speed_setup(cmd[1], int(cmd[2]), cmd[3])
        print(json.dumps("ok"), flush=True)
    else:
        print(json.dumps(runs[cmd[0]](int(cmd[1]))), flush=True)
'''


class Worker:
    """A checkout's code in a subprocess (that checkout first on sys.path, its own numba cache)."""

    def __init__(self, checkout: str):
        checkout = os.path.abspath(checkout)
        cache = os.path.join(tempfile.gettempdir(), "dobs_bench_numba_" + checkout.strip("/").replace("/", "_"))
        env = dict(os.environ, PYTHONPATH=checkout, PYTHONDONTWRITEBYTECODE="1", NUMBA_CACHE_DIR=cache)
        self.proc = subprocess.Popen([sys.executable, "-c", WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True, env=env, cwd=tempfile.gettempdir())
        self.file = self._read()["file"]

    def _read(self):
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("worker died (see its stderr above)")
        return json.loads(line)

    def ask(self, *cmd):
        self.proc.stdin.write(" ".join(str(c) for c in cmd) + "\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_base_argument(ap, what="reference checkout")
    ap.add_argument("--head", default=REPO, metavar="REF|PATH",
                    help="checkout compared with it, a directory or a git ref (default: this checkout)")
    ap.add_argument("--digest", action="store_true", help="compare the outputs bit for bit")
    ap.add_argument("--speed", action="store_true", help="compare the speed (the default without --digest)")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--seconds", type=float, default=0.4, help="length of one timed run")
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--pairs", type=int, default=1,
                    help="pairs of worker processes timed one after the other (--speed): the ratio of each pair and "
                         "their median (the speed of a compiled kernel varies from process to process)")
    ap.add_argument("--env-id", default="dobs_envs/Tracking-v0")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="time runs by the wall clock or by the worker's CPU time (process_time: on a loaded "
                         "machine, not the time the worker waits for a core; single-threaded runs only)")
    args = ap.parse_args(argv)
    if args.pairs < 1 or args.repeats < 1:
        ap.error(f"--pairs and --repeats must be positive integers, got {args.pairs} and {args.repeats}")
    speed = args.speed or not args.digest
    with contextlib.ExitStack() as stack:
        try:
            paths = {k: stack.enter_context(checkout(getattr(args, k))) for k in ("base", "head")}
        except ValueError as exc:
            ap.error(str(exc))
        return _compare(args, speed, paths)


def _compare(args, speed, paths):
    workers = {k: Worker(path) for k, path in paths.items()}
    for k, w in workers.items():
        print(f"{k}: {w.file}")
    status = 0
    if args.digest:
        dig = {k: w.ask("digest") for k, w in workers.items()}
        same = 0
        for name in dig["base"]:
            a, b = dig["base"][name], dig["head"].get(name)
            same += a == b
            print(f"  {'same' if a == b else 'DIFFERENT':9s} {name:45s} {a} {b}")
        print(f"bit for bit: {same} of {len(dig['base'])} runs identical")
        status = 0 if same == len(dig["base"]) else 1
    if speed:
        ratios = {what: [] for what, _ in SPEED_RUNS}
        for pair in range(args.pairs):
            if pair:  # a fresh pair of worker processes (the numba caches are warm by now)
                for w in workers.values():
                    w.close()
                workers = {k: Worker(path) for k, path in paths.items()}
            best = _speed_pair(args, workers, pair)
            print(f"{args.env_id}, pair {pair + 1} of {args.pairs}: best of {args.repeats} interleaved runs of "
                  f"~{args.seconds:g} s ({args.clock} clock)")
            for what, label in SPEED_RUNS:
                b, hd = best["base", what], best["head", what]
                ratios[what].append(hd / b)
                print(f"  {label.format(B=args.batch):40s} base {b:12,.0f}  head {hd:12,.0f}  head/base {hd / b:.3f}")
        if args.pairs > 1:
            import statistics

            print(f"head/base over {args.pairs} pairs of processes: median [min, max]")
            for what, label in SPEED_RUNS:
                r = ratios[what]
                print(f"  {label.format(B=args.batch):40s} {statistics.median(r):.3f} [{min(r):.3f}, {max(r):.3f}]  "
                      + " ".join(f"{x:.3f}" for x in r))
    for w in workers.values():
        w.close()
    return status


#: the timed runs of ``--speed``: (worker command, label)
SPEED_RUNS = (("single", "gym single env (steps/s)"), ("vec", "vector B={B} threads=1 (env-steps/s)"),
              ("sim1", "NE2 control period B=1 (periods/s)"), ("simB", "NE2 control period B={B} (copy-periods/s)"))


def _speed_pair(args, workers, pair):
    """Best rates of one pair of worker processes, interleaved, the order of the checkouts alternating
    (starting with the base in even pairs, the head in odd ones)."""
    for w in workers.values():
        w.ask("setup", args.env_id, args.batch, args.clock)
    steps = {}
    for k, w in workers.items():  # calibrate run lengths on the base
        steps[k, "single"] = max(3, int(w.ask("single", 300) * args.seconds))
        steps[k, "vec"] = max(3, int(w.ask("vec", 3) / args.batch * args.seconds))
        steps[k, "sim1"] = max(3, int(w.ask("sim1", 300) * args.seconds))
        steps[k, "simB"] = max(3, int(w.ask("simB", 3) / args.batch * args.seconds))
    for key in steps:
        steps[key] = steps["base", key[1]]
    best = dict.fromkeys(steps, 0.0)
    order = list(workers.items())
    for rep in range(args.repeats):  # interleaved, the order of the two checkouts alternating
        for what, _ in SPEED_RUNS:
            for k, w in (order if (rep + pair) % 2 == 0 else order[::-1]):
                best[k, what] = max(best[k, what], w.ask(what, steps[k, what]))
    return best

if __name__ == "__main__":
    sys.exit(main())
