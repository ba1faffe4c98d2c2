"""RL and hybrid agents versus the paper's controllers, over training seeds, with confidence intervals.

``dobs-envs benchmark --env tracking --budget quick --out runs/benchmark``
(``--env all``: the fault-free tasks tracking, disturbance_rejection, hetero_mas, random_network;
``--env tracking_lossy``: tracking over a lossy observer network, with the degradation columns of step 3)

1. **Train** every agent of the budget with several training seeds, in parallel
   (``--backend``: worker processes by default, ``--workers`` of them, one per core; or Ray
   tasks on a local Ray or a cluster, :mod:`agents.benchmark.backends`): pure RL (centralised PPO,
   parameter-shared PPO; ``full`` adds SAC, TD3 and PPO trained on the sqrt cost) and the hybrids (residual PPO, centralised and shared; PPO warm-started by
   behaviour cloning), each with the recipe of ``agents/config/hyperparams/<algo>.yaml``; ``--recipe
   AGENT=FILE`` adds ``AGENT@recipe``, AGENT trained with a recipe file's section (e.g. ``dobs-envs
   tune``'s ``best.yml``) in run directories of its own, a row of its own next to AGENT's. ``--trainer jax``
   (``all``) gives the default set the jitted agents instead of (besides) the SB3 ones: "PPO (JAX)" and
   "PPO (JAX, shared)", each env's seeds of one of them one compiled run vmapped over the seeds, each seed a run.
   Each run records its learning curve (:mod:`agents.training.curves`). A finished run is
   reused when its configuration is identical (``<out>/models/<env>/<budget>/<agent>/s<seed>``),
   so an interrupted benchmark resumes where it stopped.
2. **Evaluate** every policy -- the trained agents, the paper's separation
   controller, the full-state oracle, the no-communication decentralised controller
   and zero input -- on the *same* ``K`` episodes of the task's own environment
   (reset with seeds ``eval_seed + k``, recorded with each episode's ``x(0)``).
3. **Aggregate** as rliable defines it, with the training run as the unit (:mod:`agents.stats`):
   a run's score is the mean over the episodes of the cost ratio ``J_policy / J_paper`` on the
   same episode (< 1: cheaper than the paper's controller); the IQM and the mean of the run
   scores with 95 % percentile-bootstrap CIs that resample whole runs, the probability of
   improvement ``P(J < J_paper)`` over matched (run, episode) pairs, and the transient cost
   (first 2 s), the steady-state error (RMS of the task error over the last 5 s) and the
   failure rate; each row states its budget and the information its policy acts on. On an env with
   communication faults (``tracking_lossy``) each row also has the **degradation** ``J_policy /
   J_paper,fault-free``: its cost relative to the paper's controller on the fault-free counterpart
   (``tracking``) on the same episodes, with the same statistics (:mod:`agents.benchmark.report`).
4. **Write** ``<out>/<env>/results.{json,csv}``, ``error_norms.png``,
   ``learning_curves.png`` and ``<out>/summary.{json,png}`` (every env's cost ratios
   with their CIs).

Modules: :mod:`agents.benchmark.plan` (agent and budget tables, what trains, what a stored run
answers), :mod:`agents.benchmark.backends` (execution backends), :mod:`agents.benchmark.tasks` (the work
units a worker runs), :mod:`agents.benchmark.store` (the ``--out`` directory and the run records the
driver writes), :mod:`agents.benchmark.report` (aggregation, tables, figures); this module is the
driver, :func:`run_benchmark`.

Budgets (environment steps per agent and seed; wall times on a 2-core CPU in the README):

- ``tiny``: a few hundred steps, 20-step episodes (tests);
- ``quick``: the README's main job (3 training seeds);
- ``full``: 10 training seeds, longer training, SAC/TD3, shared residual PPO and the
  sqrt-cost PPO (hours per env on 2 cores).
"""
from __future__ import annotations

import shutil
import time

