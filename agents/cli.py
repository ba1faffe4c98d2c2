"""``dobs-envs train | evaluate | benchmark | tune`` (registered by :mod:`dobs_envs.cli`)."""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time
from collections import Counter

from dobs_envs.paths import OutputPathError, check_output_dir, check_output_file

from .benchmark.backends import BACKENDS
from .benchmark.plan import AGENTS, BUDGETS
from .training.seeds import EVALUATION, TRAINING, TUNING, check_training_seeds
from .config.hyperparam_files import ALGOS
from .config.envs import ENVS, FAULT_FREE, TASKS

__all__ = ["add_parser"]


def add_parser(sub) -> None:
    p = sub.add_parser("train", help="train an agent (PPO/SAC/TD3/CrossQ; shared PPO/SAC with --multi-agent)")
    # defaults of the run's identity are None here (applied in _train) so that --resume can tell
    # which options were given and check them against the run's config
    p.add_argument("--env", default=None,
                   help=f"{' | '.join(ENVS)} (default tracking), or a Gymnasium id")
    p.add_argument("--algo", choices=ALGOS, default=None, help="ppo (default) | sac | td3 | crossq (the off-policy algorithms train with SBX when the jax "
                        "extra is installed, else with stable-baselines3 / sb3-contrib)")
    p.add_argument("--multi-agent", action="store_true", default=None,
                   help="one policy shared by all controller nodes on the PettingZoo env (ppo, sac)")
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
    p.add_argument("--threads", type=_positive_int, default=1, help="torch threads (default 1: fastest for small MLPs)")
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
    p.set_defaults(func=_train)

    p = sub.add_parser("evaluate", help="evaluate a trained run directory on seeded episodes")
    p.add_argument("--model", required=True,
                   help="run directory (or its model.zip, or a checkpoint DIR/checkpoints/<algo>_<steps>_steps.zip)")
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
    p.set_defaults(func=_evaluate)

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
    p.set_defaults(func=_benchmark)

    p = sub.add_parser("tune", help="search a recipe's hyperparameters with Ray Tune (Optuna + ASHA), scored by "
                                    "J/J_paper on tuning episodes; writes best.yml (rl-zoo3 format) and trials.csv")
    # defaults of the study's definition are None here (applied in _tune) so that --resume can tell which
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
    p.set_defaults(func=_tune)


def _usage_error(msg: str) -> None:
    """One line on stderr, exit status 2 (argparse's convention for usage errors)."""
    print(f"dobs-envs: error: {msg}", file=sys.stderr)
    raise SystemExit(2)


def _check_out_dir(path: str | None, option: str) -> None:
    """Usage error when the output directory ``path`` (None: not given) cannot be made
    (:func:`dobs_envs.paths.check_output_dir`: a regular file in the way)."""
    if path is not None:
        try:
            check_output_dir(path, option)
        except OutputPathError as exc:
            _usage_error(str(exc))


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


#: the options that define a run (argparse dest, option, config.json key); --resume checks them
_RUN_OPTIONS = (("env", "--env", "env"), ("algo", "--algo", "algo"), ("multi_agent", "--multi-agent", "multi_agent"),
                ("hybrid", "--hybrid", "hybrid"), ("seed", "--seed", "seed"), ("timesteps", "--timesteps", "timesteps"),
                ("checkpoint_freq", "--checkpoint-freq", "checkpoint_freq"))


def _interrupted(out: str, exc: KeyboardInterrupt) -> None:
    """One line on stderr after Ctrl-C, exit status 130 (128 + SIGINT)."""
    from .training.runs import RunDirError, resume_point
    from .training.train import TrainingInterrupted

    if isinstance(exc, TrainingInterrupted):
        msg = (f"interrupted after {exc.timesteps_done} of {exc.timesteps} env steps; model, normaliser and config "
               f"saved in {out}; resume with: dobs-envs train --resume {out}")
    else:
        try:
            resume_point(out)
            msg = f"aborted; resume from the run's last save with: dobs-envs train --resume {out}"
        except (RunDirError, OSError):
            msg = "aborted before anything was saved"
    print(f"dobs-envs: {msg}", file=sys.stderr)
    raise SystemExit(130)


