"""Benchmark planning: the agent and budget tables, the runs an invocation trains
(:func:`plan_runs`) and what a stored run in ``<out>/models`` already answers
(:func:`stored_answer`, :func:`pending_runs`, :func:`reevaluated_runs`, :func:`replaced_runs`).

Nothing here trains or writes: the execution backends (:mod:`agents.benchmark.backends`) run the
work units of :mod:`agents.benchmark.tasks`, the driver (:func:`agents.benchmark.driver.run_benchmark`)
writes the records they return (:mod:`agents.benchmark.store`).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

from ..config.envs import ENVS, TASKS
from ..training.algos import LEGACY_LIBRARY, backend
from ..training.seeds import EVALUATION, TUNING, check_episode_seeds, check_training_seeds

__all__ = ["AGENTS", "BUDGETS", "TRAINERS", "AgentSpec", "default_agents", "BenchmarkPlan", "RunConflictError", "plan_runs", "pending_runs",
           "reevaluated_runs", "replaced_runs", "stored_answer", "ANALYTIC", "ANALYTIC_INFO", "PAPER", "CURVE_SEED",
           "TRAINING_KEYS", "RECIPE_SUFFIX", "agent_spec", "is_agent_name", "recipe_provenance"]


@dataclass(frozen=True)
class AgentSpec:
    """A benchmark agent: algorithm, parameter sharing, hybrid kind, label, extra training env options, trainer.

    ``trainer``: ``"sb3"`` (:func:`agents.training.train.train`, one task per run) or ``"jax"`` (the jitted trainer,
    :mod:`agents.training.jax`: an env's seeds of the agent vmapped in one task,
    :func:`agents.training.jax.vmap_seeds.train_jax_seeds`); ``counterpart``: a jitted agent's SB3 agent, whose env
    steps it trains in every budget (equal budgets: :data:`BUDGETS` is filled from it)."""

    algo: str
    multi_agent: bool
    hybrid: str | None
    label: str
    train_env_kwargs: tuple = ()
    trainer: str = "sb3"
    counterpart: str | None = None

    @property
    def kind(self) -> str:
        return "hybrid" if self.hybrid else "RL"

    @property
    def information(self) -> str:
        """What the agent observes (the table's information column)."""
        return INFO_OWN_NODE if self.multi_agent else INFO_POOLED

    @property
    def hp_key(self) -> str:
        """The key of a budget's ``hyperparams`` overrides the agent trains with: its algorithm (SB3), or
        ``<algo>_jax`` (the jitted trainer reads other keys)."""
        return self.algo if self.trainer == "sb3" else f"{self.algo}_{self.trainer}"

    @property
    def library(self) -> str:
        """What a stored run must have been trained by (``config.json`` ``library``) to be reused."""
        if self.trainer == "jax":
            from ..training.jax import LIBRARY

            return LIBRARY
        return backend(self.algo).library


AGENTS = {
    "ppo": AgentSpec("ppo", False, None, "PPO (centralised)"),
    "ppo_ma": AgentSpec("ppo", True, None, "PPO (shared, per node)"),
    "sac": AgentSpec("sac", False, None, "SAC (centralised)"),
    "td3": AgentSpec("td3", False, None, "TD3 (centralised)"),
    "crossq": AgentSpec("crossq", False, None, "CrossQ (centralised)"),
    "sac_ma": AgentSpec("sac", True, None, "SAC (shared, per node)"),
    "ppo_log": AgentSpec("ppo", False, None, "PPO (centralised, log-cost training)", (("reward", "log"),)),
    "ppo_sqrt": AgentSpec("ppo", False, None, "PPO (centralised, sqrt-cost training)", (("reward", "sqrt"),)),
    "ppo_res": AgentSpec("ppo", False, "residual", "residual PPO (centralised) [hybrid]"),
    "ppo_res_ma": AgentSpec("ppo", True, "residual", "residual PPO (shared) [hybrid]"),
    "ppo_bc": AgentSpec("ppo", False, "bc", "BC-warm-started PPO (centralised) [hybrid]"),
    # the jitted trainer (agents.training.jax; its algorithms: agents.training.jax.ALGOS)
    "ppo_jax": AgentSpec("ppo", False, None, "PPO (JAX)", trainer="jax", counterpart="ppo"),
    "ppo_ma_jax": AgentSpec("ppo", True, None, "PPO (JAX, shared)", trainer="jax", counterpart="ppo_ma"),
    "ppo_sqrt_jax": AgentSpec("ppo", False, None, "PPO (JAX, sqrt-cost training)", (("reward", "sqrt"),), trainer="jax",
                              counterpart="ppo_sqrt"),
    "sac_jax": AgentSpec("sac", False, None, "SAC (JAX)", trainer="jax", counterpart="sac"),
}
#: ``benchmark --trainer``: the learned rows of the default agent set (the analytic rows are always there)
TRAINERS = {"sb3": ("sb3",), "jax": ("jax",), "all": ("sb3", "jax")}

BUDGETS = {
    "tiny": {
        "episodes": 2, "seeds": 2, "env_kwargs": {"max_cycles": 20}, "curve_points": 2, "curve_episodes": 1,
        "agents": {"ppo": 256, "ppo_ma": 128, "ppo_res": 128, "ppo_bc": 128},
        "hyperparams": {
            "ppo": {"n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1, "bc": {"episodes": 1, "epochs": 1}},
            "sac": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
            "td3": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
            "crossq": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
            # the jitted agents' overrides: "<algo>_jax" (AgentSpec.hp_key)
            "ppo_jax": {"n_envs": 2, "n_steps": 64, "batch_size": 64, "n_epochs": 1},
            "sac_jax": {"learning_starts": 32, "batch_size": 32, "buffer_size": 1000},
        },
    },
    "quick": {
        "episodes": 10, "seeds": 3, "env_kwargs": {}, "curve_points": 6, "curve_episodes": 3,
        "agents": {"ppo": 400_000, "ppo_ma": 120_000, "ppo_res": 150_000, "ppo_bc": 150_000},
        "hyperparams": {},
    },
    "full": {
        "episodes": 20, "seeds": 10, "env_kwargs": {}, "curve_points": 10, "curve_episodes": 5,
        # sac_ma (SAC per node: 5 samples and gradient steps per env step, ~50 env steps/s) and
        # ppo_log (J/J_paper 21x and 67x at 400k on tracking) are available through --agents
        # the off-policy agents at PPO's env steps (issue 21: equal budgets)
        "agents": {"ppo": 600_000, "ppo_ma": 300_000, "ppo_sqrt": 600_000, "sac": 600_000, "td3": 600_000,
                   "crossq": 600_000, "ppo_res": 300_000, "ppo_res_ma": 150_000, "ppo_bc": 300_000},
        "hyperparams": {},
    },
}

# equal budgets: a jitted agent trains its SB3 counterpart's env steps wherever the budget trains that agent
for _b in BUDGETS.values():
    _b["agents"].update({k: _b["agents"][a.counterpart] for k, a in AGENTS.items()
                         if a.counterpart in _b["agents"]})
del _b


def default_agents(budget: str, trainer: str = "sb3") -> list[str]:
    """The agents ``budget`` trains by default with ``benchmark --trainer trainer`` (:data:`TRAINERS`): its agents
    trained by the selected trainers, in table order."""
    if trainer not in TRAINERS:
        raise ValueError(f"unknown trainer {trainer!r}; choose from {list(TRAINERS)}")
    return [k for k in BUDGETS[budget]["agents"] if AGENTS[k].trainer in TRAINERS[trainer]]


#: ``--recipe AGENT=FILE`` (:func:`plan_runs` ``recipes``) adds the agent ``AGENT + RECIPE_SUFFIX``: AGENT's
#: runs trained with the recipe file's section, in their own run directories, as a row of their own
RECIPE_SUFFIX = "@recipe"


def is_agent_name(name: str) -> bool:
    """Whether ``name`` is a benchmark agent: a key of :data:`AGENTS`, or one followed by :data:`RECIPE_SUFFIX`."""
    base = name[:-len(RECIPE_SUFFIX)] if name.endswith(RECIPE_SUFFIX) else name
    return base in AGENTS


def agent_spec(name: str) -> AgentSpec:
    """The :class:`AgentSpec` of the agent ``name`` (:func:`is_agent_name`): a recipe-file agent
    ``<agent>@recipe`` is its base agent with its own label."""
    if name.endswith(RECIPE_SUFFIX) and name[:-len(RECIPE_SUFFIX)] in AGENTS:
        a = AGENTS[name[:-len(RECIPE_SUFFIX)]]
        return AgentSpec(a.algo, a.multi_agent, a.hybrid, f"{a.label}, --recipe file", a.train_env_kwargs, a.trainer,
                         a.counterpart)
    return AGENTS[name]


def recipe_provenance(path: str) -> dict:
    """``{"file": path, "sha256": hex digest of its bytes}``: which recipe file a benchmark trained with."""
    import hashlib

    with open(path, "rb") as fh:
        return {"file": path, "sha256": hashlib.sha256(fh.read()).hexdigest()}


#: the information columns (what a policy observes)
INFO_POOLED = "pooled: every node's obs"
INFO_OWN_NODE = "own node + neighbours"
ANALYTIC_INFO = {"paper (separation)": "own observer's estimate",
                 "Kalman on pooled obs + paper law": INFO_POOLED,
                 "LQG on pooled obs (task's Q, R)": INFO_POOLED,
                 "oracle (full state)": "full state (privileged)",
                 "decentralised (no comm.)": "own measurement, no comm.", "zero input": "none"}
ANALYTIC = tuple(ANALYTIC_INFO)
PAPER = ANALYTIC[0]
#: learning-curve episodes use seeds CURVE_SEED + k (the tuning range, agents/training/seeds.py)
CURVE_SEED = TUNING.start


# ---------------------------------------------------------------------- what a stored run answers
def _run_signature(spec: dict) -> dict:
    return {k: spec[k] for k in ("env", "agent", "seed", "steps", "hp", "env_kwargs", "eval_seeds", "curve_seeds",
                                 "curve_every")}


TRAINING_KEYS = ("env", "agent", "seed", "steps", "hp", "env_kwargs", "curve_seeds", "curve_every")
"""The part of a run's signature that defines its training (the rest, ``eval_seeds``, its evaluation)."""


def _finished_run(path: str, sig: dict, hyperparams: dict, *, training_only: bool = False,
                  library: str | None = None) -> dict | None:
    """The stored result of the run in ``path`` if it finished with this signature *and* was trained
    with these merged hyperparameters (its ``config.json``): editing a recipe file retrains the
    affected runs instead of reusing results of the old recipe. None otherwise.

    ``library``: the run must also have been trained by this implementation (``config.json``
    ``library``; :data:`agents.training.algos.LEGACY_LIBRARY` for runs that record none), so that installing
    or removing the ``jax`` extra (SBX instead of SB3) never passes one library's result off as another's.

    ``training_only``: compare only the signature's :data:`TRAINING_KEYS` (the run was trained as
    ``sig`` asks, perhaps evaluated on other episodes)."""
    try:
        with open(os.path.join(path, "result.json")) as fh:
            prev = json.load(fh)
        with open(os.path.join(path, "config.json")) as fh:
            config = json.load(fh)
        trained_with = config.get("hyperparams")
    except (OSError, ValueError, AttributeError):
        return None
    if library is not None and config.get("library", LEGACY_LIBRARY) != library:
        return None
    old = prev.get("signature")
    if not isinstance(old, dict) or trained_with != json.loads(json.dumps(hyperparams)):
        return None
    keys = TRAINING_KEYS if training_only else tuple(sig)
    if set(old) != set(sig) or any(old[k] != sig[k] for k in keys):
        return None
    prev["cached"] = True
    return prev


def _training_overrides(spec: dict) -> dict:
    """The budget's hyperparameter overrides of a run plus its agent's training-only env options; a
    recipe-file agent's: its file's section with the budget's overrides over it (as over the shipped recipe)."""
    from ..training.recipes import merge_overrides

    a = agent_spec(spec["agent"])
    hp = merge_overrides(spec.get("recipe"), spec["hp"])
    extra = dict(a.train_env_kwargs)
    if a.trainer == "jax":  # the jitted trainer takes the benchmark's env options as the recipe's training options
        extra.update(jax_env_options(spec["env_kwargs"]))
    if extra:
        hp["env_kwargs"] = {**hp.get("env_kwargs", {}), **extra}
    return hp


def jax_env_options(env_kwargs: dict) -> dict:
    """The benchmark's env options (those of the PettingZoo envs) as options of :func:`dobs_envs.jax.make`: the
    episode length ``max_cycles`` as ``max_episode_steps`` (as :func:`agents.config.envs.gym_factory` gives it to the
    Gymnasium envs), the others as they are."""
    kw = dict(env_kwargs)
    if "max_cycles" in kw:
        kw["max_episode_steps"] = int(kw.pop("max_cycles"))
    return kw


def _stored_result(spec: dict, *, training_only: bool = False) -> dict | None:
    """The finished result of ``spec``'s run if it can be reused with today's recipe, else None
    (``training_only``: see :func:`_finished_run`)."""
    from ..training.recipes import resolve_recipe

    a = agent_spec(spec["agent"])
    recipe = resolve_recipe(a.algo, spec["env"], multi_agent=a.multi_agent, hybrid=a.hybrid,
                            overrides=_training_overrides(spec) or None, trainer=a.trainer)
    return _finished_run(spec["path"], _run_signature(spec), recipe.hyperparams, training_only=training_only,
                         library=a.library)


def _stored_model(spec: dict) -> dict | None:
    """The stored result of a run trained exactly as ``spec`` asks but evaluated on other episodes,
    if its model is kept (``model.zip``, and ``vecnormalize.pkl`` when it normalises; a jitted run: its exported
    policy, ``policy.npz`` + ``policy.json``): the benchmark evaluates that model again instead of training it
    again. None otherwise."""
    import zipfile

    prev = _stored_result(spec, training_only=True)
    if prev is None or prev["signature"] == _run_signature(spec):
        return None
    path = spec["path"]
    if agent_spec(spec["agent"]).trainer == "jax":
        from ..training.jax import POLICY_FILES

        return prev if all(os.path.isfile(os.path.join(path, f)) for f in POLICY_FILES) else None
    try:
        with open(os.path.join(path, "config.json")) as fh:
            normalize = bool(json.load(fh).get("normalize"))
    except (OSError, ValueError):
        return None
    model = os.path.join(path, "model.zip")
    if not (os.path.isfile(model) and zipfile.is_zipfile(model)):
        return None
    if normalize and not os.path.isfile(os.path.join(path, "vecnormalize.pkl")):
        return None
    return prev


#: what :func:`stored_answer` says of a run: reuse its stored result, evaluate its kept model again, train it
REUSE, REEVALUATE, TRAIN = "reuse", "reevaluate", "train"


def stored_answer(spec: dict) -> tuple[str, dict | None]:
    """What the stored run in ``spec['path']`` answers: ``(REUSE, result)`` (finished with this signature
    and today's recipe), ``(REEVALUATE, result)`` (trained as asked, its model kept, evaluated on other
    episodes: :func:`_stored_model`) or ``(TRAIN, None)``."""
    prev = _stored_result(spec)
    if prev is not None:
        return REUSE, prev
    prev = _stored_model(spec)
    if prev is not None:
        return REEVALUATE, prev
    return TRAIN, None


# ---------------------------------------------------------------------- the runs of an invocation
def _plan(budget: str, agents: list[str] | None, timesteps: int | None, seeds: int | None,
          recipes: dict | None = None, agent_seeds: dict | None = None,
          trainer: str = "sb3") -> tuple[dict, int, dict]:
    B = BUDGETS[budget]
    default = max(B["agents"].values())
    plan = {k: B["agents"][k] for k in default_agents(budget, trainer)}
    variants = [k + RECIPE_SUFFIX for k in recipes or {}]
    if agents is not None:
        unknown = sorted(set(agents) - set(AGENTS) - set(variants))
        if unknown:
            raise ValueError(f"unknown agents {unknown}; choose from {sorted(AGENTS)}"
                             + (f" or {sorted(variants)}" if variants else ""))
        # the budget's steps of each agent named, whichever trainer's default set it belongs to (agents the
        # budget does not list, e.g. sac_ma, train its longest)
        plan = {k: B["agents"].get(k, default) for k in agents if k not in variants}
    for v in variants:  # equal budgets: a recipe-file agent trains as many steps as its base agent
        base = v[:-len(RECIPE_SUFFIX)]
        plan[v] = B["agents"].get(base, default)
    if timesteps is not None:
        if timesteps < 1:
            raise ValueError(f"timesteps must be >= 1, got {timesteps}")
        plan = {k: int(timesteps) for k in plan}
    n_seeds = int(seeds if seeds is not None else B["seeds"])
    if n_seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    counts = {}
    for key, n in (agent_seeds or {}).items():
        if key not in plan:
            raise ValueError(f"agent_seeds names {key!r}, which this benchmark does not train; its agents: "
                             f"{sorted(plan)}")
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"agent_seeds[{key!r}] must be an integer >= 1, got {n!r}")
        if n != n_seeds:
            counts[key] = n
    return plan, n_seeds, counts


@dataclass(frozen=True)
class BenchmarkPlan:
    """What a benchmark invocation trains and evaluates (:func:`plan_runs`).

    ``specs`` holds one training run per (env, agent, training seed), longest first; a run's
    ``path`` is ``<out>/models/<env>/<budget>/<agent>/s<seed>``. ``recipes``: the recipe-file agents,
    ``{"<agent>@recipe": {"agent", "file", "sha256"}}`` (:func:`plan_runs`). ``training_seeds``: every
    agent's training seeds but those of ``agent_seeds`` (``{agent: its seeds}``, agents trained with
    another number of runs); :meth:`seeds_of` gives an agent's.
    """

    envs: list
    budget: str
    steps: dict
    training_seeds: list
    eval_seeds: list
    curve_seeds: list
    env_kwargs: dict
    specs: list
    recipes: dict = field(default_factory=dict)
    agent_seeds: dict = field(default_factory=dict)

    def seeds_of(self, agent: str) -> list:
        """The training seeds of ``agent`` (a key of ``steps``)."""
        return self.agent_seeds.get(agent, self.training_seeds)


def plan_runs(env: str = "tracking", budget: str = "quick", out: str = "runs/benchmark", *, seed: int = 0,
              eval_seed: int = 10_000, episodes: int | None = None, timesteps: int | None = None,
              agents: list[str] | None = None, seeds: int | None = None, threads: int | None = 1,
              recipes: dict | None = None, agent_seeds: dict | None = None, trainer: str = "sb3") -> BenchmarkPlan:
    """The runs :func:`run_benchmark` would train with these arguments (it validates them; nothing is
    written). With :func:`pending_runs` it tells which of them a stored result already answers.

    ``env``: a registered name (:data:`agents.config.envs.ENVS`) or ``"all"``: the fault-free tasks
    (:data:`agents.config.envs.TASKS`; an environment with faults on by default, ``tracking_lossy``, is one of
    them again under faults and is run by its name).

    ``seeds``: the number of training runs of every agent (``seed, seed + 1, ...``; default the
    budget's); ``agent_seeds``: ``{agent: number}`` for agents that train another number (e.g. 5 runs of
    an expensive agent beside 10 of the others: its table row then says 5 runs); each must be an agent
    of this benchmark (``<agent>@recipe`` included).

    ``recipes``: ``{agent: recipe file}`` (rl-zoo3 format, e.g. ``dobs-envs tune``'s ``best.yml``).
    Each adds the agent ``<agent>@recipe`` (:data:`RECIPE_SUFFIX`), trained as ``agent`` with its
    budget's steps, but with the file's section for the env (:func:`agents.training.recipes.recipe_file_section`:
    a shared-policy agent's ``<env>-ma`` if the file has one, else the Gymnasium id's, else ``default``; the
    budget's overrides apply over it as over the shipped
    recipe), in its own run directories ``<out>/models/<env>/<budget>/<agent>@recipe/s<seed>``: the
    shipped recipe's runs and the file's stand side by side in one table. ``agents`` may name
    ``<agent>@recipe`` (e.g. to train only the file's runs); otherwise it is added. Raises
    :class:`agents.config.hyperparam_files.HyperparamsError` (a ``ValueError``) when a file is missing, invalid or has
    no section for an env. Recipe files are for the SB3 agents (a jitted agent's: ``ValueError``).

    ``trainer`` (:data:`TRAINERS`): which learned agents the default set has (``agents`` not given): ``"sb3"`` the
    SB3 agents of the budget, ``"jax"`` the jitted ones (:class:`AgentSpec` ``trainer``), ``"all"`` both; ``agents``
    names any. A jitted agent's seeds of one env train as one task (vmapped, :mod:`agents.benchmark.tasks`); each
    seed is a run of its own, as an SB3 agent's."""
    if budget not in BUDGETS:
        raise ValueError(f"unknown budget {budget!r}; choose from {sorted(BUDGETS)}")
    env_names = list(TASKS) if env == "all" else [env]  # "all": the fault-free tasks (agents.config.envs.TASKS)
    for e in env_names:
        if e not in ENVS:
            raise ValueError(f"unknown env {e!r}; choose from {sorted(ENVS)} or 'all'")
    B = BUDGETS[budget]
    recipes = dict(recipes or {})
    bad = sorted(set(recipes) - set(AGENTS))
    if bad:
        raise ValueError(f"recipe files for unknown agents {bad}; choose from {sorted(AGENTS)}")
    jitted = sorted(k for k in recipes if AGENTS[k].trainer != "sb3")
    if jitted:
        raise ValueError(f"recipe files are for the SB3 agents; {jitted} train with the jitted trainer (give their "
                         f"recipe's keys in agents/config/hyperparams instead)")
    plan, n_seeds, counts = _plan(budget, agents, timesteps, seeds, recipes, agent_seeds, trainer)
    _check_jitted(plan)
    episodes = int(episodes or B["episodes"])
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    # the three seed ranges (agents/training/seeds.py): training seeds, evaluation episodes, tuning episodes
    check_training_seeds(seed, max([n_seeds, *counts.values()]), name="seed")
    eval_seeds = check_episode_seeds(eval_seed, episodes, EVALUATION, name="eval_seed")
    curve_seeds = check_episode_seeds(CURVE_SEED, B["curve_episodes"], TUNING, name="learning-curve seed")
    env_kwargs = dict(B["env_kwargs"])
    from ..training.recipes import merge_overrides, recipe_file_section

    # the files' sections, read and validated once per env (nothing named in a file is imported)
    sections = {(k, e): recipe_file_section(f, e, multi_agent=AGENTS[k].multi_agent) for k, f in recipes.items()
                for e in env_names}
    for (k, e), section in sections.items():
        _check_constructor_keys(k, e, recipes[k], merge_overrides(section, B["hyperparams"].get(AGENTS[k].algo)))
    provenance = {k + RECIPE_SUFFIX: {"agent": k, **recipe_provenance(f)} for k, f in recipes.items()}
    specs = []
    for e in env_names:
        for key, steps in plan.items():
            a = agent_spec(key)
            hp = dict(B["hyperparams"].get(a.hp_key, {}))
            extra = {}
            if key in provenance:  # not in the signature: the stored run's hyperparameters tell the recipe
                extra = {"recipe": sections[(provenance[key]["agent"], e)],
                         "recipe_file": {k: provenance[key][k] for k in ("file", "sha256")}}
            for s in range(seed, seed + counts.get(key, n_seeds)):
                specs.append({"env": e, "agent": key, "seed": s, "steps": int(steps), "hp": hp,
                              "env_kwargs": env_kwargs, "eval_seeds": eval_seeds, "curve_seeds": curve_seeds,
                              "curve_every": max(1, int(steps) // B["curve_points"]),
                              "curve_points": B["curve_points"], "threads": threads,
                              "path": os.path.join(out, "models", e, budget, key, f"s{s}"), **extra})
    # longest jobs first: better packing on the workers
    specs.sort(key=lambda sp: -sp["steps"] * (5 if agent_spec(sp["agent"]).multi_agent else 1))
    return BenchmarkPlan(env_names, budget, plan, list(range(seed, seed + n_seeds)), eval_seeds, curve_seeds,
                         env_kwargs, specs, provenance,
                         {k: list(range(seed, seed + n)) for k, n in counts.items()})


def _check_jitted(plan: dict) -> None:
    """``ValueError`` naming a planned jitted agent whose algorithm the jitted trainer does not implement
    (:data:`agents.training.jax.ALGOS`; read without importing JAX)."""
    from ..training.jax import ALGOS

    for key in plan:
        a = agent_spec(key)
        if a.trainer == "jax" and a.algo not in ALGOS:
            raise ValueError(f"agent {key!r}: the jitted trainer implements {list(ALGOS)}, not {a.algo!r}")


def _check_constructor_keys(agent: str, env: str, path: str, overrides: dict) -> None:
    """:class:`agents.config.hyperparam_files.HyperparamsError` naming the keys of the recipe file ``path`` that
    ``agent``'s algorithm class does not take, before anything trains (every run would fail the same way)."""
    import inspect

    from ..config.hyperparam_files import HyperparamsError
    from ..training.recipes import resolve_recipe

    a = AGENTS[agent]
    recipe = resolve_recipe(a.algo, env, multi_agent=a.multi_agent, hybrid=a.hybrid, overrides=overrides)
    cls = backend(a.algo).load_class()
    params = inspect.signature(cls.__init__).parameters
    unknown = sorted(set(recipe.algo_kwargs) - set(params))
    if unknown and not any(p.kind is p.VAR_KEYWORD for p in params.values()):
        raise HyperparamsError(f"{path}: {cls.__name__} ({agent}) takes no argument(s) {unknown} (its section for "
                               f"env {env!r})")


class RunConflictError(ValueError):
    """Training would replace finished runs of another configuration (``paths``; pass ``overwrite=True``)."""

    def __init__(self, out: str, paths: list[str]):
        self.out, self.paths = out, list(paths)
        super().__init__(f"{len(self.paths)} finished run(s) in {os.path.join(out, 'models')} were made with another "
                         f"configuration or recipe (first: {self.paths[0]}); training would replace them: pass "
                         f"overwrite=True or choose another out")


def replaced_runs(pending: list[dict]) -> list[dict]:
    """The specs among ``pending`` whose directory holds a finished result of another configuration
    or recipe: training them replaces that run."""
    return [sp for sp in pending if os.path.exists(os.path.join(sp["path"], "result.json"))]


def pending_runs(plan: BenchmarkPlan) -> list[dict]:
    """The specs of ``plan`` that would train: those without a finished result of the same signature
    and recipe (:func:`_finished_run`) and without a kept model trained as asked
    (:func:`reevaluated_runs`). ``[]`` means the benchmark trains nothing."""
    return [sp for sp in plan.specs if stored_answer(sp)[0] == TRAIN]


def reevaluated_runs(plan: BenchmarkPlan) -> list[dict]:
    """The specs of ``plan`` whose kept model was trained as asked but evaluated on other episodes
    (another ``eval_seed`` or ``episodes``): the benchmark evaluates it again, without training."""
    return [sp for sp in plan.specs if stored_answer(sp)[0] == REEVALUATE]


