"""What ``dobs-envs train | evaluate | benchmark | tune`` do with their parsed arguments (:mod:`agents.cli.parser`):
one function per sub-command; usage errors are one line on stderr and exit status 2."""
from __future__ import annotations

import importlib.util
import json
import os
import sys
import time
from collections import Counter

from dobs_envs.paths import OutputPathError, check_output_dir, check_output_file

from ..benchmark.plan import AGENTS
from ..config.envs import ENVS
from ..training.seeds import TUNING, check_training_seeds

__all__ = ["TRAINERS", "train_command", "evaluate_command", "benchmark_command", "tune_command"]


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




#: ``train --trainer``: sb3 (Stable-Baselines3 / SBX, agents.training.train) or jax (agents.training.jax.run)
TRAINERS = ("sb3", "jax")
#: train options the jitted trainer does not take (argparse dest, option, whether it was given)
_NOT_JAX = (("resume", "--resume", lambda v: v is not None), ("hybrid", "--hybrid", lambda v: v is not None),
            ("tensorboard", "--tensorboard", lambda v: v is not None),
            ("checkpoint_freq", "--checkpoint-freq", lambda v: v is not None),
            ("allow_custom_env", "--allow-custom-env", bool), ("verbose", "--verbose", bool))
_JAX_OPTIONS = ("--algo ppo | sac | td3, --multi-agent (ppo), --env, --timesteps, --seed, --out, --hyperparams, "
                "--recipe, --threads, --overwrite, --no-progress")

#: the options that define a run (argparse dest, option, config.json key); --resume checks them
_RUN_OPTIONS = (("env", "--env", "env"), ("algo", "--algo", "algo"), ("multi_agent", "--multi-agent", "multi_agent"),
                ("hybrid", "--hybrid", "hybrid"), ("seed", "--seed", "seed"), ("timesteps", "--timesteps", "timesteps"),
                ("checkpoint_freq", "--checkpoint-freq", "checkpoint_freq"))


def _interrupted(out: str, exc: KeyboardInterrupt) -> None:
    """One line on stderr after Ctrl-C, exit status 130 (128 + SIGINT)."""
    from ..training.runs import RunDirError, resume_point
    from ..training.train import TrainingInterrupted

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


def train_command(args) -> int:
    from ..config.hyperparam_files import HyperparamsError
    from ..training.runs import default_run_dir
    from ..training.train import train

    if getattr(args, "trainer", "sb3") == "jax":
        return _train_jax(args)
    if args.resume is not None:
        return _resume(args)
    args.algo = args.algo or "ppo"
    env = _new_run_env(args)
    out = args.out or default_run_dir(env, args.algo, args.multi_agent, args.seed)
    _check_out_dir(out, "--out")
    _check_out_dir(args.tensorboard, "--tensorboard")
    if os.path.isdir(out) and os.listdir(out) and not args.overwrite:
        _usage_error(_occupied_run_dir(out))
    try:
        res = train(env, args.algo, multi_agent=args.multi_agent, timesteps=args.timesteps, seed=args.seed,
                    out=out, tensorboard=args.tensorboard, progress=not args.no_progress,
                    checkpoint_freq=args.checkpoint_freq, hyperparams=args.hyperparams, threads=args.threads,
                    verbose=args.verbose, hybrid=args.hybrid, callbacks=_curve(env, out))
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


def _curve(env: str, out: str) -> list:
    """The SB3 run's learning curve (``out/curve.json``, :func:`agents.training.curves.run_curve_callback`) as a
    callback list: empty for an env that is not one of the tasks."""
    from ..training.curves import run_curve_callback

    cb = run_curve_callback(env, out)
    return [] if cb is None else [cb]


def _new_run_env(args) -> str:
    """The checks of a new run's seed, env and ``--recipe`` (merged into ``args.hyperparams``); the env's name."""
    from ..config.envs import EnvNameError, check_env_name
    from ..config.hyperparam_files import HyperparamsError

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
        from ..training.recipes import merge_overrides, recipe_file_section

        try:
            section = recipe_file_section(args.recipe, env, multi_agent=args.multi_agent,
                                          trainer=getattr(args, "trainer", "sb3") or "sb3")
            args.hyperparams = merge_overrides(section, args.hyperparams)
        except HyperparamsError as exc:
            _usage_error(f"--recipe: {exc}")
    return env