def _hp_subset(given: dict, stored: dict, prefix: str = "") -> list[str]:
    """Keys of ``given`` (hyperparameter overrides) whose values differ from the run's ``stored`` ones."""
    diff = []
    for k, v in given.items():
        if isinstance(v, dict) and isinstance(stored.get(k), dict):
            diff += _hp_subset(v, stored[k], f"{prefix}{k}.")
        elif k not in stored or stored[k] != v:
            diff.append(f"{prefix}{k}={json.dumps(v)} (the run has {json.dumps(stored.get(k))})")
    return diff


def _train(args) -> int:
    from .config.envs import EnvNameError, check_env_name
    from .config.hyperparam_files import HyperparamsError
    from .training.runs import default_run_dir
    from .training.train import train

    if args.resume is not None:
        return _resume(args)
    args.algo = args.algo or "ppo"
    args.seed = 0 if args.seed is None else args.seed
    try:  # a training seed's env copies must not replay evaluation or tuning episodes (agents/training/seeds.py)
        check_training_seeds(args.seed, 1, name="--seed")
    except ValueError as exc:
        _usage_error(str(exc))
    args.multi_agent = bool(args.multi_agent)
    if args.env is not None and not args.env.strip():
        _usage_error(f"--env '': expected an env name ({', '.join(ENVS)}) or a Gymnasium id")
    try:
        env = check_env_name(args.env or "tracking", multi_agent=args.multi_agent, allow_custom=args.allow_custom_env,
                             what="--env")
    except EnvNameError as exc:
        _usage_error(str(exc))
    if args.recipe is not None:
        from .training.recipes import merge_overrides, recipe_file_section

        try:
            args.hyperparams = merge_overrides(recipe_file_section(args.recipe, env), args.hyperparams)
        except HyperparamsError as exc:
            _usage_error(f"--recipe: {exc}")
    out = args.out or default_run_dir(env, args.algo, args.multi_agent, args.seed)
    _check_out_dir(out, "--out")
    _check_out_dir(args.tensorboard, "--tensorboard")
    if os.path.isdir(out) and os.listdir(out) and not args.overwrite:
        _usage_error(_occupied_run_dir(out))
    try:
        res = train(env, args.algo, multi_agent=args.multi_agent, timesteps=args.timesteps, seed=args.seed,
                    out=out, tensorboard=args.tensorboard, progress=not args.no_progress,
                    checkpoint_freq=args.checkpoint_freq, hyperparams=args.hyperparams, threads=args.threads,
                    verbose=args.verbose, hybrid=args.hybrid)
    except TypeError as exc:  # an unknown hyperparameter reaches the SB3 constructor
        if "unexpected keyword argument" in str(exc):
            _usage_error(f"--hyperparams: {exc}")
        raise
    except HyperparamsError as exc:  # names its source: --hyperparams ("overrides") or the recipe file
        _usage_error(str(exc))
    except KeyboardInterrupt as exc:
        _interrupted(out, exc)
    print(f"trained {res.config['algo']}{' (shared)' if res.config['multi_agent'] else ''} on {res.config['env']}: "
          f"{res.config['timesteps']} env steps in {res.seconds:.1f} s -> {res.path}")
    return 0


def _occupied_run_dir(out: str) -> str:
    """Why ``train --out`` refuses the non-empty directory ``out``: a run (its status, resumable or not)
    or other files (named), and the ways out."""
    from .training.runs import RunDirError, read_run_config, resume_point

    if os.path.isfile(os.path.join(out, "config.json")):
        try:
            cfg = read_run_config(out, require_model=False)
        except RunDirError:
            cfg = None
        if cfg is not None:
            what = f"a {cfg.get('status', 'training')} {cfg['algo']} run on {cfg['env']}"
            try:
                resume_point(out, cfg)
                hint = f", --resume {out} to continue it"
            except (RunDirError, OSError):
                hint = ""
            return f"--out {out!r} already holds {what}; pass --overwrite to replace it{hint}, or choose another --out"
    entries = sorted(os.listdir(out))
    shown = ", ".join(entries[:5]) + (f" and {len(entries) - 5} more" if len(entries) > 5 else "")
    return (f"--out {out!r} is not empty and holds no run ({len(entries)} entr{'y' if len(entries) == 1 else 'ies'}: "
            f"{shown}); choose another --out, or pass --overwrite to train into it (a run's files are replaced, "
            f"other files are kept)")


