"""``dobs-envs train | evaluate | benchmark`` (registered by :mod:`dobs_envs.cli`)."""
from __future__ import annotations

import json
import time

from .benchmark import AGENTS, BUDGETS
from .config import ALGOS

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

    p = sub.add_parser("benchmark", help="RL agents vs the paper's controller, oracle, decentralised and zero input")
    p.add_argument("--env", default="tracking")
    p.add_argument("--budget", choices=sorted(BUDGETS), default="quick")
    p.add_argument("--out", default="runs/benchmark")
    p.add_argument("--seed", type=int, default=0, help="training seed")
    p.add_argument("--eval-seed", type=int, default=10_000, help="episode k of every policy is reset with eval_seed + k")
    p.add_argument("--episodes", type=int, default=None, help="evaluation episodes (default: the budget's)")
    p.add_argument("--timesteps", type=int, default=None, help="override every agent's training budget")
    p.add_argument("--agents", default=None, help=f"comma-separated subset of {','.join(AGENTS)}")
    p.add_argument("--tensorboard", default=None, metavar="DIR")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_benchmark)


def _train(args) -> int:
    from .train import train

    hp = json.loads(args.hyperparams) if args.hyperparams else None
    res = train(args.env, args.algo, multi_agent=args.multi_agent, timesteps=args.timesteps, seed=args.seed,
                out=args.out, tensorboard=args.tensorboard, progress=not args.no_progress,
                checkpoint_freq=args.checkpoint_freq, hyperparams=hp, threads=args.threads, verbose=args.verbose)
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
    doc = run_benchmark(args.env, args.budget, args.out, seed=args.seed, eval_seed=args.eval_seed,
                        episodes=args.episodes, timesteps=args.timesteps, agents=agents,
                        progress=not args.no_progress, tensorboard=args.tensorboard)
    print()
    print(f"{args.env}, budget {args.budget}: {doc['episodes']} episodes, seeds {doc['eval_seeds'][0]}.."
          f"{doc['eval_seeds'][-1]} (same for every policy); mean +- std")
    print(doc["table"])
    print(f"wrote {args.out}/results.csv, results.json, error_norms.png; wall time {time.perf_counter() - t0:.0f} s")
    return 0