from ..config.envs import FAULT_FREE
from ..training.provenance import run_provenance
from .backends import Job, make_backend
from .plan import (REEVALUATE, REUSE, BenchmarkPlan, RunConflictError, agent_spec, pending_runs, plan_runs,
                   replaced_runs, stored_answer)
from .report import write_env_report, write_summary
from .store import claim_out_dir, read_run_files, write_record
from .tasks import analytic_results, compile_kernels, fault_free_paper, reevaluate, train_and_evaluate, \
    train_seeds_and_evaluate

__all__ = ["run_benchmark", "FAULT_FREE_PAPER", "TRAIN_SEEDS"]

#: the job key of the paper's controller on an env's fault-free counterpart
#: (:func:`agents.benchmark.tasks.fault_free_paper`)
FAULT_FREE_PAPER = "fault_free_paper"
#: the job key of a jitted agent's seeds of one env trained as one vmapped run
#: (:func:`agents.benchmark.tasks.train_seeds_and_evaluate`: a list of run records)
TRAIN_SEEDS = "train_seeds"


def _jobs(plan: BenchmarkPlan, scratch: str | None, eval_seed: int) -> tuple[list[Job], dict]:
    """The work of ``plan`` not answered by a stored run: a training job per run to train, an evaluation
    job per kept model to evaluate again (its files read here and sent along; a jitted agent's runs to train on an
    env: one job, its seeds vmapped, :data:`TRAIN_SEEDS`), the analytic
    controllers' evaluation per env and, for an env with faults, the paper's controller on its fault-free
    counterpart (last: short jobs fill the gaps); and the stored results reused,
    ``{(env, agent, seed): result}``."""
    train, again, reused, vmapped = [], [], {}, {}
    for sp in plan.specs:
        key = (sp["env"], sp["agent"], sp["seed"])
        answer, prev = stored_answer(sp)
        if answer == REUSE:
            reused[key] = prev
        elif answer == REEVALUATE:
            again.append(Job(("reevaluate", *key), reevaluate, (sp, read_run_files(sp["path"]), prev, scratch),
                             cpus=sp["threads"] or 1))
        elif agent_spec(sp["agent"]).trainer == "jax":
            vmapped.setdefault(key[:2], []).append(sp)
        else:
            train.append(Job(("train", *key), train_and_evaluate, (sp, scratch), cpus=sp["threads"] or 1))
    train = [Job((TRAIN_SEEDS, *key), train_seeds_and_evaluate, (specs, scratch), cpus=specs[0]["threads"] or 1)
             for key, specs in vmapped.items()] + train
    episodes = len(plan.eval_seeds)
    analytic = [Job(("analytic", e), analytic_results, (e, plan.env_kwargs, eval_seed, episodes)) for e in plan.envs]
    # an env with faults: the paper's controller on its fault-free counterpart, the degradation columns' reference
    analytic += [Job((FAULT_FREE_PAPER, e), fault_free_paper, (e, plan.env_kwargs, eval_seed, episodes))
                 for e in plan.envs if e in FAULT_FREE]
    return train + again + analytic, reused