def _resume(args) -> int:
    """``train --resume DIR``: the run's own configuration; options that define a run must agree with it."""
    from .config.envs import EnvNameError, env_key
    from .training.runs import RunDirError, read_run_config, resume_point
    from .training.train import resume

    run = args.resume
    if args.overwrite:
        _usage_error("--resume continues a run, --overwrite replaces it: give one of them")
    if args.recipe is not None:
        _usage_error("--resume continues a run with its own recipe (config.json); --recipe starts a new run")
    if args.out is not None and os.path.abspath(args.out) != os.path.abspath(run):
        _usage_error(f"--out {args.out!r} differs from --resume {run!r} (a resumed run stays in its directory)")
    _check_out_dir(args.tensorboard, "--tensorboard")
    try:
        cfg = read_run_config(run, require_model=False)
        resume_point(run, cfg)
    except RunDirError as exc:
        _usage_error(f"--resume: {exc}")
    diffs = []
    for dest, opt, key in _RUN_OPTIONS:
        given, stored = getattr(args, dest), cfg.get(key)
        if given is None:
            continue
        if dest == "env":
            given, stored = env_key(given), env_key(str(stored))
        if given != stored:
            diffs.append(f"{opt} {given} (the run has {stored})")
    if args.hyperparams:
        diffs += [f"--hyperparams {d}" for d in _hp_subset(args.hyperparams, cfg.get("hyperparams") or {})]
    if diffs:
        _usage_error(f"--resume {run}: the run's configuration differs: {'; '.join(diffs)} (omit these options to "
                     f"resume with the run's own, or start a new run in another --out)")
    try:
        res = resume(run, progress=not args.no_progress, threads=args.threads, verbose=args.verbose,
                     tensorboard=args.tensorboard, allow_custom_env=args.allow_custom_env)
    except (EnvNameError, RunDirError) as exc:
        _usage_error(f"--resume: {exc}")
    except KeyboardInterrupt as exc:
        _interrupted(run, exc)
    r = res.config["resumes"][-1]
    print(f"resumed {res.config['algo']}{' (shared)' if res.config['multi_agent'] else ''} on {res.config['env']} "
          f"from {r['from']} ({r['timesteps_done']} env steps) to {res.config['timesteps']} env steps; "
          f"{res.seconds:.1f} s of training in all -> {res.path}")
    return 0


def _evaluate(args) -> int:
    from .config.envs import EnvNameError
    from .training.loading import evaluate_model
    from .training.runs import RunDirError

    if args.json:
        try:
            check_output_file(args.json, "--json", overwrite=args.overwrite, example="eval.json")
        except OutputPathError as exc:
            _usage_error(str(exc))
    try:
        summ = evaluate_model(args.model, args.episodes, args.seed, allow_custom_env=args.allow_custom_env)
    except (RunDirError, EnvNameError) as exc:
        _usage_error(f"--model: {exc}")
    for k, v in summ.items():
        if k != "seeds":
            print(f"{k:34s} {v}")
    if args.json:  # atomic: an interrupted write never leaves a half-written file under the user's name
        with open(args.json + ".tmp", "w") as fh:
            json.dump(summ, fh, indent=2)
        os.replace(args.json + ".tmp", args.json)
    return 0


