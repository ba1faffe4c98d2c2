"""The benchmark: RL and hybrid agents versus the paper's controllers (``dobs-envs benchmark``).

:mod:`~agents.benchmark.driver` (:func:`~agents.benchmark.driver.run_benchmark`: plan, jobs, records, report),
:mod:`~agents.benchmark.plan` (agent and budget tables, what trains, what a stored run answers),
:mod:`~agents.benchmark.backends` (where jobs run: serial, process pool, Ray), :mod:`~agents.benchmark.tasks` (the
work units a worker runs), :mod:`~agents.benchmark.store` (the ``--out`` directory and the run records),
:mod:`~agents.benchmark.report` (aggregation, tables, figures); the statistics are :mod:`agents.stats`
(rliable's, with the training run as the unit; :mod:`~agents.benchmark.stats` re-exports them).

The public names of the module ``agents.benchmark`` before issue 38 (``from agents.benchmark import
run_benchmark``, ``agents.benchmark.foreign_entries``, ...) are still found here; they are imported on first use,
so that importing a part of the package does not import the driver.
"""
from .._moved import moved_names

#: name -> the module that defines it (the public names of the former module agents/benchmark.py)
_MOVED = {
    **dict.fromkeys(("run_benchmark",), "driver"),
    **dict.fromkeys(("AGENTS", "BUDGETS", "plan_runs", "pending_runs", "reevaluated_runs", "replaced_runs",
                     "BenchmarkPlan", "RunConflictError", "AgentSpec", "stored_answer"), "plan"),
    **dict.fromkeys(("format_table",), "report"),
    **dict.fromkeys(("BACKENDS",), "backends"),
    **dict.fromkeys(("OutDirError", "MARKER", "foreign_entries", "claim_out_dir"), "store"),
}

__getattr__, __dir__ = moved_names(__name__, _MOVED)
