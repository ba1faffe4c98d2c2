"""The stored run records behind the published tables (``results/*.tar.gz``; the tables are in
``docs/results/*.md``) still answer the current benchmark: the documented command on them trains
nothing and gives the published tables, number by number (:mod:`readme_tables`)."""
from __future__ import annotations

import os
import tarfile

import pytest

from agents.benchmark.plan import pending_runs, plan_runs
from readme_tables import check_readme_table

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ARCHIVES = {
    # archive -> (env argument, budget, runs, {env: (docs page, heading of its table)}, --agents (None: the budget's))
    # the budget's nine agents: the six PPO-family ones (10 runs each), SAC, TD3 and CrossQ at PPO's step
    # count (5 runs each, AGENT_SEEDS)
    "hetero_mas_full_runs.tar.gz": ("hetero_mas", "full", 75,
                                    {"hetero_mas": ("docs/results/full_hetero_mas.md",
                                                    "## RL versus the paper's controller (full budget, hetero_mas)")},
                                    None),
    "quick_all_runs.tar.gz": ("all", "quick", 48,
                              {e: ("docs/results/quick.md", f"## {e} (quick budget)") for e in
                               ("tracking", "disturbance_rejection", "hetero_mas", "random_network")}, None),
    # issue 23: the faulted environment, the quick budget's agents
    "tracking_lossy_quick_runs.tar.gz": ("tracking_lossy", "quick", 12,
                                         {"tracking_lossy": ("docs/results/quick.md", "## tracking_lossy (quick budget)")}, None),
    # issue 22: the shipped PPO recipe (dobs-envs tune's best since 2026-12-05) and the former one (RECIPES), 10 runs each
    "hetero_mas_tuned_runs.tar.gz": ("hetero_mas", "full", 20,
                                     {"hetero_mas": ("docs/results/tuned_ppo.md",
                                                    "## The tuned PPO recipe on hetero_mas (full budget)")}, ["ppo"]),
    # the budget's nine agents: the six PPO-family ones, SAC, TD3 and CrossQ at PPO's step count
    # issue 40: the jitted PPO, 10 seeds vmapped in one call, with SB3's tracking recipe (chosen over the sweep's winner
    # on the tuning range, ppo.yaml)
    # + the jitted shared PPO and the jitted SAC (SB3/SBX's tracking recipes), 10 seeds vmapped each, and the jitted PPO
    # trained on the sqrt cost (ppo_sqrt_jax: the jitted PPO's recipe of the env, as ppo_sqrt takes PPO's)
    "tracking_full_jax_runs.tar.gz": ("tracking", "full", 40,
                                      {"tracking": ("docs/results/full_tracking_jax.md",
                                                    "## The jitted agents (full budget, tracking)")},
                                      ["ppo_jax", "ppo_ma_jax", "ppo_sqrt_jax", "sac_jax"]),
    # the jitted PPO, shared PPO and SAC with SB3's recipes (random_network: PPO with its section random_network-jax)
    "disturbance_rejection_full_jax_runs.tar.gz": ("disturbance_rejection", "full", 40,
                                                   {"disturbance_rejection": (
                                                       "docs/results/full_disturbance_rejection.md",
                                                       "## The jitted agents (full budget, disturbance_rejection)")},
                                                   ["ppo_jax", "ppo_ma_jax", "ppo_sqrt_jax", "sac_jax"]),
    "random_network_full_jax_runs.tar.gz": ("random_network", "full", 40,
                                            {"random_network": ("docs/results/full_random_network.md",
                                                                "## The jitted agents (full budget, random_network)")},
                                            ["ppo_jax", "ppo_ma_jax", "ppo_sqrt_jax", "sac_jax"]),
    "hetero_mas_full_jax_runs.tar.gz": ("hetero_mas", "full", 40,
                                        {"hetero_mas": ("docs/results/full_hetero_mas.md",
                                                        "## The jitted agents (full budget, hetero_mas)")},
                                        ["ppo_jax", "ppo_ma_jax", "ppo_sqrt_jax", "sac_jax"]),
    # the six PPO-family agents with SB3's recipes and SBX SAC, 10 runs each (TD3 and CrossQ not trained on these envs)
    "disturbance_rejection_full_runs.tar.gz": ("disturbance_rejection", "full", 70,
                                               {"disturbance_rejection": (
                                                   "docs/results/full_disturbance_rejection.md",
                                                   "## RL versus the paper's controller (full budget, disturbance_rejection)")},
                                               ["ppo", "ppo_ma", "ppo_sqrt", "ppo_res", "ppo_res_ma", "ppo_bc", "sac"]),
    "random_network_full_runs.tar.gz": ("random_network", "full", 70,
                                        {"random_network": ("docs/results/full_random_network.md",
                                                            "## RL versus the paper's controller (full budget, random_network)")},
                                        ["ppo", "ppo_ma", "ppo_sqrt", "ppo_res", "ppo_res_ma", "ppo_bc", "sac"]),
    "tracking_full_runs.tar.gz": ("tracking", "full", 90,
                                  {"tracking": ("docs/results/full_tracking.md",
                                                "## RL versus the paper's controller (full budget, tracking)")}, None),
}