def _benchmark(args) -> int:
    from .benchmark.backends import RAY_EXTRA
    from .benchmark.driver import run_benchmark
    from .benchmark.plan import RunConflictError, plan_runs
    from .benchmark.store import OutDirError, foreign_entries

    from .benchmark.plan import RECIPE_SUFFIX
    from .config.hyperparam_files import HyperparamsError

    t0 = time.perf_counter()
    recipes = {}
    for item in args.recipe or []:
        name, sep, path = item.partition("=")
        name = name.strip()
        if not sep or not name or not path:
            _usage_error(f"--recipe {item!r}: expected AGENT=FILE, e.g. ppo=runs/tune/best.yml")
        if name not in AGENTS:
            _usage_error(f"--recipe {item!r}: unknown agent {name!r}; choose from {sorted(AGENTS)}")
        if name in recipes:
            _usage_error(f"--recipe: two files for agent {name!r} ({recipes[name]!r}, {path!r}); give one per agent")
        if not os.path.isfile(path):
            _usage_error(f"--recipe {item!r}: recipe file {path!r} does not exist")
        recipes[name] = path
    agent_seeds = {}
    for item in args.agent_seeds or []:
        name, sep, n = item.partition("=")
        name = name.strip()
        if not sep or not name or not n.strip().isdigit() or int(n) < 1:
            _usage_error(f"--agent-seeds {item!r}: expected AGENT=N with N >= 1, e.g. crossq=5")
        if name in agent_seeds:
            _usage_error(f"--agent-seeds: two numbers for agent {name!r}; give one per agent")
        agent_seeds[name] = int(n)
    agents = None
    if args.agents is not None:
        agents = [a.strip() for a in args.agents.split(",")]
        variants = [k + RECIPE_SUFFIX for k in recipes]
        unknown = [a for a in agents if a not in AGENTS and a not in variants]
        if not args.agents.strip():
            _usage_error(f"--agents '': expected a comma-separated subset of {','.join(AGENTS)}")
        if unknown:
            _usage_error(f"--agents: unknown agents {unknown}; choose from {sorted(AGENTS)}"
                         + (f" or {sorted(variants)}" if variants else " (AGENT@recipe needs --recipe AGENT=FILE)"))
    trained = agents if agents is not None else [*BUDGETS[args.budget]["agents"], *(k + RECIPE_SUFFIX for k in recipes)]
    for name in agent_seeds:
        if name not in trained:
            _usage_error(f"--agent-seeds names {name!r}, which this benchmark does not train; its agents: "
                         f"{','.join(trained)}")
    _check_out_dir(args.out, "--out")
    if args.address is not None and args.backend != "ray":
        _usage_error(f"--address names a Ray cluster: it needs --backend ray (got --backend {args.backend})")
    if args.address is not None and not args.address.strip():
        _usage_error("--address '': expected a Ray address (host:port, ray://host:port or auto)")
    if args.address is not None and args.workers is not None:
        _usage_error("--workers sizes the local Ray the benchmark starts; a cluster given by --address has its own "
                     "size: give one of them")
    if args.backend == "ray" and not args.dry_run and importlib.util.find_spec("ray") is None:
        _usage_error(f"--backend ray needs Ray: {RAY_EXTRA}")
    foreign = foreign_entries(args.out)
    if foreign and not args.overwrite:
        _usage_error(f"--out {OutDirError(args.out, foreign)}")
    if args.address is not None and not args.dry_run:
        from .benchmark.backends import check_address

        try:
            check_address(args.address)
        except (ValueError, ConnectionError) as exc:
            _usage_error(f"--address: {exc}")
    try:  # the arguments argparse cannot check, as a usage error
        plan = plan_runs(args.env, args.budget, args.out, seed=args.seed, eval_seed=args.eval_seed,
                         episodes=args.episodes, timesteps=args.timesteps, agents=agents, seeds=args.seeds,
                         recipes=recipes, agent_seeds=agent_seeds)
    except HyperparamsError as exc:  # a recipe file without the env's section, or unreadable
        _usage_error(f"--recipe: {exc}")
    except ValueError as exc:
        _usage_error(str(exc))
    if args.dry_run:
        return _benchmark_dry_run(args, plan)
    try:
        summ = run_benchmark(args.env, args.budget, args.out, seed=args.seed, eval_seed=args.eval_seed,
                             episodes=args.episodes, timesteps=args.timesteps, agents=agents, seeds=args.seeds,
                             workers=args.workers, progress=not args.no_progress, overwrite=args.overwrite,
                             backend=args.backend, address=args.address, recipes=recipes,
                             agent_seeds=agent_seeds)
    except OutDirError as exc:  # the directory changed since the check above
        _usage_error(f"--out {exc}")
    except ConnectionError as exc:  # --address: no Ray cluster there
        _usage_error(f"--address {args.address}: {exc}")
    except RunConflictError as exc:
        _usage_error(f"--out {args.out!r}: {len(exc.paths)} finished run(s) were made with another configuration "
                     f"or recipe (first: {exc.paths[0]}); pass --overwrite to retrain them or choose another --out")
    except KeyboardInterrupt:
        print(f"dobs-envs: benchmark interrupted; finished runs are kept in {args.out}/models (result.json) and "
              f"reused when the same command runs again", file=sys.stderr)
        raise SystemExit(130) from None
    for env, table in summ["tables"].items():
        print()
        other = "".join(f", {k}: {v}" for k, v in summ.get("agent_training_seeds", {}).items())
        print(f"{env}, budget {args.budget}: training seeds {summ['training_seeds']}{other}, evaluation episodes "
              f"{summ['eval_seeds'][0]}..{summ['eval_seeds'][-1]} (the same for every policy)")
        print(table)
        if env in summ.get("fault_free", {}):
            print(f"{env} has communication faults: J / J_paper,fault-free = J over the paper's controller's cost on "
                  f"{summ['fault_free'][env]} (no faults) on the same episodes (results.json: degradation_*)")
    for name, r in summ["recipe_files"].items():
        print(f"{name}: {r['label']} trained with {r['file']} (sha256 {r['sha256'][:12]}...)")
    nodes = Counter((w["host"], w["ray_node_id"]) for w in summ["executed_on"].values() if w)
    if len(nodes) > 1 or any(node for _, node in nodes):
        print("runs of this call executed on: " + "; ".join(
            f"{host}" + (f" (Ray node {node[:12]})" if node else "") + f": {n}" for (host, node), n in sorted(nodes.items(), key=str)))
    print(f"\nwrote {args.out}/summary.json, summary.png and <env>/results.{{csv,json}}, error_norms.png, "
          f"learning_curves.png; wall time {time.perf_counter() - t0:.0f} s")
    return 0