def _train_jax(args) -> int:
    """``train --trainer jax``: the jitted trainer (:func:`agents.training.jax.run.train_jax`; with --multi-agent the
    shared policy, :func:`agents.training.jax.run_marl.train_jax_marl`); the SB3-only options are usage errors."""
    from ..config.hyperparam_files import HyperparamsError
    from ..training.jax import ALGOS
    from ..training.runs import default_run_dir

    for dest, opt, given in _NOT_JAX:
        if given(getattr(args, dest)):
            _usage_error(f"--trainer jax does not support {opt}; it supports {_JAX_OPTIONS}")
    args.algo = args.algo or "ppo"
    if args.algo not in ALGOS:
        _usage_error(f"--trainer jax implements --algo {' | '.join(ALGOS)}, not {args.algo} (use --trainer sb3 for "
                     f"{args.algo})")
    env = _new_run_env(args)
    from ..training.jax.run import JaxRunError, jax_env, train_jax

    try:
        env = jax_env(env)[0]
    except JaxRunError as exc:
        _usage_error(str(exc))
    out = args.out or default_run_dir(env, f"{args.algo}_jax", args.multi_agent, args.seed)
    _check_out_dir(out, "--out")
    if os.path.isdir(out) and os.listdir(out) and not args.overwrite:
        _usage_error(_occupied_run_dir(out))
    if args.multi_agent:
        from ..training.jax.run_marl import train_jax_marl as train_jax
    try:
        res = train_jax(env, args.algo, timesteps=args.timesteps, seed=args.seed, out=out,
                        hyperparams=args.hyperparams, threads=args.threads, progress=not args.no_progress)
    except (JaxRunError, HyperparamsError) as exc:
        _usage_error(str(exc))
    except KeyboardInterrupt as exc:
        _interrupted(out, exc)
    c = res.config
    print(f"trained {c['algo']} (jax{', shared' if c['multi_agent'] else ''}) on {c['env']}: {c['timesteps_done']} env "
          f"steps in {c['train_seconds']:.1f} s (compiled in {c['compile_seconds']:.1f} s) -> {res.path}")
    return 0


def _occupied_run_dir(out: str) -> str:
    """Why ``train --out`` refuses the non-empty directory ``out``: a run (its status, resumable or not)
    or other files (named), and the ways out."""
    from ..training.runs import RunDirError, read_run_config, resume_point

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
    from ..config.envs import EnvNameError, env_key
    from ..training.runs import RunDirError, read_run_config, resume_point
    from ..training.train import resume

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
                     tensorboard=args.tensorboard, allow_custom_env=args.allow_custom_env,
                     callbacks=_curve(env_key(str(cfg["env"])), run))
    except (EnvNameError, RunDirError) as exc:
        _usage_error(f"--resume: {exc}")
    except KeyboardInterrupt as exc:
        _interrupted(run, exc)
    r = res.config["resumes"][-1]
    print(f"resumed {res.config['algo']}{' (shared)' if res.config['multi_agent'] else ''} on {res.config['env']} "
          f"from {r['from']} ({r['timesteps_done']} env steps) to {res.config['timesteps']} env steps; "
          f"{res.seconds:.1f} s of training in all -> {res.path}")
    return 0


def evaluate_command(args) -> int:
    from ..config.envs import EnvNameError
    from ..training.loading import evaluate_model
    from ..training.runs import RunDirError

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


