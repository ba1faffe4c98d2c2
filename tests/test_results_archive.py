"""The stored full-budget run records (``results/hetero_mas_full_runs.tar.gz``) still answer today's
benchmark: the README's command on them trains nothing and regenerates the README's table."""
from __future__ import annotations

import os
import tarfile

import pytest

from agents.benchmark import pending_runs, plan_runs
from readme_tables import check_readme_table

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ARCHIVE = os.path.join(ROOT, "results", "hetero_mas_full_runs.tar.gz")


@pytest.fixture(scope="module")
def extracted(tmp_path_factory):
    out = tmp_path_factory.mktemp("full")
    with tarfile.open(ARCHIVE) as tf:
        names = tf.getnames()
        prefix = ["models", "hetero_mas", "full"]
        assert all(n.split("/")[:3] == prefix[:len(n.split("/"))] for n in names)
        assert not any(n.endswith((".zip", ".pkl")) for n in names)  # records only: no pickles
        tf.extractall(out, filter="data")
    return str(out)


def test_every_stored_run_is_reused_with_todays_recipes(extracted):
    """A recipe edit that changes a full-budget agent's training makes its stored runs stale: the
    README's hetero_mas table would then no longer be what the command gives (retrain, re-archive)."""
    plan = plan_runs("hetero_mas", "full", extracted)
    assert len(plan.specs) == 80
    assert [(sp["agent"], sp["seed"]) for sp in pending_runs(plan)] == []


def test_the_readme_table_is_what_the_stored_runs_give(extracted):
    """``dobs-envs benchmark --env hetero_mas --budget full --out <extracted>`` (no training: every run
    is stored) gives the table printed in the README: the analytic controllers are evaluated again on
    the same seeded episodes, the statistics recomputed from the stored per-episode costs. Numbers are
    compared, each with a tolerance suited to its quantity (:mod:`tests.readme_tables`)."""
    from agents.benchmark import run_benchmark

    assert pending_runs(plan_runs("hetero_mas", "full", extracted)) == []  # or this would train for hours
    run_benchmark("hetero_mas", "full", extracted, workers=1, progress=False)
    check_readme_table("### RL versus the paper's controller (full budget, hetero_mas)",
                       os.path.join(extracted, "hetero_mas", "results.json"))


def test_other_evaluation_episodes_would_retrain_and_are_refused(extracted):
    """The archive keeps no models: evaluating on other episodes means training again, which would
    replace the stored records, so the benchmark refuses unless told to overwrite."""
    from agents.benchmark import RunConflictError, reevaluated_runs, replaced_runs, run_benchmark

    plan = plan_runs("hetero_mas", "full", extracted, episodes=5)
    todo = pending_runs(plan)
    assert len(todo) == 80 and len(replaced_runs(todo)) == 80 and reevaluated_runs(plan) == []
    with pytest.raises(RunConflictError, match="80 finished run"):
        run_benchmark("hetero_mas", "full", extracted, episodes=5, workers=1, progress=False)
    assert pending_runs(plan_runs("hetero_mas", "full", extracted)) == []  # nothing was touched