def _benchmark_dry_run(args, plan) -> int:
    """``benchmark --dry-run``: which runs would train, which stored results are reused (nothing written)."""
    from .benchmark.plan import pending_runs, reevaluated_runs, replaced_runs

    todo, again = pending_runs(plan), reevaluated_runs(plan)
    clash = {sp["path"] for sp in replaced_runs(todo)}
    reused = len(plan.specs) - len(todo) - len(again)
    print(f"{len(todo)} of {len(plan.specs)} runs would train; {len(again)} kept models are evaluated again on "
          f"other episodes; {reused} stored results in {args.out}/models are reused (same configuration and recipe)")
    key = lambda sp: (sp["env"], sp["agent"], sp["seed"])  # noqa: E731
    for sp in sorted(todo, key=key):
        note = " (replaces a finished run of another configuration: needs --overwrite)" if sp["path"] in clash else ""
        print(f"  train {sp['env']} {sp['agent']} seed {sp['seed']}: {sp['steps']} steps -> {sp['path']}{note}")
    for sp in sorted(again, key=key):
        print(f"  evaluate again {sp['env']} {sp['agent']} seed {sp['seed']} -> {sp['path']}")
    return 0


#: tune options that define a study: argparse dest -> (StudySpec field, default)
_TUNE_OPTIONS = {"env": ("env", "tracking"), "algo": ("algo", "ppo"), "trials": ("trials", 24),
                 "timesteps": ("timesteps", None), "episodes": ("episodes", 5), "tune_seed": ("tune_seed", TUNING.start),
                 "seed": ("seed", 0), "report_points": ("report_points", 6), "cpus_per_trial": ("cpus_per_trial", 1),
                 "hyperparams": ("hyperparams", {})}