def run_benchmark(env: str = "tracking", budget: str = "quick", out: str = "runs/benchmark", *, seed: int = 0,
                  eval_seed: int = 10_000, episodes: int | None = None, timesteps: int | None = None,
                  agents: list[str] | None = None, seeds: int | None = None, workers: int | None = None,
                  progress: bool = True, threads: int | None = 1, overwrite: bool = False,
                  backend: str = "process", address: str | None = None, recipes: dict | None = None,
                  agent_seeds: dict | None = None, trainer: str = "sb3") -> dict:
    """Run the benchmark (see module doc) on ``env`` (a name or ``"all"``); returns the summary document.

    Training seeds are ``seed, seed + 1, ...`` (``seeds`` of them, default the budget's; ``agent_seeds``
    ``{agent: number}`` gives some agents another number, :func:`plan_runs`).
    ``backend`` (:data:`agents.benchmark.backends.BACKENDS`): ``"process"`` (default): ``workers``
    processes train in parallel (default: the number of CPU cores, at most 8); ``"serial"``: one
    after another in this process; ``"ray"``: Ray tasks of ``threads`` CPUs each, on a local Ray
    of ``workers`` CPUs (default: the machine's) or on the cluster at ``address`` (``"auto"``,
    ``"host:port"``). The numbers do not depend on the backend; a stored run is reused by any.
    The driver writes every run's record as it arrives, so Ctrl-C keeps every finished run.
    :func:`plan_runs` and :func:`pending_runs` tell beforehand what it would train.
    ``recipes``: ``{agent: recipe file}``: adds the agents ``<agent>@recipe`` trained with the file's
    section (:func:`plan_runs`); the files' paths and SHA-256 are recorded in the results and summary.
    ``trainer``: the learned agents of the default set (:data:`agents.benchmark.plan.TRAINERS`: ``"sb3"``,
    ``"jax"``: the jitted agents, each env's seeds of one agent vmapped in one task, ``"all"``).

    Raises
    ------
    RunConflictError
        if a run to train would replace a finished run of another configuration (other training
        steps, evaluation seeds or recipe) in its directory, unless ``overwrite`` (which removes
        those runs first).
    """
    t_start = time.perf_counter()
    provenance = run_provenance()  # the code and machine as the command starts (files may change while it runs)
    P = plan_runs(env, budget, out, seed=seed, eval_seed=eval_seed, episodes=episodes, timesteps=timesteps,
                  agents=agents, seeds=seeds, threads=threads, recipes=recipes, agent_seeds=agent_seeds,
                  trainer=trainer)
    be = make_backend(backend, workers=workers, address=address)  # checks the arguments before any write
    claim_out_dir(out, overwrite=overwrite)  # refuses a directory holding files the benchmark did not write
    clash = replaced_runs(pending_runs(P))
    if clash and not overwrite:
        raise RunConflictError(out, [sp["path"] for sp in clash])
    for sp in clash:
        shutil.rmtree(sp["path"])
    specs = {(sp["env"], sp["agent"], sp["seed"]): sp for sp in P.specs}
    analytic: dict[str, dict] = {}
    fault_free: dict[str, dict] = {}  # env with faults -> the paper's payload on its fault-free counterpart
    placed: dict[str, dict] = {}  # where each run trained or evaluated by this call ran
    t_train = time.perf_counter()
    bar = None
    with be:
        jobs, results = _jobs(P, be.scratch, eval_seed)
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=len(P.specs), initial=len(results), desc=f"train+evaluate ({be.describe()})", unit="run")
        try:
            if be.parallel(len(jobs)):
                compile_kernels(P.envs, P.env_kwargs)
            for job, res in be.run(jobs):
                if job.key[0] == "analytic":
                    analytic[job.key[1]] = res
                    continue
                if job.key[0] == FAULT_FREE_PAPER:
                    fault_free[job.key[1]] = res
                    continue
                for rec in res if job.key[0] == TRAIN_SEEDS else [res]:  # vmapped seeds: one record per run
                    key = (*job.key[1:3], rec["result"]["seed"])
                    write_record(specs[key]["path"], rec)  # the driver writes; a finished run is kept from here on
                    results[key] = {**rec["result"], "reevaluated": True} if rec["reevaluated"] else rec["result"]
                    placed["/".join(map(str, key))] = rec["result"].get("executed_on")
                    if bar is not None:
                        bar.update(1)
        finally:
            if bar is not None:
                bar.close()
    train_wall = time.perf_counter() - t_train

    per_env_rows, docs = {}, {}
    for e in P.envs:
        per_env_rows[e], docs[e] = write_env_report(out, e, P, results, analytic[e], fault_free.get(e))
    return write_summary(out, P, per_env_rows, docs, trainer=trainer, backend=backend, address=address,
                         workers=getattr(be, "workers", None), executed_on=placed, provenance=provenance,
                         timings_s={"train_and_evaluate_wall": train_wall, "total": time.perf_counter() - t_start})
