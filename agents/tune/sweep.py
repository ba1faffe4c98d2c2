"""Vmapped hyperparameter sweep of the jitted PPO (:mod:`agents.training.jax.ppo`): hundreds of trials in
one compiled function per structure, scored on the tuning range.

A *structure* fixes what changes the shapes of a run (``n_envs``, ``n_steps``, ``batch_size``,
``n_epochs``, the network): it is one ``jax.jit`` of ``make_train``. Inside it, the float hyperparameters
of :data:`~agents.training.jax.ppo.HPARAMS` are traced, so ``jax.vmap`` runs ``draws`` points of the
float space times ``seeds`` training seeds side by side in one call. Trial 0 of every structure is the
recipe's own float values; the others are a scrambled Sobol sequence (:class:`scipy.stats.qmc.Sobol`)
mapped onto :data:`FLOAT_SPACE` (log-uniform where the range spans decades).

Each trained policy (the actor and observation statistics at the end of the run) is exported as the
numpy :class:`~agents.training.jax.numpy_policy.NumpyPolicy` and scored with the benchmark's harness
(:func:`agents.evaluate.run_episode`) on the task's compiled environment, on the tuning episodes
``TUNING.start + k`` (never an evaluation seed): a run's score is its mean ``J_policy / J_paper`` over
those episodes, a trial's score the mean over its training seeds (the metric of ``dobs-envs tune``,
:data:`agents.tune.spec.METRIC`; lower is better). The record (``sweep.json``) holds every trial (its
structure, float values, per-seed scores, CPU and wall time of its structure's compiled call) and the
winner; ``best.yml`` the winner as a recipe section in rl-zoo3's format, with the search space and the
winner's figures against trial 0 in its comments.

Usage: ``python -m agents.tune.sweep --env tracking --timesteps 600000 --structures FILE.json --draws 31
--seeds 2 --episodes 5 --out runs/sweep_tracking`` (``--structures``: a JSON list of dicts of the static
keys; default :data:`STRUCTURES`).
``--multi-agent`` sweeps the shared-policy PPO instead (:mod:`agents.training.jax.ippo`: one policy for every
controller node, each acting on its own node's observation, scored through the PettingZoo env as the
benchmark's "PPO (JAX, shared)" row); its ``best.yml`` is a ``<env>-ma-jax`` section for ``ppo.yaml``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

from ..training.seeds import TUNING, check_episode_seeds

__all__ = ["FLOAT_SPACE", "STRUCTURES", "STATIC_KEYS", "sample_floats", "run_sweep", "main"]

#: the float hyperparameters swept inside a structure: (kind, low, high); "log": log-uniform
FLOAT_SPACE = {
    "learning_rate": ("log", 1e-4, 3e-3),
    "clip_range": ("uniform", 0.1, 0.3),
    "gamma": ("uniform", 0.98, 0.999),
    "gae_lambda": ("uniform", 0.9, 0.99),
    "ent_coef": ("log", 1e-6, 1e-2),
    "log_std_init": ("uniform", -3.0, -1.0),
    "vf_coef": ("uniform", 0.25, 1.0),
    "max_grad_norm": ("log", 0.3, 3.0),
}
#: the recipe keys a structure may set (static under ``jit``: one compilation each)
STATIC_KEYS = ("n_envs", "n_steps", "batch_size", "n_epochs", "policy_kwargs")
#: default structures: more copies and fewer epochs than the shipped recipe (8 copies, 10 epochs), the
#: sizes at which the jitted run costs least per env step (benchmarks/bench_jax_train.py)
STRUCTURES = [
    {"n_envs": 64, "n_steps": 128, "batch_size": 1024, "n_epochs": 3},
    {"n_envs": 64, "n_steps": 256, "batch_size": 2048, "n_epochs": 4},
    {"n_envs": 128, "n_steps": 64, "batch_size": 1024, "n_epochs": 3},
]


def sample_floats(recipe_floats: dict, draws: int, seed: int) -> list[dict]:
    """``draws`` points of :data:`FLOAT_SPACE`: point 0 the recipe's own values (``recipe_floats``), the
    others a scrambled Sobol sequence (seeded) mapped onto the ranges."""
    from scipy.stats import qmc

    if draws < 1:
        raise ValueError(f"draws must be a positive integer, got {draws!r}")
    names = list(FLOAT_SPACE)
    out = [{k: float(recipe_floats[k]) for k in names}]
    if draws > 1:
        # the first draws - 1 points of the sequence (Sobol's balance holds for a power of 2: draws = 2^k + 1)
        u = qmc.Sobol(len(names), scramble=True, seed=seed).random_base2(math.ceil(math.log2(draws - 1)))[:draws - 1]
        for row in u:
            point = {}
            for k, x in zip(names, row):
                kind, lo, hi = FLOAT_SPACE[k]
                point[k] = float(math.exp(math.log(lo) + x * (math.log(hi) - math.log(lo))) if kind == "log"
                                 else lo + x * (hi - lo))
            out.append(point)
    return out


def _structure_recipe(base: dict, structure: dict) -> dict:
    bad = sorted(set(structure) - set(STATIC_KEYS))
    if bad:
        raise ValueError(f"structure keys {bad} are not static recipe keys; allowed: {list(STATIC_KEYS)}")
    hp = dict(base)
    for k, v in structure.items():
        hp[k] = dict(hp.get(k) or {}, **v) if k == "policy_kwargs" else v
    return hp


#: compiled vmapped trainings of this process by structure (:func:`compiled_vmap`), the least recently used first
_COMPILED: dict = {}
_COMPILED_KEEP = 4


def compiled_vmap(structure: tuple, train, keys, hps, hps_axis: int | None = 0) -> tuple:
    """``(run_all, times)``: ``jax.jit(jax.vmap(train, in_axes=(0, hps_axis)))`` compiled for ``keys`` and ``hps``
    (``hps_axis`` 0: a value per run, ``None``: one for every run), with the CPU and wall seconds of its
    compilation. ``structure`` names what fixes the compiled program (the algorithm, the env,
    ``repr`` of the run's static config): the float hyperparameters are traced arguments, so two candidates of one
    structure compile the same program, and the second one reuses the first one's (compile times 0,
    ``compile_reused``), as do the comparisons of :mod:`agents.tune.compare` (the last :data:`_COMPILED_KEEP`
    structures of the process are kept)."""
    import jax

    leaves = jax.tree_util.tree_leaves((keys, hps))
    key = (structure, hps_axis, bool(jax.config.jax_enable_x64), jax.tree_util.tree_structure((keys, hps)),
           tuple((np.shape(x), np.dtype(getattr(x, "dtype", None) or type(x)).str) for x in leaves))
    if key in _COMPILED:
        _COMPILED[key] = _COMPILED.pop(key)  # the most recent last
        return _COMPILED[key], {"compile_cpu_seconds": 0.0, "compile_wall_seconds": 0.0, "compile_reused": True}
    c0, w0 = time.process_time(), time.perf_counter()
    run_all = jax.jit(jax.vmap(train, in_axes=(0, hps_axis))).lower(keys, hps).compile()
    times = {"compile_cpu_seconds": time.process_time() - c0, "compile_wall_seconds": time.perf_counter() - w0}
    _COMPILED[key] = run_all
    while len(_COMPILED) > _COMPILED_KEEP:
        _COMPILED.pop(next(iter(_COMPILED)))
    return run_all, times


def _run_structure(env_name: str, hp: dict, timesteps: int, points: list[dict], seeds: list[int],
                   episode_seeds: list[int], paper: np.ndarray, dtype: str,
                   multi_agent: bool = False) -> tuple[np.ndarray, dict]:
    """``(scores (P, S), times)``: every point x training seed of one structure, trained in one vmapped
    compiled call, each run scored as its mean J/J_paper on ``episode_seeds``; ``times``: CPU and wall
    seconds of the compilation and of the compiled call. ``multi_agent``: ``hp`` is a shared-policy recipe,
    trained by :mod:`agents.training.jax.ippo` and scored through :class:`agents.vecenv.slots.SlotEncoder` on
    the PettingZoo env, as ``dobs-envs train --trainer jax --multi-agent`` runs are (its ``dtype`` is the
    recipe's)."""
    import jax
    import jax.numpy as jnp

    from ..config.envs import gym_factory, parallel_factory
    from ..training.jax.export import policy_arrays, select_run
    from ..training.jax.numpy_policy import NumpyPolicy
    from ..training.jax.ppo import HPARAMS
    from ..training.jax.run import jax_env

    _, jid = jax_env(env_name)
    if multi_agent:
        from ..training.jax.ippo import make_train as ippo_make_train
        from ..training.jax.run_marl import build_marl_run, shared_export
        from ..training.loading import slot_policy
        from ..vecenv.slots import SlotEncoder

        run = build_marl_run("ppo", env_name, jid, hp, timesteps)
        cfg, hp0 = run.cfg, run.hp
        train = ippo_make_train(cfg, run.env)
        env_np = parallel_factory(env_name, {})()
        agents = list(env_np.possible_agents)
        enc = SlotEncoder(agents, {a: env_np.observation_space(a) for a in agents},
                          {a: env_np.action_space(a) for a in agents}, agent_id=run.layout.agent_id,
                          rescale_actions=run.layout.rescale)
        cfg_p, space, _ = shared_export(cfg, run.layout)

        def policy(run_i, hp_i):
            return slot_policy(enc, NumpyPolicy.from_arrays(*policy_arrays(run_i, cfg_p, hp_i, space, None)))
    else:
        from ..training.jax.ppo import make_env, make_train, ppo_config

        cfg, hp0 = ppo_config(hp, jid, total_timesteps=timesteps, dtype=dtype)
        env, env_params = make_env(cfg)
        train = make_train(cfg, env, env_params)
        env_np = gym_factory(env_name, {})()

        def policy(run_i, hp_i):
            return NumpyPolicy.from_arrays(*policy_arrays(run_i, cfg, hp_i, env, env_params))
    P, S = len(points), len(seeds)
    hps = {k: jnp.asarray(np.repeat([p.get(k, hp0[k]) for p in points], S), jnp.float32)
           if k in FLOAT_SPACE else jnp.asarray(np.full(P * S, hp0[k]), jnp.float32) for k in HPARAMS}
    if "gamma" in FLOAT_SPACE and "gamma" not in (hp.get("normalize") or {}):
        hps["norm_gamma"] = hps["gamma"]  # VecNormalize's gamma follows the algorithm's unless the recipe sets it
    keys = jnp.stack([jax.random.PRNGKey(s) for s in np.tile(seeds, P)])
    run_all, times = compiled_vmap(("ppo", bool(multi_agent), env_name, repr(cfg)), train, keys, hps)
    c1, w1 = time.process_time(), time.perf_counter()
    result = jax.block_until_ready(run_all(keys, hps))
    times.update(cpu_seconds=time.process_time() - c1, wall_seconds=time.perf_counter() - w1)
    scores = score_runs(env_np, [policy(select_run(result, i), {k: float(hps[k][i]) for k in HPARAMS})
                                 for i in range(P * S)], episode_seeds, paper, parallel=multi_agent)
    env_np.close()
    return scores.reshape(P, S), times


def score_runs(env_np, policies: list, episode_seeds: list[int], paper: np.ndarray, *,
               parallel: bool = False) -> np.ndarray:
    """Each policy's score (module doc): its mean ``J_policy / J_paper`` over ``episode_seeds`` with the
    benchmark's harness (:func:`agents.evaluate.run_episode`) on ``env_np``; ``inf`` if an episode diverged."""
    from ..evaluate import run_episode

    scores = np.empty(len(policies))
    for i, pol in enumerate(policies):
        costs = np.array([run_episode(env_np, pol, s, parallel=parallel).cost for s in episode_seeds])
        ratio = costs / paper
        scores[i] = float(np.mean(ratio)) if np.all(np.isfinite(ratio)) else math.inf
    return scores


def run_sweep(env_name: str, *, timesteps: int, structures: list[dict] | None = None, draws: int = 16,
              seeds=(0, 1), episodes: int = 5, sampler_seed: int = 0, out: str, dtype: str = "float32",
              overwrite: bool = False, multi_agent: bool = False, log=print) -> dict:
    """Sweep the jitted PPO on ``env_name`` (module doc); writes ``out/sweep.json`` and ``out/best.yml`` and
    returns the record. The recipe is the jitted trainer's shipped PPO recipe of the env
    (:func:`agents.training.recipes.resolve_recipe` with ``trainer="jax"``), each structure's keys merged over it.
    ``multi_agent``: the shared-policy PPO (:mod:`agents.training.jax.ippo`, the recipe of ``dobs-envs train
    --trainer jax --multi-agent``); ``best.yml`` then holds the section ``<env>-ma-jax`` of ``ppo.yaml``."""
    from ..training.curves import paper_costs
    from ..training.recipes import resolve_recipe

    seeds = [int(s) for s in seeds]
    if not seeds or any(s < 0 for s in seeds):
        raise ValueError(f"seeds must be non-negative training seeds, got {seeds!r}")
    episode_seeds = check_episode_seeds(TUNING.start, episodes, TUNING, name="tuning episode seed")
    path = os.path.join(out, "sweep.json")
    if os.path.exists(path) and not overwrite:
        raise FileExistsError(f"{path} exists (a finished or interrupted sweep): choose another --out or pass "
                              "--overwrite")
    os.makedirs(out, exist_ok=True)
    # the jitted trainer's recipe: its sections too
    recipe = resolve_recipe("ppo", env_name, multi_agent=multi_agent, trainer="jax")
    base = dict(recipe.hyperparams)
    structures = [dict(s) for s in (structures or STRUCTURES)]
    paper = paper_costs(env_name, {}, episode_seeds)
    record = {"env": env_name, "algo": "ppo", "trainer": "jax", "timesteps": int(timesteps), "seeds": seeds,
              "episode_seeds": episode_seeds, "paper_cost": paper.tolist(), "float_space": FLOAT_SPACE,
              "draws": int(draws), "sampler_seed": int(sampler_seed), "recipe": base, "multi_agent": bool(multi_agent),
              "structures": [], "trials": [], "status": "running"}
    from ..training.jax.ippo import ippo_config
    from ..training.jax.ppo import ppo_config
    from ..training.jax.run import jax_env

    for j, structure in enumerate(structures):
        hp = _structure_recipe(base, structure)
        if multi_agent:
            _, hp0 = ippo_config(hp, env_name, total_timesteps=timesteps)
        else:
            _, hp0 = ppo_config(hp, jax_env(env_name)[1], total_timesteps=timesteps, dtype=dtype)
        points = sample_floats(hp0, draws, sampler_seed + j)
        log(f"structure {j + 1}/{len(structures)} {structure}: {len(points)} points x {len(seeds)} seeds")
        scores, times = _run_structure(env_name, hp, timesteps, points, seeds, episode_seeds, paper, dtype,
                                       multi_agent)
        record["structures"].append({"structure": structure, **times, "runs": len(points) * len(seeds)})
        for p, row in zip(points, scores):
            record["trials"].append({"trial": len(record["trials"]), "structure": j, "floats": p,
                                     "recipe_floats": p is points[0], "seed_scores": row.tolist(),
                                     "score": float(np.mean(row))})
        best_j = min(record["trials"][-len(points):], key=lambda t: t["score"])
        log(f"  compile {times['compile_cpu_seconds']:.0f} CPU s, training {times['cpu_seconds']:.0f} CPU s "
            f"({times['wall_seconds']:.0f} s); recipe floats {scores[0].mean():.4g}, best {best_j['score']:.4g}")
        _write_json(path, record)
    record["status"] = "complete"
    best = min(record["trials"], key=lambda t: t["score"])
    record["best"] = best
    _write_json(path, record)
    _write_best(os.path.join(out, "best.yml"), record, base, structures[best["structure"]], best)
    return record


def _write_json(path: str, doc: dict) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(doc, fh, indent=1, default=lambda x: None if isinstance(x, float) and not math.isfinite(x) else x)
    os.replace(tmp, path)


def _write_best(path: str, record: dict, base: dict, structure: dict, best: dict) -> None:
    import yaml

    from ..config.envs import gym_id

    hp = dict(_structure_recipe(base, structure), n_timesteps=record["timesteps"])
    for k, v in best["floats"].items():
        if k == "log_std_init":
            hp["policy_kwargs"] = dict(hp.get("policy_kwargs") or {}, log_std_init=v)
        elif k in ("learning_rate", "clip_range") and isinstance(base.get(k), str) and base[k].startswith("lin_"):
            hp[k] = f"lin_{v:.6g}"
        else:
            hp[k] = float(f"{v:.6g}")
    trial0 = [t for t in record["trials"] if t["structure"] == best["structure"] and t["recipe_floats"]][0]
    ranges = ", ".join(f"{k} {kind} [{lo:g}, {hi:g}]" for k, (kind, lo, hi) in FLOAT_SPACE.items())
    what = "shared-policy PPO" if record.get("multi_agent") else "PPO"
    lines = [f"# Jitted {what} recipe for {record['env']}, chosen by agents/tune/sweep.py on the tuning range",
             f"# (episodes {record['episode_seeds'][0]}-{record['episode_seeds'][-1]}, training seeds {record['seeds']}, "
             f"{record['timesteps']} env steps per run).",
             f"# Search space: structures {[s['structure'] for s in record['structures']]}; floats {ranges};",
             f"# {len(record['trials'])} trials ({record['draws']} per structure, trial 0 of each the shipped "
             f"recipe's floats), {sum(s['cpu_seconds'] for s in record['structures']):.0f} CPU s of training "
             f"(one core; compilation {sum(s['compile_cpu_seconds'] for s in record['structures']):.0f} CPU s).",
             f"# Winner: trial {best['trial']} score (mean J/J_paper) {best['score']:.4g}; the shipped recipe's "
             f"floats in the same structure: {trial0['score']:.4g}."]
    section = gym_id(record["env"])
    if record.get("multi_agent"):  # an agents-only section of agents/config/hyperparams/ppo.yaml (rl-zoo3 skips it)
        section = f"{record['env']}-ma-jax"
        lines.append(f"# The section {section} of agents/config/hyperparams/ppo.yaml (read by dobs-envs train "
                     "--trainer jax --multi-agent).")
    else:  # a section rl-zoo3 reads (train / compare --recipe FILE): its vocabulary
        from .outputs import recipe_section

        hp = recipe_section(hp)
        lines.append("# Its keys go over the jitted trainer's recipe with dobs-envs train --trainer jax --recipe FILE "
                     f"(or as the section {record['env']}-jax of agents/config/hyperparams/ppo.yaml).")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
        yaml.safe_dump({section: hp}, fh, sort_keys=False)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.tune.sweep",
                                 description=" ".join(__doc__.split("\n\n")[0].split()))  # the first paragraph
    ap.add_argument("--env", default="tracking")
    ap.add_argument("--timesteps", type=int, default=600_000)
    ap.add_argument("--structures", default=None, help="JSON file: a list of dicts of static recipe keys")
    ap.add_argument("--draws", type=int, default=16, help="float points per structure (point 0: the recipe's)")
    ap.add_argument("--seeds", type=int, default=2, help="training seeds 0 .. N-1 per point")
    ap.add_argument("--episodes", type=int, default=5, help="tuning episodes per run (from the tuning range)")
    ap.add_argument("--sampler-seed", type=int, default=0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--overwrite", action="store_true")
    ap.add_argument("--multi-agent", action="store_true", help="the shared-policy PPO (one policy for every "
                    "controller node, each acting on its own observation)")
    ap.add_argument("--threads", type=int, default=1, help="XLA threads (1: one core, as the benchmark's runs; 0: "
                    "XLA's default pool)")
    args = ap.parse_args(argv)
    from ..training.xla import xla_threads

    xla_threads(args.threads if args.threads > 0 else None)
    structures = None
    if args.structures:
        try:
            with open(args.structures) as fh:
                structures = json.load(fh)
        except (OSError, ValueError) as exc:
            ap.error(f"--structures: {exc}")
        if not isinstance(structures, list) or not all(isinstance(s, dict) for s in structures):
            ap.error("--structures must hold a JSON list of objects")
    try:
        run_sweep(args.env, timesteps=args.timesteps, structures=structures, draws=args.draws,
                  seeds=range(args.seeds), episodes=args.episodes, sampler_seed=args.sampler_seed, out=args.out,
                  overwrite=args.overwrite, multi_agent=args.multi_agent)
    except (ValueError, FileExistsError) as exc:
        ap.error(str(exc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