def _tune(args) -> int:
    """``dobs-envs tune``: a Ray Tune study (:mod:`agents.tune`)."""
    from .config.hyperparam_files import HyperparamsError

    try:
        import optuna  # noqa: F401
        from ray import tune as _  # noqa: F401
    except ImportError as exc:
        _usage_error(f"tune needs Ray Tune and Optuna ({exc.name} is missing): pip install 'dobs-envs[distributed]'")
    from .tune.spec import StudyDirError, StudySpec, stored_spec
    from .tune.study import check_constructor_keys, run_study

    if args.resume and args.overwrite:
        _usage_error("--resume continues a study, --overwrite replaces it: give one of them")
    _check_out_dir(args.out, "--out")
    if args.address is not None and args.cpus is not None:
        _usage_error("--cpus sizes a local Ray; with --address the cluster's CPUs are used")
    given = {dest: getattr(args, dest) for dest in _TUNE_OPTIONS if getattr(args, dest) is not None}
    try:
        if args.resume:
            spec = stored_spec(args.out)
            diffs = [f"--{d.replace('_', '-')} {v} (the study has {getattr(spec, _TUNE_OPTIONS[d][0])})"
                     for d, v in given.items() if v != getattr(spec, _TUNE_OPTIONS[d][0])]
            if diffs:
                _usage_error(f"--resume {args.out}: the study's definition differs: {'; '.join(diffs)} (omit these "
                             f"options to resume it as it was, or start a new study in another --out)")
        else:
            kw = {field: given.get(dest, default) for dest, (field, default) in _TUNE_OPTIONS.items()}
            if kw["timesteps"] is None:
                from .training.recipes import resolve_recipe

                kw["timesteps"] = resolve_recipe(kw["algo"], kw["env"], overrides=kw["hyperparams"] or None).n_timesteps
            spec = StudySpec(**kw)
            spec.check()
            check_constructor_keys(spec)
    except (StudyDirError, HyperparamsError) as exc:
        _usage_error(f"--out {exc}" if isinstance(exc, StudyDirError) else f"--hyperparams: {exc}")
    except ValueError as exc:
        _usage_error(str(exc))
    try:
        res = run_study(spec, args.out, resume=args.resume, overwrite=args.overwrite, address=args.address,
                        cpus=args.cpus, progress=not args.no_progress)
    except StudyDirError as exc:
        _usage_error(f"--out {exc}")
    except KeyboardInterrupt:  # a second Ctrl-C: Ray was shut down by run_study's finally
        print(f"dobs-envs: tune aborted; finished trials are kept in {args.out}/study; continue with: "
              f"dobs-envs tune --resume --out {args.out}", file=sys.stderr)
        raise SystemExit(130) from None
    n = {s: sum(r["status"] == s for r in res.rows) for s in ("complete", "stopped early", "error", "unfinished")}
    summary = (f"{len(res.rows)} trials ({n['complete']} complete, {n['stopped early']} stopped early, {n['error']} "
               f"failed) in {res.seconds:.0f} s")
    if not res.complete:
        print(f"dobs-envs: tune interrupted: {summary}; finished trials are kept in {args.out}/study; continue "
              f"with: dobs-envs tune --resume --out {args.out}", file=sys.stderr)
        return 130
    if res.best is None:
        print(f"{summary}; no trial finished its budget: no best.yml (see {args.out}/trials.csv)")
        return 1
    print(f"{summary}; best trial {res.best['trial']}: score {res.best['score']:.4g} (mean J/J_paper on tuning "
          f"episodes {spec.episode_seeds[0]}-{spec.episode_seeds[-1]}) -> {args.out}/best.yml, trials.csv, trials.png")
    return 0
