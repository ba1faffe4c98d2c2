"""Choose between jitted PPO, SAC or TD3 recipes on the tuning range: each candidate trained with the same fresh training
seeds (vmapped, one compiled call per candidate) and scored on the same tuning episodes, as the sweep scores
its trials (:mod:`agents.tune.sweep`: a run's score is its mean ``J_policy / J_paper`` over the episodes
``TUNING.start + k``, never an evaluation seed).

A sweep picks its winner from many points on two seeds and a few episodes, so the winner's score is biased
low (the best of many noisy draws). Comparing a few finalists (the sweep's winner, the SB3 recipe run by the
jitted trainer, ...) on more seeds and episodes, seeds the sweep did not use, gives the choice the benchmark's
evaluation then tests.

Candidates (``NAME=SOURCE``):

- ``sb3``: SB3's shipped PPO recipe of the env (``agents/config/hyperparams/ppo.yaml`` without the jitted
  trainer's sections), run by the jitted trainer;
- ``jax``: the jitted trainer's shipped recipe (with its ``<env>-jax`` section);
- a recipe file (rl-zoo3 format, e.g. the sweep's ``best.yml``): its section for the env merged over the jitted
  trainer's recipe, as ``dobs-envs train --trainer jax --recipe FILE`` does.

``--multi-agent``: the shared-policy PPO's recipes (``dobs-envs train --multi-agent``'s sections), trained and
scored as :mod:`agents.tune.sweep` does with ``--multi-agent``.

``--algo sac`` or ``td3``: the off-policy recipes (``agents/config/hyperparams/<algo>.yaml``; ``sb3``: SBX's / SB3's
recipe, ``jax``: the same with the file's ``<env>-jax`` section, e.g. SAC's minibatch of 128 on tracking; the two
name the same recipe where the file has no such section), trained by
:mod:`agents.training.jax.sac` / ``td3`` vmapped over the seeds, each run's final deterministic policy scored as
above.

Usage: ``python -m agents.tune.compare --env tracking --candidate sb3=sb3 --candidate jax=jax --first-seed 100
--seeds 8 --episodes 10 --out runs/compare_tracking`` writes ``compare.json``: per candidate the recipe, the
per-seed scores, their mean, median and IQM, the CPU time; the winner (lowest mean); and per pair of candidates
the probability of improvement over seeds (rliable's definition: ``P(X < Y)`` over the runs' scores, lower
is better, ties counted half). Candidates that differ only in float hyperparameters (traced arguments of the
compiled run) share one compilation (:func:`agents.tune.sweep.compiled_vmap`): the later ones record compile
times of 0 and ``"compile_reused": true``.

``--resume``: go on with the ``compare.json`` already in ``--out`` (an interrupted comparison, or a finished one
given a new candidate): it must be the same comparison (env, algorithm, budget, training seeds, tuning episodes
and their paper costs). A candidate it holds under the same name with the same recipe is not trained again
(its entry is kept as it was, marked ``"resumed": true``); the same name with another recipe is an error. Every
candidate of the file is kept, and the probabilities of improvement and the winner are over all of them. The
trainers are deterministic for a given seed, recipe and code, so the scores are those a new run would give
while the code is unchanged (the file does not record the code's revision: resume from a record of the same
checkout).

``--part`` and ``--join DIR``: one comparison run in several processes (one per core), each training some of the
candidates: ``--part`` lets a process train a single candidate (its record has ``"status": "part"`` and no
statistics); ``--join DIR`` (repeatable) takes every candidate of the record in ``DIR``, which must be the same
comparison (as for ``--resume``), marked ``"joined_from": DIR``, and the statistics are over all of them:

    python -m agents.tune.compare --algo sac --env hetero_mas --candidate recipe=jax --part --out runs/cmp_a &
    python -m agents.tune.compare --algo sac --env hetero_mas --candidate b128=b128.yml --part --out runs/cmp_b
    python -m agents.tune.compare --algo sac --env hetero_mas --join runs/cmp_a --join runs/cmp_b --out runs/cmp

A name in two records must name the same recipe (the first record's entry is kept).
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

from ..stats import iqm, probability_of_improvement
from ..training.seeds import TUNING, check_episode_seeds, check_training_seeds

__all__ = ["ALGOS", "candidate_recipe", "compare_recipes", "main"]


#: the algorithms a comparison trains (the jitted trainer's; the shared policy is PPO's only)
ALGOS = ("ppo", "sac", "td3")


def candidate_recipe(source: str, env_name: str, multi_agent: bool = False, algo: str = "ppo") -> dict:
    """The merged hyperparameters of a candidate ``source`` (module doc: ``sb3``, ``jax`` or a recipe file) of
    ``algo``; ``multi_agent``: the shared-policy recipe (``dobs-envs train --multi-agent``'s sections)."""
    from ..training.recipes import recipe_file_section, resolve_recipe

    if algo not in ALGOS:
        raise ValueError(f"--algo {algo!r}: a comparison trains one of {', '.join(ALGOS)}")
    if multi_agent and algo != "ppo":
        raise ValueError(f"--multi-agent: the jitted shared policy is trained by PPO only, not {algo}")
    if source in ("sb3", "jax"):
        return dict(resolve_recipe(algo, env_name, multi_agent=multi_agent, trainer=source).hyperparams)
    return dict(resolve_recipe(algo, env_name, multi_agent=multi_agent, trainer="jax",
                               overrides=recipe_file_section(source, env_name, multi_agent=multi_agent,
                                                             trainer="jax")).hyperparams)


def _p_better(x: np.ndarray, y: np.ndarray) -> float:
    """``P(X < Y)`` for a run ``X`` of ``x`` and ``Y`` of ``y`` (:func:`agents.stats.probability_of_improvement`
    on one task). A diverged run scores ``inf`` (``nan`` is treated alike). The statistic depends on the order of
    the scores only, so ``inf`` is passed as the largest float: two diverged runs tie, as two ``inf`` would."""
    big = np.finfo(np.float64).max
    return probability_of_improvement(np.nan_to_num(x, nan=big, posinf=big)[:, None],
                                      np.nan_to_num(y, nan=big, posinf=big)[:, None])


def _run_offpolicy(env_name: str, algo: str, hp: dict, timesteps: int, seeds: list[int], episode_seeds: list[int],
                   paper: np.ndarray) -> tuple[np.ndarray, dict]:
    """``(scores (S,), times)`` of the off-policy ``algo`` with the merged recipe ``hp``: the training seeds run
    vmapped in one compiled call (:func:`agents.training.jax.run.build_run`'s run, as ``dobs-envs train --trainer
    jax`` builds it), each run's final policy scored by :func:`agents.tune.sweep.score_runs`; ``times`` as
    :func:`agents.tune.sweep._run_structure`'s."""
    import time

    import jax
    import jax.numpy as jnp

    from ..config.envs import gym_factory
    from ..training.jax.export import policy_arrays, select_run
    from ..training.jax.numpy_policy import NumpyPolicy
    from ..training.jax.run import build_run, enable_x64_for, jax_env
    from .sweep import compiled_vmap, score_runs

    env_name, gid = jax_env(env_name)
    enable_x64_for(env_name)
    run = build_run(algo, env_name, gid, hp, timesteps)
    train = run.make_train(run.cfg, run.env, run.env_params)
    keys = jnp.stack([jax.random.PRNGKey(s) for s in seeds])
    run_all, times = compiled_vmap((algo, env_name, repr(run.cfg)), train, keys, run.hp, hps_axis=None)
    c1, w1 = time.process_time(), time.perf_counter()
    result = jax.device_get(jax.block_until_ready(run_all(keys, run.hp)))
    times.update(cpu_seconds=time.process_time() - c1, wall_seconds=time.perf_counter() - w1)
    env_np = gym_factory(env_name, {})()
    policies = [NumpyPolicy.from_arrays(*policy_arrays(select_run(result, i), run.cfg, run.hp, run.env,
                                                       run.env_params)) for i in range(len(seeds))]
    scores = score_runs(env_np, policies, episode_seeds, paper)
    env_np.close()
    return scores, times


def _as_json(x):
    """``x`` as it reads back from the record (tuples as lists, ...), to compare a recipe with a stored one."""
    import json

    return json.loads(json.dumps(x))


def _resumed_record(path: str, record: dict, recipes: dict, flag: str = "--resume") -> dict:
    """The record at ``path`` checked to be the comparison ``record`` describes (:func:`compare_recipes`'s
    ``resume``, or ``join``: ``flag`` names the option in the errors), with its candidates; a candidate of
    ``recipes`` stored under its name with another recipe is an error."""
    import json

    try:
        with open(path) as fh:
            old = json.load(fh)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{flag}: cannot read {path}: {exc}") from None
    if not isinstance(old, dict) or not isinstance(old.get("candidates"), dict) or not all(
            isinstance(c, dict) for c in old["candidates"].values()):
        raise ValueError(f"{flag}: {path} is not a comparison record (no 'candidates')")
    for key in ("env", "algo", "multi_agent", "timesteps", "seeds", "episode_seeds"):
        if old.get(key) != record[key]:
            raise ValueError(f"{flag}: {path} is another comparison: its {key} is {old.get(key)!r}, this one's "
                             f"{record[key]!r}")
    try:
        stored = np.asarray(old.get("paper_cost", []), dtype=float)
    except (TypeError, ValueError):
        stored = np.zeros(0)
    if stored.shape != np.shape(record["paper_cost"]) or not np.allclose(stored, record["paper_cost"], rtol=1e-9,
                                                                         atol=0.0):
        raise ValueError(f"{flag}: the paper's costs on the tuning episodes differ from those of {path}: the "
                         "environments changed since, so its scores do not compare with new ones")
    for name, hp in recipes.items():
        prev = old["candidates"].get(name)
        if prev is not None and _as_json(prev.get("recipe")) != _as_json(hp):
            raise ValueError(f"--candidate {name}: {path} holds another recipe under that name; give this one "
                             "another name")
    return old


def _join(record: dict, recipes: dict, join, log) -> None:
    """Adds to ``record["candidates"]`` every candidate of the comparison records in the directories ``join``
    (checked as a resumed record is), each marked ``"joined_from"``; a name already held keeps its entry and must
    name the same recipe."""
    for d in join:
        old = _resumed_record(os.path.join(d, "compare.json"), record, recipes, flag="--join")
        for name, c in old["candidates"].items():
            held = record["candidates"].get(name)
            if held is not None:
                if _as_json(held.get("recipe")) != _as_json(c.get("recipe")):
                    raise ValueError(f"--join: candidate {name!r} of {d} has another recipe than the candidate "
                                     "of that name already held; rename one")
                continue
            if not isinstance(c.get("seed_scores"), list) or len(c["seed_scores"]) != len(record["seeds"]):
                raise ValueError(f"--join: candidate {name!r} of {d} has no score for each of the "
                                 f"{len(record['seeds'])} training seeds")
            record["candidates"][name] = {**{k: v for k, v in c.items() if k != "resumed"}, "joined_from": str(d)}
            log(f"candidate {name}: joined from {d}")


def compare_recipes(env_name: str, candidates: dict[str, str], *, timesteps: int, seeds, episodes: int, out: str,
                    dtype: str = "float32", overwrite: bool = False, resume: bool = False, multi_agent: bool = False,
                    algo: str = "ppo", part: bool = False, join=(), log=print) -> dict:
    """Train and score every candidate (``name -> source``, module doc) of ``algo`` on ``seeds`` and the first
    ``episodes`` tuning episodes; writes ``out/compare.json`` after each candidate (an interrupted comparison keeps
    the finished ones) and returns the record. ``multi_agent``: the shared-policy PPO (as :mod:`agents.tune.sweep`'s).
    ``dtype`` is PPO's (an off-policy recipe's run takes the recipe's). ``resume``: go on with ``out/compare.json``
    (module doc). ``part``: one process's share of a comparison (one candidate is enough; no statistics); ``join``:
    directories whose comparison records' candidates are taken in (module doc)."""
    from ..training.curves import paper_costs
    from .sweep import _run_structure, _write_json

    if overwrite and resume:
        raise ValueError("--overwrite and --resume: give one (replace the comparison in --out, or go on with it)")
    seeds = [int(s) for s in seeds]
    check_training_seeds(seeds[0], len(seeds), name="--first-seed")
    episode_seeds = check_episode_seeds(TUNING.start, episodes, TUNING, name="tuning episode seed")
    path = os.path.join(out, "compare.json")
    if resume and not os.path.exists(path):
        raise FileNotFoundError(f"--resume: no comparison to go on with ({path} does not exist)")
    if os.path.exists(path) and not (overwrite or resume):
        raise FileExistsError(f"{path} exists (a finished or interrupted comparison): choose another --out, pass "
                              "--resume to go on with it or --overwrite to replace it")
    join = [str(d) for d in join]
    if part and join:
        raise ValueError("--part and --join: give one (train a share of a comparison, or join the shares)")
    if len(set(join)) < len(join):
        raise ValueError("--join: a directory given twice")
    for d in join:
        if os.path.realpath(d) == os.path.realpath(out):
            raise ValueError(f"--join {d}: that is --out (to go on with the comparison in --out, pass --resume)")
        if not os.path.exists(os.path.join(d, "compare.json")):
            raise FileNotFoundError(f"--join: no comparison record in {d} ({os.path.join(d, 'compare.json')} does "
                                    "not exist)")
    if part and not candidates:
        raise ValueError("--part: give the candidate(s) this process trains")
    if not (resume or join or part) and len(candidates) < 2:
        raise ValueError(f"--candidate: give at least two candidates to compare, got {len(candidates)} (to train "
                         "one in each of several processes: --part, then --join)")
    # errors before training
    recipes = {name: candidate_recipe(src, env_name, multi_agent, algo) for name, src in candidates.items()}
    paper = paper_costs(env_name, {}, episode_seeds)
    record = {"env": env_name, "algo": algo, "trainer": "jax", "multi_agent": bool(multi_agent),
              "timesteps": int(timesteps), "seeds": seeds,
              "episode_seeds": episode_seeds, "paper_cost": paper.tolist(), "candidates": {}, "status": "running"}
    if resume:
        record["candidates"] = _resumed_record(path, record, recipes)["candidates"]
    _join(record, recipes, join, log)
    if not part and len(set(record["candidates"]) | set(recipes)) < 2:
        raise ValueError("--candidate: give at least two candidates to compare (with those of the records)")
    os.makedirs(out, exist_ok=True)
    for name, hp in recipes.items():
        if name in record["candidates"]:
            held = record["candidates"][name]
            if "joined_from" not in held:
                held["resumed"] = True
            log(f"candidate {name}: kept from {held.get('joined_from', path)} (same recipe, seeds and episodes)")
            continue
        log(f"candidate {name} ({candidates[name]}): {len(seeds)} seeds")
        if algo == "ppo":
            scores, times = _run_structure(env_name, hp, timesteps, [{}], seeds, episode_seeds, paper, dtype,
                                           multi_agent)
            s = scores[0]
        else:
            s, times = _run_offpolicy(env_name, algo, hp, timesteps, seeds, episode_seeds, paper)
        finite = s[np.isfinite(s)]
        record["candidates"][name] = {
            "source": candidates[name], "recipe": hp, "seed_scores": s.tolist(), **times,
            "mean": float(np.mean(s)), "median": float(np.median(s)),
            "iqm": float(iqm(s)) if finite.size == s.size else math.inf}
        log(f"  mean {np.mean(s):.4g}, median {np.median(s):.4g}, {times['cpu_seconds']:.0f} CPU s of training")
        _write_json(path, record)
    if part:
        record["status"] = "part"
        _write_json(path, record)
        log(f"{path}: a part of a comparison (no statistics); join it with --join {out}")
        return record
    names = list(record["candidates"])
    sc = {n: np.asarray([math.inf if v is None else v for v in record["candidates"][n]["seed_scores"]], dtype=float)
          for n in names}
    record["p_improvement"] = {f"{a} < {b}": _p_better(sc[a], sc[b]) for a in names for b in names if a != b}
    record["winner"] = min(names, key=lambda n: record["candidates"][n]["mean"])
    record["status"] = "complete"
    _write_json(path, record)
    return record


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.tune.compare",
                                 description=" ".join(__doc__.split("\n\n")[0].split()))  # the first paragraph
    ap.add_argument("--env", default="tracking")
    ap.add_argument("--algo", default="ppo", choices=ALGOS, help="the jitted trainer's algorithm (default ppo)")
    ap.add_argument("--candidate", action="append", default=[], metavar="NAME=SOURCE",
                    help="sb3, jax or a recipe file (module doc); repeat, at least two (with those of --resume, "
                    "--join)")
    ap.add_argument("--timesteps", type=int, default=600_000)
    ap.add_argument("--first-seed", type=int, default=100, help="training seeds first .. first + N - 1 (the "
                    "benchmark trains seeds 0-9, a sweep 0 .. its --seeds - 1)")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--episodes", type=int, default=10, help="tuning episodes per run (from the tuning range)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--overwrite", action="store_true", help="replace the comparison in --out")
    ap.add_argument("--resume", action="store_true", help="go on with the comparison in --out: train only the "
                    "candidates it does not hold (module doc)")
    ap.add_argument("--multi-agent", action="store_true", help="the shared-policy PPO's recipes")
    ap.add_argument("--part", action="store_true", help="train this process's share of a comparison run in "
                    "several processes (one candidate is enough; no statistics): join the shares with --join")
    ap.add_argument("--join", action="append", default=[], metavar="DIR", help="take in the candidates of the "
                    "comparison record in DIR (the same comparison); repeat")
    args = ap.parse_args(argv)
    from ..training.xla import xla_threads

    xla_threads(1)
    candidates = {}
    for item in args.candidate:
        name, sep, src = item.partition("=")
        if not sep or not name or not src:
            ap.error(f"--candidate {item!r}: expected NAME=SOURCE (SOURCE sb3, jax or a recipe file)")
        if name in candidates:
            ap.error(f"--candidate {name!r} given twice")
        candidates[name] = src
    if args.seeds < 1:
        ap.error(f"--seeds must be a positive integer, got {args.seeds}")
    from ..config.hyperparam_files import HyperparamsError

    try:
        compare_recipes(args.env, candidates, timesteps=args.timesteps,
                        seeds=range(args.first_seed, args.first_seed + args.seeds), episodes=args.episodes,
                        out=args.out, overwrite=args.overwrite, resume=args.resume, multi_agent=args.multi_agent,
                        algo=args.algo, part=args.part, join=args.join)
    except (ValueError, FileExistsError, FileNotFoundError, HyperparamsError) as exc:
        ap.error(str(exc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