def benchmark_command(args) -> int:
    from ..benchmark.backends import RAY_EXTRA
    from ..benchmark.driver import run_benchmark
    from ..benchmark.plan import RunConflictError, plan_runs
    from ..benchmark.store import OutDirError, foreign_entries

    from ..benchmark.plan import RECIPE_SUFFIX, agent_spec, default_agents
    from ..benchmark.plan import TRAINERS as BENCHMARK_TRAINERS
    from ..config.hyperparam_files import HyperparamsError

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
    trainer = args.trainer or "sb3"
    if args.trainer is not None and agents is not None:
        other = [a for a in agents if agent_spec(a).trainer not in BENCHMARK_TRAINERS[trainer]]
        if other:
            _usage_error(f"--agents {','.join(other)}: not trained by --trainer {trainer} (its agents: "
                         f"{','.join(k for k in AGENTS if AGENTS[k].trainer in BENCHMARK_TRAINERS[trainer])}); "
                         f"drop --trainer to train the agents named")
    jitted_recipes = [k for k in recipes if AGENTS[k].trainer != "sb3"]
    if jitted_recipes:
        _usage_error(f"--recipe {jitted_recipes[0]}=...: recipe files are for the SB3 agents; "
                     f"{jitted_recipes[0]} trains with the jitted trainer")
    trained = agents if agents is not None else [*default_agents(args.budget, trainer),
                                                 *(k + RECIPE_SUFFIX for k in recipes)]
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
        from ..benchmark.backends import check_address

        try:
            check_address(args.address)
        except (ValueError, ConnectionError) as exc:
            _usage_error(f"--address: {exc}")
    try:  # the arguments argparse cannot check, as a usage error
        plan = plan_runs(args.env, args.budget, args.out, seed=args.seed, eval_seed=args.eval_seed,
                         episodes=args.episodes, timesteps=args.timesteps, agents=agents, seeds=args.seeds,
                         recipes=recipes, agent_seeds=agent_seeds, trainer=trainer)
    except HyperparamsError as exc:  # a recipe file without the env's section, or unreadable
        _usage_error(f"--recipe: {exc}")
    except ValueError as exc:
        _usage_error(str(exc))
    jitted = [k for k in plan.steps if agent_spec(k).trainer == "jax"]
    missing = [m for m in ("jax", "optax") if importlib.util.find_spec(m) is None]
    if jitted and missing and not args.dry_run:
        _usage_error(f"the jitted agents ({', '.join(jitted)}) need the jax extra ({missing[0]} is missing): "
                     f"pip install 'dobs-envs[jax]'")
    if args.dry_run:
        return _benchmark_dry_run(args, plan)
    try:
        summ = run_benchmark(args.env, args.budget, args.out, seed=args.seed, eval_seed=args.eval_seed,
                             episodes=args.episodes, timesteps=args.timesteps, agents=agents, seeds=args.seeds,
                             workers=args.workers, progress=not args.no_progress, overwrite=args.overwrite,
                             backend=args.backend, address=args.address, recipes=recipes,
                             agent_seeds=agent_seeds, trainer=trainer)
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
    from ..benchmark.plan import agent_spec, pending_runs, reevaluated_runs, replaced_runs

    todo, again = pending_runs(plan), reevaluated_runs(plan)
    clash = {sp["path"] for sp in replaced_runs(todo)}
    reused = len(plan.specs) - len(todo) - len(again)
    print(f"{len(todo)} of {len(plan.specs)} runs would train; {len(again)} kept models are evaluated again on "
          f"other episodes; {reused} stored results in {args.out}/models are reused (same configuration and recipe)")
    key = lambda sp: (sp["env"], sp["agent"], sp["seed"])  # noqa: E731
    for sp in sorted(todo, key=key):
        note = " (replaces a finished run of another configuration: needs --overwrite)" if sp["path"] in clash else ""
        if agent_spec(sp["agent"]).trainer == "jax":
            n = sum(o["env"] == sp["env"] and o["agent"] == sp["agent"] for o in todo)
            note += f" (jitted: {n} seeds in one vmapped task)" if n > 1 else " (jitted)"
        print(f"  train {sp['env']} {sp['agent']} seed {sp['seed']}: {sp['steps']} steps -> {sp['path']}{note}")
    for sp in sorted(again, key=key):
        print(f"  evaluate again {sp['env']} {sp['agent']} seed {sp['seed']} -> {sp['path']}")
    return 0


#: tune options that define a study: argparse dest -> (StudySpec field, default)
_TUNE_OPTIONS = {"env": ("env", "tracking"), "algo": ("algo", "ppo"), "trials": ("trials", 24),
                 "timesteps": ("timesteps", None), "episodes": ("episodes", 5), "tune_seed": ("tune_seed", TUNING.start),
                 "seed": ("seed", 0), "report_points": ("report_points", 6), "cpus_per_trial": ("cpus_per_trial", 1),
                 "hyperparams": ("hyperparams", {})}


def tune_command(args) -> int:
    """``dobs-envs tune``: a Ray Tune study (:mod:`agents.tune`)."""
    from ..config.hyperparam_files import HyperparamsError

    try:
        import optuna  # noqa: F401
        from ray import tune as _  # noqa: F401
    except ImportError as exc:
        _usage_error(f"tune needs Ray Tune and Optuna ({exc.name} is missing): pip install 'dobs-envs[distributed]'")
    from ..tune.spec import StudyDirError, StudySpec, stored_spec
    from ..tune.study import check_constructor_keys, run_study

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
                from ..training.recipes import resolve_recipe

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
