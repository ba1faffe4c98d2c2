"""``dobs-envs train | evaluate | benchmark`` (registered by :mod:`dobs_envs.cli`)."""
from __future__ import annotations

import argparse
import json
import time

from .benchmark import AGENTS, BUDGETS
from .config import ALGOS, ENVS

__all__ = ["add_parser"]


def add_parser(sub) -> None:
    p = sub.add_parser("train", help="train an SB3 agent (PPO/SAC/TD3; shared PPO/SAC with --multi-agent)")
    p.add_argument("--env", default="tracking",
                   help="tracking | disturbance_rejection | hetero_mas | random_network, or a Gymnasium id")
    p.add_argument("--algo", choices=ALGOS, default="ppo")
    p.add_argument("--multi-agent", action="store_true",
                   help="one policy shared by all controller nodes on the PettingZoo env (ppo, sac)")
    p.add_argument("--timesteps", type=int, default=None,
                   help="environment steps (multi-agent: SB3 sees one sample per agent); default from the YAML")
    p.add_argument("--hybrid", choices=("residual", "bc"), default=None,
                   help="residual: learn a bounded correction of the paper's controller; bc: warm-start the actor "
                        "by behaviour cloning of the paper's controller (centralised PPO)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="run directory (default runs/<env>_<algo>[_ma]_s<seed>)")
    p.add_argument("--tensorboard", default=None, metavar="DIR", help="write TensorBoard logs to DIR")
    p.add_argument("--checkpoint-freq", type=int, default=None, help="env steps between checkpoints (0: none)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1: fastest for small MLPs)")
    p.add_argument("--hyperparams", default=None, help='JSON overrides, e.g. \'{"learning_rate": 1e-4}\'')
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--verbose", type=int, default=0)
    p.set_defaults(func=_train)

    p = sub.add_parser("evaluate", help="evaluate a trained run directory on seeded episodes")
    p.add_argument("--model", required=True, help="run directory (or its model.zip)")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--seed", type=int, default=10_000, help="episode k is reset with seed + k")
    p.add_argument("--json", default=None, help="also write the summary to this file")
    p.set_defaults(func=_evaluate)

    p = sub.add_parser("benchmark", help="RL and hybrid agents (several training seeds) vs the paper's controller, "
                                         "oracle, decentralised and zero input; IQM and bootstrap CIs")
    p.add_argument("--env", default="tracking", choices=sorted(ENVS) + ["all"])
    p.add_argument("--budget", choices=sorted(BUDGETS), default="quick")
    p.add_argument("--out", default="runs/benchmark")
    p.add_argument("--seed", type=int, default=0, help="first training seed (seeds seed, seed+1, ...)")
    p.add_argument("--seeds", type=_positive_int, default=None, help="number of training seeds (default: the budget's)")
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="parallel training processes (default: the number of CPU cores)")
    p.add_argument("--eval-seed", type=int, default=10_000, help="episode k of every policy is reset with eval_seed + k")
    p.add_argument("--episodes", type=_positive_int, default=None, help="evaluation episodes (default: the budget's)")
    p.add_argument("--timesteps", type=_positive_int, default=None, help="override every agent's training budget")
    p.add_argument("--agents", default=None, help=f"comma-separated subset of {','.join(AGENTS)}")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_benchmark)


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def _train(args) -> int:
    from .train import train

    hp = json.loads(args.hyperparams) if args.hyperparams else None
    res = train(args.env, args.algo, multi_agent=args.multi_agent, timesteps=args.timesteps, seed=args.seed,
                out=args.out, tensorboard=args.tensorboard, progress=not args.no_progress,
                checkpoint_freq=args.checkpoint_freq, hyperparams=hp, threads=args.threads, verbose=args.verbose,
                hybrid=args.hybrid)
    print(f"trained {res.config['algo']}{' (shared)' if res.config['multi_agent'] else ''} on {res.config['env']}: "
          f"{res.config['timesteps']} env steps in {res.seconds:.1f} s -> {res.path}")
    return 0


def _evaluate(args) -> int:
    from .evaluate import evaluate_model

    summ = evaluate_model(args.model, args.episodes, args.seed)
    for k, v in summ.items():
        if k != "seeds":
            print(f"{k:34s} {v}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(summ, fh, indent=2)
    return 0


def _benchmark(args) -> int:
    from .benchmark import run_benchmark

    t0 = time.perf_counter()
    agents = [a.strip() for a in args.agents.split(",")] if args.agents else None
    summ = run_benchmark(args.env, args.budget, args.out, seed=args.seed, eval_seed=args.eval_seed,
                         episodes=args.episodes, timesteps=args.timesteps, agents=agents, seeds=args.seeds,
                         workers=args.workers, progress=not args.no_progress)
    for env, table in summ["tables"].items():
        print()
        print(f"{env}, budget {args.budget}: training seeds {summ['training_seeds']}, evaluation episodes "
              f"{summ['eval_seeds'][0]}..{summ['eval_seeds'][-1]} (the same for every policy)")
        print(table)
    print(f"\nwrote {args.out}/summary.json, summary.png and <env>/results.{{csv,json}}, error_norms.png, "
          f"learning_curves.png; wall time {time.perf_counter() - t0:.0f} s")
    return 0
