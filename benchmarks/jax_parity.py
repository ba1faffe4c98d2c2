"""The parity table of the JAX environments against the compiled core (float64).

For every environment x option set x action source (random inputs, bang-bang inputs beyond the bounds, the
paper's controller, a PPO policy trained briefly with SB3): an episode of the compiled core in which, at every
step, the JAX form advances the core's own state with the same input (:func:`dobs_envs.jax.parity.
one_step_episode`); the table gives the largest difference of every quantity relative to
``max(1, |value|)``, and the mismatched terminations / truncations / reason codes (0 expected). Then the
paper controller's free-running returns on the benchmark's evaluation episodes (seeds 10000-10019),
JAX against compiled, in float64 and float32. With communication faults (tracking_lossy and the fault rows)
also the fault state (held copies, snapshots, noise, C-O buffers) and the count of steps whose draws or
received flags differ (0 expected: the same counter-based generator).

    python benchmarks/jax_parity.py --steps 400 --episodes 20 --out results/jax_parity.json
    python benchmarks/jax_parity.py --faults --out results/jax_parity_faults.json
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import sys

import numpy as np

CASES = [
    ("tracking", {}), ("tracking", {"observation": "full", "reward": "log", "normalized_actions": True,
                                    "padded_observations": True}),
    ("disturbance_rejection", {}), ("disturbance_rejection", {"disturbance": "random", "reward": "sqrt"}),
    ("hetero_mas", {}), ("hetero_mas", {"state_bound": 30.0, "termination_penalty": False}),
    ("random_network", {}), ("random_network", {"padded_observations": True, "observation": "full"}),
    # communication faults: tracking_lossy's defaults, then the other keys on tracking
    ("tracking_lossy", {}),
    ("tracking", {"faults": {"oo_period": None, "oo_loss": 0.2, "oo_delay": 1, "co_loss": 0.1, "co_delay": 2}}),
    ("tracking", {"faults": {"oo_period": 0.01, "oo_burst": {"p_good_bad": 0.1, "p_bad_good": 0.3, "loss_good": 0.05},
                             "oo_delay": 2, "measurement_noise": 0.02}}),
]
#: the free-running comparison's environments
FREE_RUN = ("tracking", "disturbance_rejection", "hetero_mas", "random_network", "tracking_lossy")
SOURCES = ("random", "bang_bang", "paper", "trained")
COLUMNS = ("x", "z", "gamma", "gamma_s", "v", "x_r", "obs", "reward", "estimation_errors", "tracking_error",
           "task_error")


def _faulted(name: str, opts: dict) -> bool:
    return name == "tracking_lossy" or opts.get("faults") is not None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--episodes", type=int, default=20, help="evaluation episodes of the free-running comparison")
    ap.add_argument("--out", help="write the table as JSON (refuses to overwrite)")
    ap.add_argument("--faults", action="store_true", help="only the rows with communication faults")
    ap.add_argument("--sources", nargs="+", choices=SOURCES, default=list(SOURCES),
                    help="action sources of the one-step table (default: all)")
    ap.add_argument("--no-free-run", action="store_true", help="skip the free-running returns")
    a = ap.parse_args(argv)
    if a.out and os.path.exists(a.out):
        print(f"jax_parity: --out {a.out} exists; remove it or choose another path", file=sys.stderr)
        return 2
    import jax
    import jax.numpy as jnp

    from baselines.policies import SeparationPolicy
    from dobs_envs.jax import parity
    from dobs_envs.jax.env import _build
    from dobs_envs.registry import ENVIRONMENTS

    rows, free = [], []
    print("| env | options | actions | steps | " + " | ".join(COLUMNS) + " | ends | fault state | draws |")
    print("|" + "---|" * (len(COLUMNS) + 7))
    with jax.enable_x64(True):
        for name, opts in CASES:
            if a.faults and not _faulted(name, opts):
                continue
            entry = ENVIRONMENTS[name]
            structure, params, _ = _build(entry, dict(opts, dtype="float64"))
            mod = importlib.import_module(entry.module)
            for src in a.sources:
                rng = np.random.default_rng(7)
                core = entry.load_class().make_core(1, max_cycles=int(params.max_steps_in_episode), **opts)
                if src == "random":
                    inputs = lambda c, k, rng=rng: rng.uniform(-1.2, 1.2, c.n_inputs) * c.action_bound  # noqa: E731
                elif src == "bang_bang":
                    inputs = lambda c, k, rng=rng: 1.2 * c.action_bound * rng.choice([-1.0, 1.0], c.n_inputs)  # noqa: E731
                elif src == "trained":  # PPO trained briefly on the Gymnasium env (SB3, 2048 steps)
                    import gymnasium as gym
                    from stable_baselines3 import PPO

                    from dobs_envs.envs.adapter import CoreAdapter

                    model = PPO("MlpPolicy", gym.make(entry.gym_id, **opts), n_steps=512, batch_size=64, n_epochs=2,
                                seed=0, device="cpu").learn(2048)

                    def inputs(c, k, model=model):
                        ad = CoreAdapter(c)
                        a_, _ = model.predict(ad.central_observations(0), deterministic=True)
                        return ad.central_inputs(np.asarray(a_, dtype=np.float64))
                else:
                    pe = mod.parallel_env(**opts)
                    pol = SeparationPolicy(pe)

                    def inputs(c, k, pe=pe, pol=pol):
                        return pol.inputs({ag: c.observations[0, i, :w]
                                           for i, (ag, w) in enumerate(zip(pe.possible_agents, c.obs_widths))})
                w = parity.one_step_episode(core, structure, params, inputs, seed=10_000, steps=a.steps)
                rows.append({"env": name, "options": opts, "actions": src, **w})
                print(f"| {name} | {', '.join(f'{k}={v}' for k, v in opts.items()) or 'default'} | {src} | "
                      f"{w['steps']} | " + " | ".join(f"{w[c]:.1e}" for c in COLUMNS) + f" | {w['ends']} | "
                      + (f"{w['fault']:.1e} | {w['draws']} |" if "fault" in w else "- | - |"), flush=True)
    print("\npaper controller, free-running, evaluation episodes: largest |J_jax - J_compiled| / |J_compiled|")
    for name in () if a.no_free_run else FREE_RUN:
        if a.faults and not _faulted(name, {}):
            continue
        entry = ENVIRONMENTS[name]
        for dtype in ("float64", "float32"):
            # faults draw in 64-bit integers (dobs_envs.jax.faults): x64 on, the simulation in float32
            with jax.enable_x64(dtype == "float64" or name == "tracking_lossy"):
                structure, params, _ = _build(entry, {"dtype": dtype})
                penv = importlib.import_module(entry.module).parallel_env(max_cycles=int(params.max_steps_in_episode))
                rel = []
                for ep in range(a.episodes):
                    ra, rb, _ = parity.free_run_episode(penv, structure, params, SeparationPolicy, seed=10_000 + ep,
                                                        dtype=getattr(jnp, dtype))
                    rel.append(abs(rb - ra) / abs(ra))
            free.append({"env": name, "dtype": dtype, "episodes": a.episodes, "max_rel": max(rel),
                         "median_rel": float(np.median(rel))})
            print(f"{name:22s} {dtype}: max {max(rel):.1e}, median {np.median(rel):.1e} ({a.episodes} episodes)",
                  flush=True)
    if a.out:
        with open(a.out, "x") as f:
            json.dump({"one_step": rows, "free_run": free}, f, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