#: ``--recipe AGENT=FILE`` of an archive's command (paths relative to the repository)
RECIPES = {"hetero_mas_tuned_runs.tar.gz": {"ppo": "results/hetero_mas_ppo_untuned.yml"}}
#: ``--agent-seeds AGENT=N`` of an archive's command
AGENT_SEEDS = {"hetero_mas_full_runs.tar.gz": {"sac": 5, "td3": 5, "crossq": 5}}


def _options(name: str) -> dict:
    """The archive's command options beyond env, budget and --agents, as plan_runs/run_benchmark take them."""
    r = RECIPES.get(name)
    return {"recipes": None if r is None else {k: os.path.join(ROOT, v) for k, v in r.items()},
            "agent_seeds": AGENT_SEEDS.get(name)}


@pytest.fixture(scope="module", autouse=True)
def analytic_rows_once():
    """Several archives hold runs of one env, budget and evaluation episodes (hetero_mas's three, tracking's two,
    ...), whose analytic rows are one computation: the driver's evaluation of the analytic controllers
    (:func:`agents.benchmark.tasks.analytic_results`, :func:`~agents.benchmark.tasks.fault_free_paper`, both
    deterministic in their arguments) runs once per argument tuple in this module, and every archive's table is
    checked against its (copied) payload."""
    import copy

    from agents.benchmark import driver

    saved = driver.analytic_results, driver.fault_free_paper

    def once(fn):
        memo = {}

        def call(env, env_kwargs, eval_seed, episodes):
            key = (env, repr(sorted(env_kwargs.items())), eval_seed, episodes)
            if key not in memo:
                memo[key] = fn(env, env_kwargs, eval_seed, episodes)
            return copy.deepcopy(memo[key])
        return call

    driver.analytic_results, driver.fault_free_paper = once(saved[0]), once(saved[1])
    yield
    driver.analytic_results, driver.fault_free_paper = saved


@pytest.fixture(scope="module", params=sorted(ARCHIVES))
def extracted(request, tmp_path_factory):
    name = request.param
    env, budget, _, _, _ = ARCHIVES[name]
    out = tmp_path_factory.mktemp(name.split(".")[0])
    with tarfile.open(os.path.join(ROOT, "results", name)) as tf:
        names = tf.getnames()
        assert all(n.split("/")[0] == "models" and (len(n.split("/")) < 3 or n.split("/")[2] == budget) for n in names)
        assert not any(n.endswith((".zip", ".pkl")) for n in names)  # records only: no pickles
        tf.extractall(out, filter="data")
    return name, str(out)


def test_every_stored_run_is_reused_with_todays_recipes(extracted):
    """A recipe edit that changes an agent's training makes its stored runs stale: the published tables
    would then no longer be what the command gives (retrain, re-archive)."""
    name, out = extracted
    env, budget, runs, _, agents = ARCHIVES[name]
    plan = plan_runs(env, budget, out, agents=agents, **_options(name))
    assert len(plan.specs) == runs
    assert [(sp["env"], sp["agent"], sp["seed"]) for sp in pending_runs(plan)] == []


def test_the_published_tables_are_what_the_stored_runs_give(extracted):
    """The documented command on the stored records (no training: every run is stored) gives the tables
    printed in ``docs/results``: the analytic controllers are evaluated again on the same seeded episodes,
    the statistics recomputed from the stored per-episode costs; numbers are compared, each with a
    tolerance suited to its quantity."""
    from agents.benchmark.driver import run_benchmark

    name, out = extracted
    env, budget, _, headings, agents = ARCHIVES[name]
    assert pending_runs(plan_runs(env, budget, out, agents=agents, **_options(name))) == []  # or hours of training
    run_benchmark(env, budget, out, workers=1, progress=False, agents=agents, **_options(name))
    for e, (page, heading) in headings.items():
        check_readme_table(page, heading, os.path.join(out, e, "results.json"))


def test_other_evaluation_episodes_would_retrain_and_are_refused(extracted):
    """The archives keep no models: evaluating on other episodes means training again, which would
    replace the stored records, so the benchmark refuses unless told to overwrite."""
    from agents.benchmark.driver import run_benchmark
    from agents.benchmark.plan import RunConflictError, reevaluated_runs, replaced_runs

    name, out = extracted
    env, budget, runs, _, agents = ARCHIVES[name]
    plan = plan_runs(env, budget, out, episodes=5, agents=agents, **_options(name))
    todo = pending_runs(plan)
    assert len(todo) == runs and len(replaced_runs(todo)) == runs and reevaluated_runs(plan) == []
    with pytest.raises(RunConflictError, match=f"{runs} finished run"):
        run_benchmark(env, budget, out, episodes=5, workers=1, progress=False, agents=agents, **_options(name))
    assert pending_runs(plan_runs(env, budget, out, agents=agents, **_options(name))) == []  # nothing was touched
