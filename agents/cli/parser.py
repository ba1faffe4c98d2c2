"""The ``dobs-envs train | evaluate | benchmark | tune`` argument parsers (:func:`add_parser`, called by
:mod:`dobs_envs.cli`) and their argument types; each sub-command runs a function of :mod:`agents.cli.commands`."""
from __future__ import annotations

import argparse
import json

from ..benchmark.backends import BACKENDS
from ..benchmark.plan import AGENTS, BUDGETS, TRAINERS as BENCHMARK_TRAINERS
from ..config.envs import ENVS, FAULT_FREE, TASKS
from ..config.hyperparam_files import ALGOS
from ..training.seeds import EVALUATION, TRAINING, TUNING
from .commands import TRAINERS, benchmark_command, evaluate_command, train_command, tune_command

__all__ = ["add_parser"]



def add_parser(sub) -> None:
    p = sub.add_parser("train", help="train an agent (PPO/SAC/TD3/CrossQ; shared PPO/SAC with --multi-agent)")
    # defaults of the run's identity are None here (applied in train_command) so that --resume can tell
    # which options were given and check them against the run's config
    p.add_argument("--env", default=None,
                   help=f"{' | '.join(ENVS)} (default tracking), or a Gymnasium id")
    p.add_argument("--algo", choices=ALGOS, default=None, help="ppo (default) | sac | td3 | crossq (the off-policy algorithms train with SBX when the jax "
                        "extra is installed, else with stable-baselines3 / sb3-contrib)")
    p.add_argument("--trainer", choices=TRAINERS, default="sb3",
                   help="sb3 (default): Stable-Baselines3 / SBX on the compiled envs; jax: the jitted trainer "
                        "(agents.training.jax: the whole run one compiled function on dobs_envs.jax; --algo ppo | sac | "
                        "td3, with --multi-agent (ppo) one policy shared by the controller nodes; exports policy.npz + "
                        "policy.json)")
    p.add_argument("--multi-agent", action="store_true", default=None,
                   help="one policy shared by all controller nodes on the PettingZoo env (ppo, sac; --trainer jax: ppo)")
    p.add_argument("--timesteps", type=_positive_int, default=None,
                   help="environment steps (multi-agent: SB3 sees one sample per agent); default from the YAML")
    p.add_argument("--hybrid", choices=("residual", "bc"), default=None,
                   help="residual: learn a bounded correction of the paper's controller; bc: warm-start the actor "
                        "by behaviour cloning of the paper's controller (centralised PPO)")
    p.add_argument("--seed", type=_seed, default=None, help=f"training seed (default 0; the {TRAINING})")
    p.add_argument("--out", default=None, help="run directory (default runs/<env>_<algo>[_ma]_s<seed>)")
    p.add_argument("--tensorboard", default=None, metavar="DIR", help="write TensorBoard logs to DIR")
    p.add_argument("--checkpoint-freq", type=_nonnegative_int, default=None,
                   help="env steps between checkpoints (0: none)")
    p.add_argument("--threads", type=_positive_int, default=1, help="torch threads (default 1: fastest for small MLPs); 1 also runs XLA on one thread "
                        "(SBX, --trainer jax), more leaves XLA its default pool")
    p.add_argument("--hyperparams", type=_json_object, default=None,
                   help='JSON overrides, e.g. \'{"learning_rate": 1e-4}\'')
    p.add_argument("--recipe", default=None, metavar="FILE",
                   help="recipe file in rl-zoo3 format (e.g. dobs-envs tune's best.yml): its section for --env (the "
                        "Gymnasium id's, else default) replaces the recipe's keys; --hyperparams apply over it")
    p.add_argument("--overwrite", action="store_true", help="replace an existing run in --out")
    p.add_argument("--resume", default=None, metavar="DIR",
                   help="continue the interrupted run in DIR from its last save (model.zip after Ctrl-C, else the "
                        "last checkpoint) with the run's own configuration")
    p.add_argument("--allow-custom-env", action="store_true",
                   help="accept --env 'package.module:factory' (imports that module and calls the factory; with "
                        "--resume: the run's config.json may name one)")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--verbose", type=int, default=0)
    p.set_defaults(func=train_command)

    p = sub.add_parser("evaluate", help="evaluate a trained run directory on seeded episodes")
    p.add_argument("--model", required=True,
                   help="run directory (or its model.zip, or a checkpoint DIR/checkpoints/<algo>_<steps>_steps.zip), or "
                        "the directory of a jitted run (train --trainer jax: its policy.npz + policy.json)")
    p.add_argument("--episodes", type=_positive_int, default=10)
    p.add_argument("--seed", type=_seed, default=TUNING.start,
                   help=f"episode k is reset with seed + k (default {TUNING.start}: the {TUNING}, for tuning and "
                        f"model selection; the {EVALUATION} holds the benchmark's evaluation episodes)")
    p.add_argument("--json", default=None, help="also write the summary to this file (a new file; see --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    p.add_argument("--allow-custom-env", action="store_true",
                   help="accept a run whose config.json names 'package.module:factory' (imports that module and "
                        "calls the factory: only that; the run's pickles never run code either way: model.zip and "
                        "vecnormalize.pkl are read as data against an allow-list of what a run holds)")
    p.set_defaults(func=evaluate_command)

    p = sub.add_parser("benchmark", help="RL and hybrid agents (several training seeds) vs the paper's controller, "
                                         "oracle, decentralised and zero input; IQM and bootstrap CIs")
    p.add_argument("--env", default="tracking", choices=sorted(ENVS) + ["all"],
                   help=f"the environment, or all: the fault-free tasks ({', '.join(TASKS)}); an env with "
                        f"communication faults ({', '.join(FAULT_FREE)}) adds the degradation columns J / J_paper on "
                        f"its fault-free counterpart")
    p.add_argument("--budget", choices=sorted(BUDGETS), default="quick")
    p.add_argument("--out", default="runs/benchmark")
    p.add_argument("--seed", type=_seed, default=0, help="first training seed (seeds seed, seed+1, ...)")
    p.add_argument("--seeds", type=_positive_int, default=None, help="number of training seeds (default: the budget's)")
    p.add_argument("--agent-seeds", action="append", default=None, metavar="AGENT=N",
                   help="train AGENT with N training seeds instead (seed .. seed+N-1; its table row says N runs), "
                        "e.g. crossq=5 beside the budget's 10 for the others; repeatable (one per agent)")
    p.add_argument("--backend", choices=BACKENDS, default="process",
                   help="where runs train: process (default: --workers processes on this machine), serial (one after "
                        "another in this process) or ray (Ray tasks; needs the distributed extra)")
    p.add_argument("--address", default=None, metavar="ADDR",
                   help="with --backend ray: join the Ray cluster at ADDR (host:port, ray://host:port, or auto: the "
                        "cluster `ray start` runs on this machine); without it a local Ray sized to the machine "
                        "(or to --workers) is started and shut down afterwards")
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="parallel training processes (process backend) or CPUs of the local Ray (default: the number "
                        "of CPU cores)")
    p.add_argument("--eval-seed", type=_seed, default=EVALUATION.start,
                   help=f"episode k of every policy is reset with eval_seed + k (inside the {EVALUATION})")
    p.add_argument("--episodes", type=_positive_int, default=None, help="evaluation episodes (default: the budget's)")
    p.add_argument("--timesteps", type=_positive_int, default=None, help="override every agent's training budget")
    p.add_argument("--agents", default=None, help=f"comma-separated subset of {','.join(AGENTS)}")
    p.add_argument("--trainer", choices=tuple(BENCHMARK_TRAINERS), default=None,
                   help="the learned rows of the default agent set: sb3 (default: the Stable-Baselines3 / SBX agents), "
                        "jax (the jitted agents, agents.training.jax: each env's seeds of an agent vmapped in one "
                        "compiled run, each seed a run of the table) or all (both); the analytic rows are always "
                        "there; with --agents, the agents named must be of this trainer")
    p.add_argument("--recipe", action="append", default=None, metavar="AGENT=FILE",
                   help="also train AGENT with the recipe file FILE (rl-zoo3 format, e.g. dobs-envs tune's best.yml; "
                        "its section for the env: the Gymnasium id's, else default; the budget's overrides apply over "
                        "it) as the agent AGENT@recipe, with AGENT's budget, in run directories of its own and a "
                        "table row of its own next to AGENT's; repeatable (one file per agent); --agents may name "
                        "AGENT@recipe to train only the file's runs")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--overwrite", action="store_true",
                   help="retrain runs whose directory holds a finished run of another configuration or recipe "
                        "(removes those runs), and write into an --out that holds files the benchmark did not write "
                        "(agents.benchmark.store.foreign_entries); without it the benchmark refuses both")
    p.add_argument("--dry-run", action="store_true",
                   help="list the runs that would train, the kept models that would be evaluated again and the "
                        "stored results that are reused; train nothing")
    p.set_defaults(func=benchmark_command)

    p = sub.add_parser("tune", help="search a recipe's hyperparameters with Ray Tune (Optuna + ASHA), scored by "
                                    "J/J_paper on tuning episodes; writes best.yml (rl-zoo3 format) and trials.csv")
    # defaults of the study's definition are None here (applied in tune_command) so that --resume can tell which
    # options were given and check them against study.json
    p.add_argument("--env", default=None, choices=sorted(ENVS), help="environment (default tracking)")
    p.add_argument("--algo", choices=ALGOS, default=None, help="ppo (default) | sac | td3")
    p.add_argument("--trials", type=_positive_int, default=None, help="number of trials (default 24)")
    p.add_argument("--timesteps", type=_positive_int, default=None,
                   help="env steps per trial (default: the recipe's n_timesteps)")
    p.add_argument("--episodes", type=_positive_int, default=None,
                   help="tuning episodes per score (default 5): seeds --tune-seed, --tune-seed + 1, ...")
    p.add_argument("--tune-seed", type=_seed, default=None,
                   help=f"first tuning episode seed (default {TUNING.start}; inside the {TUNING}, never the "
                        f"{EVALUATION})")
    p.add_argument("--seed", type=_seed, default=None,
                   help=f"training seed of every trial and seed of Optuna's sampler (default 0; the {TRAINING})")
    p.add_argument("--report-points", type=_positive_int, default=None,
                   help="scores per trial along training, for ASHA's early stopping (default 6)")
    p.add_argument("--hyperparams", type=_json_object, default=None,
                   help="JSON overrides fixed for every trial (the searched values apply over them)")
    p.add_argument("--out", required=True, help="study directory (Tune experiment, trials.csv/png, best.yml)")
    p.add_argument("--backend", choices=("ray",), default="ray", help="ray (Ray Tune; the only backend)")
    p.add_argument("--address", default=None,
                   help="join a running Ray cluster (ray.init(address=...), e.g. 'auto' or 'host:6379'); default: "
                        "start a local Ray of --cpus CPUs")
    p.add_argument("--cpus", type=_positive_int, default=None, help="CPUs of the local Ray (default: all cores)")
    p.add_argument("--cpus-per-trial", type=_positive_int, default=None,
                   help="CPUs (and torch threads) per trial (default 1)")
    p.add_argument("--resume", action="store_true", help="continue the interrupted study in --out")
    p.add_argument("--overwrite", action="store_true", help="replace the study in --out")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=tune_command)


def _json_object(text: str) -> dict:
    def no_constant(name):
        raise ValueError(f"{name} is not a number JSON allows")

    try:
        v = json.loads(text, parse_constant=no_constant)
    except ValueError as exc:
        if not isinstance(exc, json.JSONDecodeError):
            raise argparse.ArgumentTypeError(f"not valid JSON ({exc}): {text!r}") from None
        raise argparse.ArgumentTypeError(f"not valid JSON ({exc.msg} at column {exc.colno}): {text!r}") from None
    if not isinstance(v, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object of hyperparameters, got {text!r}")
    return v


def _int_at_least(lo: int, what: str):
    """argparse type: an integer >= ``lo`` (the message says ``what`` was expected)."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"expected {what}, got {v}")
        return v

    return parse


_nonnegative_int = _int_at_least(0, "an integer >= 0")
_positive_int = _int_at_least(1, "a positive integer")
_seed = _int_at_least(0, "a seed: an integer >= 0")
