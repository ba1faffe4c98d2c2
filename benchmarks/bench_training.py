"""SB3 PPO training throughput on ``dobs_envs/Tracking-v0`` versus ``Pendulum-v1``.

Both are trained in one process with identical settings (DummyVecEnv with the same
number of copies, n_steps, batch size, epochs, network, torch threads, no
normalisation), so the ratio ``tracking / pendulum`` isolates the environment's
cost: >= 0.8 means the simulator is not the bottleneck of RL training.

    python benchmarks/bench_training.py [--timesteps 16384] [--threads 1] [--repeats 2]
"""
from __future__ import annotations

import argparse
import time


def ppo_steps_per_second(env_id: str, timesteps: int, threads: int, seed: int = 0) -> float:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    import dobs_envs  # noqa: F401  (registers the dobs_envs/* ids)

    torch.set_num_threads(threads)
    venv = make_vec_env(env_id, n_envs=4, seed=seed)
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=64, n_epochs=10, seed=seed,
                policy_kwargs={"net_arch": [64, 64]}, verbose=0)
    model.learn(total_timesteps=1024)  # warm-up (numba compilation, first allocations)
    t0 = time.perf_counter()
    model.learn(total_timesteps=timesteps, reset_num_timesteps=True)
    dt = time.perf_counter() - t0
    venv.close()
    return model.num_timesteps / dt


def env_step_us(env_id: str, steps: int = 4000) -> float:
    """Raw ``gym.make(env_id).step`` cost (zero action, autoreset), microseconds."""
    import gymnasium as gym
    import numpy as np

    import dobs_envs  # noqa: F401

    env = gym.make(env_id)
    env.reset(seed=0)
    a = np.zeros(env.action_space.shape, dtype=np.float32)
    for k in range(steps + 200):
        if k == 200:
            t0 = time.perf_counter()
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    env.close()
    return (time.perf_counter() - t0) / steps * 1e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timesteps", type=int, default=16384)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=2, help="alternating repeats; the best of each is kept")
    ap.add_argument("--env", default="dobs_envs/Tracking-v0")
    args = ap.parse_args(argv)
    best = {args.env: 0.0, "Pendulum-v1": 0.0}
    for r in range(args.repeats):
        for env_id in (args.env, "Pendulum-v1"):
            sps = ppo_steps_per_second(env_id, args.timesteps, args.threads, seed=r)
            best[env_id] = max(best[env_id], sps)
            print(f"repeat {r}: {env_id:26s} {sps:8.0f} steps/s")
    ratio = best[args.env] / best["Pendulum-v1"]
    us = {e: env_step_us(e) for e in (args.env, "Pendulum-v1")}
    for e in us:
        share = us[e] / (1e6 / best[e])
        print(f"{e:26s} env.step {us[e]:6.1f} us = {share:.0%} of a PPO training step")
    print(f"PPO (n_envs=4, n_steps=256, batch=64, n_epochs=10, net=[64, 64], threads={args.threads}, "
          f"{args.timesteps} steps, best of {args.repeats})")
    print(f"{args.env}: {best[args.env]:.0f} steps/s   Pendulum-v1: {best['Pendulum-v1']:.0f} steps/s   "
          f"ratio {ratio:.2f} (goal >= 0.8)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
