"""Hyperparameter search of a recipe with Ray Tune: Optuna's TPE sampler and ASHA early stopping.

:func:`run_study` searches the hyperparameters that matter for ``algo`` on ``env``
(:class:`SearchSpace`: learning rate and its schedule, rollout / batch sizes, gamma, the policy's
initial log-std or gSDE, the network size, the recipe's training-only state bound, and
``train_freq`` / ``gradient_steps`` for the off-policy algorithms). Every trial is one training run
(:func:`agents.training.train.train`, the recipe of ``agents/config/hyperparams/<algo>.yaml`` with the trial's values
merged over it) scored like the benchmark scores a run: the mean over ``episodes`` seeded episodes of
the cost ratio ``J_policy / J_paper`` on the task's own environment (lower is better), evaluated at
``report_points`` points of training (:mod:`agents.training.curves`) so that ASHA stops the trials that lag
behind at the same number of environment steps.

Seeds (:mod:`agents.training.seeds`): the episodes are the **tuning** range (from 20 000); the evaluation
range (10 000 - 19 999), on which the benchmark's tables are computed, is refused before Ray starts
and asserted again in every trial. Every trial trains with the same training seed ``seed`` (common
random numbers: trials differ by their hyperparameters only); ``seed`` also seeds Optuna's sampler
(with several concurrent trials the order in which results arrive still varies).

The first trial is the recipe as it is (Optuna's ``enqueue_trial``) when its values lie in the search
space (``study.json`` ``baseline`` says whether), so the table shows where today's recipe ranks.

Output directory ``out``
------------------------
- ``study.json``: the study's definition (what ``resume`` checks and restores);
- ``study/``: the Ray Tune experiment (one directory per trial: ``run/`` the training run,
  ``curve.json`` the cost ratios and the episode seeds, Tune's ``result.json`` / ``progress.csv``);
- ``trials.csv``: one row per trial (status, environment steps reached, score, searched values);
- ``trials.png``: score vs trial (trials stopped early by ASHA hollow, the running best);
- ``best.yml``: the best finished trial's recipe as one rl-zoo3 section named by the Gymnasium id
  (``dobs_envs/HeteroMAS-v0``), complete (every key, as rl-zoo3 reads it alone), with a comment
  header (env, algorithm, trials, score, seeds). ``dobs-envs train --recipe best.yml`` trains with
  it; pasted over that section of ``agents/config/hyperparams/<algo>.yaml`` it becomes the benchmark's recipe.

An interrupted study (Ctrl-C, or a killed process: finished trials are kept) continues with ``resume=True``
from its own plain-JSON records, never from Tune's pickled experiment state (``Tuner.restore`` would unpickle
whatever the directory holds): the trial log ``study/trials.jsonl`` (:data:`~agents.tune.spec.TRIAL_LOG`, written
by the driver as trials start and end) and each trial's ``result.json``. Finished trials (complete, stopped early,
failed) are not run again: they are given to a new Optuna sampler as evaluated points, and a new Tune run in the
same experiment directory runs the remaining trials, the unfinished ones first with their own values (each as a
new trial; the unfinished one is marked superseded and left out of the table). ASHA starts the resumed run with
empty rungs (its comparisons at a milestone are between the trials of the resumed run), and the sampler's seed
is the study's seed mixed with the number of finished trials (so that its start-up draws differ from the first
run's).
"""
from __future__ import annotations

import json
import math
import os
import shutil
import time
from dataclasses import asdict, dataclass

import numpy as np

from ..config.envs import gym_id
from .outputs import trials_table, write_outputs
from .space import SearchSpace
from .spec import (EXPERIMENT, METRIC, STUDY_FILES, TRIAL_LOG, StudyDirError, StudySpec, assert_tuning_only,
                   read_study_json)

__all__ = ["run_study", "StudyResult", "check_constructor_keys", "REDUCTION_FACTOR"]


#: ASHA's halving rate: rungs at max_t / 9, max_t / 3, max_t
REDUCTION_FACTOR = 3


def _recipe_hp(spec: StudySpec) -> dict:
    from ..training.recipes import resolve_recipe

    return resolve_recipe(spec.algo, spec.env, overrides=spec.hyperparams or None).hyperparams


def check_constructor_keys(spec: StudySpec) -> None:
    """ValueError naming the keys of the study's recipe (with ``spec.hyperparams``) that the algorithm's
    class does not take, before any trial starts (every trial would fail the same way)."""
    import inspect

    from ..training.algos import backend
    from ..training.recipes import resolve_recipe

    recipe = resolve_recipe(spec.algo, spec.env, overrides=spec.hyperparams or None)
    cls = backend(spec.algo).load_class()
    params = inspect.signature(cls.__init__).parameters
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return
    unknown = sorted(set(recipe.algo_kwargs) - set(params))
    if unknown:
        raise ValueError(f"hyperparams: {cls.__name__} takes no argument(s) {unknown} (from the recipe of {spec.algo} "
                         f"on {spec.env} with the overrides {spec.hyperparams})")


def _space(spec: StudySpec) -> SearchSpace:
    return SearchSpace(spec.algo, _recipe_hp(spec), spec.timesteps)


def _trial_dirname(trial) -> str:
    """``trial_<id>`` (Tune's default name lists the sampled values and gets cut at the file name limit)."""
    return f"trial_{trial.trial_id}"


def _quiet() -> None:
    """Tune's and Optuna's console output off: the progress bar and the final summary say it (the same goes
    to the experiment's files)."""
    import logging

    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    for name in ("ray.tune", "ray.train", "optuna"):
        logging.getLogger(name).setLevel(logging.WARNING)


def _finite(x: float) -> float:
    return float(x) if math.isfinite(x) else float("inf")


def _trial(config: dict, spec: StudySpec) -> None:
    """The Ray Tune trainable: train one run with the trial's values, report the score at the
    learning-curve points (:func:`agents.training.curves.make_curve_callback` on the tuning episodes)."""
    from ray import tune
    from stable_baselines3.common.callbacks import BaseCallback

    from ..training.curves import make_curve_callback
    from ..training.recipes import merge_overrides
    from ..training.train import train

    seeds = spec.episode_seeds
    assert_tuning_only(seeds)
    trial_dir = tune.get_context().get_trial_dir()
    overrides = merge_overrides(spec.hyperparams, _space(spec).overrides(config))
    curve = make_curve_callback(spec.env, spec.env_kwargs, seeds, spec.report_every,
                                path=os.path.join(trial_dir, "curve.json"))

    class _Report(BaseCallback):
        """Reports the curve's points as they come, except those at the full budget: they go after
        ``train`` has saved the run (the scheduler ends a trial that reports ``max_t``)."""
        sent = 0

        def _send(self, final: bool = False):
            while self.sent < len(curve.points):
                pt = curve.points[self.sent]
                if not final and pt["env_steps"] >= spec.timesteps:
                    return
                self.sent += 1
                ratios = np.asarray(pt["cost_ratio"], dtype=float)
                tune.report({METRIC: _finite(float(np.mean(ratios))), "env_steps": int(pt["env_steps"]),
                             "cost_ratio_median": _finite(float(np.median(ratios))),
                             "episode_seeds": ",".join(map(str, seeds))})

        def _on_step(self) -> bool:
            self._send()
            return True

    report = _Report()
    train(spec.env, spec.algo, timesteps=spec.timesteps, seed=spec.seed, out=os.path.join(trial_dir, "run"),
          progress=False, hyperparams=overrides, env_kwargs=spec.env_kwargs or None, callbacks=[curve, report],
          checkpoint_freq=0, threads=spec.cpus_per_trial)
    report._send(final=True)


class _Progress:
    """Ray Tune callback: a progress bar over finished trials (with the best score so far)."""

    def __new__(cls, total: int, done: int = 0):
        from ray.tune import Callback

        class _Bar(Callback):
            def __init__(self):
                self.total, self.done, self.bar = total, done, None

            def __getstate__(self):  # Tune pickles its callbacks with the experiment (never read back)
                return {"total": self.total, "done": self.done, "bar": None}

            def _update(self, trials):
                from tqdm.auto import tqdm

                if self.bar is None:
                    self.bar = tqdm(total=self.total, desc="trials", unit="trial", dynamic_ncols=True)
                done = [t for t in trials if t.status in ("TERMINATED", "ERROR")]
                scores = [t.last_result.get(METRIC) for t in done if t.last_result]
                scores = [s for s in scores if isinstance(s, (int, float))]
                self.bar.n = self.done + len(done)
                if scores:
                    self.bar.set_postfix_str(f"best score {min(scores):.3g}", refresh=False)
                self.bar.refresh()

            def on_trial_complete(self, iteration, trials, trial, **info):
                self._update(trials)

            def on_trial_error(self, iteration, trials, trial, **info):
                self._update(trials)

            def on_experiment_end(self, trials, **info):
                if self.bar is not None:
                    self._update(trials)
                    self.bar.close()
                    self.bar = None

        return _Bar()


def _plain(x):
    """A searched value as plain JSON (numpy scalars as Python numbers)."""
    return x.item() if hasattr(x, "item") else x


def _log_event(out: str, event: str, trial_id: str, **fields) -> None:
    """Append one event to the study's trial log, on a line of its own (after a torn last line too), flushed."""
    path = os.path.join(out, EXPERIMENT, TRIAL_LOG)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "a+b") as fh:
        fh.seek(0, os.SEEK_END)
        torn = fh.tell() > 0 and (fh.seek(-1, os.SEEK_END), fh.read(1))[1] != b"\n"
        line = json.dumps({"event": event, "trial_id": str(trial_id), **fields}) + "\n"
        fh.write((b"\n" if torn else b"") + line.encode())


class _TrialLog:
    """Ray Tune callback (in the driver): appends a line to the study's trial log as Tune starts a trial
    (its id, directory and searched values) and as it ends one (``complete``: finished or stopped by ASHA;
    ``error``), flushed at once so that a killed study keeps it (:func:`agents.tune.outputs.read_trial_log`)."""

    def __new__(cls, out: str):
        from ray.tune import Callback

        class _Log(Callback):
            def _write(self, trial, event: str, **fields):
                _log_event(out, event, trial.trial_id, **fields)

            def on_trial_start(self, iteration, trials, trial, **info):
                self._write(trial, "start", path=os.path.relpath(trial.path, out),
                            config={k: _plain(v) for k, v in trial.config.items()})

            def on_trial_complete(self, iteration, trials, trial, **info):
                self._write(trial, "complete")

            def on_trial_error(self, iteration, trials, trial, **info):
                self._write(trial, "error")

        return _Log()


def _resumed_searcher(spec: StudySpec, space, out: str, rows: list[dict]):
    """The Optuna sampler of a resumed study (module doc): an Optuna study told the finished trials (each asked
    with its own values enqueued, through the search space, then told its score: Optuna's ask-and-tell), the
    unfinished ones first to run again (each marked superseded in the trial log). Returns ``(searcher, number of
    finished trials)``."""
    import optuna
    from ray.tune.search.optuna import OptunaSearch

    names = [n for n, _, _ in space.params()]
    done = [r for r in rows if r["status"] != "unfinished"]
    redo = [r for r in rows if r["status"] == "unfinished"]
    seed = int(np.random.SeedSequence([spec.seed, len(done)]).generate_state(1)[0] % (2 ** 31))
    storage, name = optuna.storages.InMemoryStorage(), "dobs-envs-tune"
    study = optuna.create_study(storage=storage, study_name=name, direction="minimize")
    for r in done:
        study.enqueue_trial({n: r[n] for n in names})
        trial = study.ask()
        space(trial)  # suggests the enqueued values: the trial records them with their distributions
        failed = r["status"] == "error" or r[METRIC] is None
        study.tell(trial, None if failed else r[METRIC],
                   state=optuna.trial.TrialState.FAIL if failed else optuna.trial.TrialState.COMPLETE)
    searcher = OptunaSearch(space=space, metric=METRIC, mode="min", seed=seed, storage=storage, study_name=name,
                            points_to_evaluate=[{n: r[n] for n in names} for r in redo] or None)
    for r in redo:
        _log_event(out, "superseded", r["trial_id"])
    return searcher, len(done)


@dataclass
class StudyResult:
    """What :func:`run_study` leaves: the table rows, the best row (None before a trial finished),
    whether every trial finished, and the files written."""

    out: str
    rows: list
    best: dict | None
    complete: bool
    seconds: float
    files: list


def _claim(out: str, spec: StudySpec, *, resume: bool, overwrite: bool) -> None:
    """Refuse an occupied ``out`` unless resuming its study (same definition) or overwriting."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise StudyDirError(f"{out!r} is a file, not a directory")
    entries = sorted(os.listdir(out)) if os.path.isdir(out) else []
    if resume:
        stored = read_study_json(out).get("spec")
        if not stored or not os.path.isdir(os.path.join(out, EXPERIMENT)):
            raise StudyDirError(f"{out!r} holds no study to resume (study.json and study/ of dobs-envs tune)")
        mine = json.loads(json.dumps(asdict(spec)))
        diff = [f"{k} {mine[k]!r} (the study has {stored.get(k)!r})" for k in mine if stored.get(k) != mine[k]]
        if diff:
            raise StudyDirError(f"{out!r}: the study's definition differs: {'; '.join(diff)}")
        if not os.path.isfile(os.path.join(out, EXPERIMENT, TRIAL_LOG)):
            if any(e.startswith("trial_") for e in os.listdir(os.path.join(out, EXPERIMENT))):
                raise StudyDirError(f"{out!r}: the study has no trial log ({EXPERIMENT}/{TRIAL_LOG}: studies started "
                                    f"before the trial log existed have none) and is not resumed from Ray Tune's pickled state; its "
                                    f"trials' reports are in {EXPERIMENT}/trial_*/result.json (start it again with "
                                    f"--overwrite, or in another directory)")
            raise StudyDirError(f"{out!r}: the study stopped before its first trial started (no {EXPERIMENT}/"
                                f"{TRIAL_LOG}); nothing to resume (start it again with --overwrite)")
        return
    if entries and not overwrite:
        what = ("a tuning study" if "study.json" in entries else
                f"{len(entries)} entr{'y' if len(entries) == 1 else 'ies'} ({', '.join(entries[:5])})")
        raise StudyDirError(f"{out!r} already holds {what}; pass --resume (resume=True) to continue a study, "
                            f"--overwrite (overwrite=True) to replace it, or choose another directory")
    for name in STUDY_FILES:  # overwrite: the study's own entries only; other files stay
        p = os.path.join(out, name)
        if os.path.isdir(p):
            shutil.rmtree(p)
        elif os.path.exists(p):
            os.remove(p)


def run_study(spec: StudySpec, out: str, *, resume: bool = False, overwrite: bool = False,
              address: str | None = None, cpus: int | None = None, progress: bool = True,
              callbacks: list | None = None) -> StudyResult:
    """Run (or continue, ``resume``) the study ``spec`` into ``out`` (see the module doc).

    Ray: an already initialised Ray is used as it is; else ``address`` joins a cluster
    (``ray.init(address=...)``) or a local Ray of ``cpus`` CPUs (default: the machine's) starts and is
    shut down at the end, also on Ctrl-C. Each trial takes ``spec.cpus_per_trial`` CPUs (and as many
    torch threads). ``callbacks``: more Ray Tune callbacks, for this call (a resumed study runs with the
    callbacks its own call gives). Returns a :class:`StudyResult`; ``complete`` is False after an interruption (the
    finished trials are kept and ``resume=True`` continues).
    """
    import ray
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.optuna import OptunaSearch

    spec.check()
    check_constructor_keys(spec)
    _quiet()
    out = os.path.abspath(out)
    _claim(out, spec, resume=resume, overwrite=overwrite)
    space = _space(spec)
    baseline = space.baseline()
    os.makedirs(out, exist_ok=True)
    if not resume:
        doc = {"spec": asdict(spec), "gym_id": gym_id(spec.env), "episode_seeds": spec.episode_seeds,
               "baseline": baseline, "search_space": [[n, k, list(a)] for n, k, a in space.params()],
               "metric": f"{METRIC}: mean J_policy / J_paper over the tuning episodes (lower is better)",
               "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        with open(os.path.join(out, "study.json.tmp"), "w") as fh:
            json.dump(doc, fh, indent=2)
        os.replace(os.path.join(out, "study.json.tmp"), os.path.join(out, "study.json"))
    started = False
    if not ray.is_initialized():
        kw = {"address": address} if address else {"num_cpus": int(cpus or os.cpu_count() or 1)}
        ray.init(include_dashboard=False, log_to_driver=False, configure_logging=False, **kw)
        started = True
    t0 = time.perf_counter()
    try:
        trainable = tune.with_resources(tune.with_parameters(_trial, spec=spec), {"cpu": spec.cpus_per_trial})
        done = 0
        if resume:
            searcher, done = _resumed_searcher(spec, space, out, trials_table(out))
        else:
            searcher = OptunaSearch(space=space, metric=METRIC, mode="min", seed=spec.seed,
                                    points_to_evaluate=[baseline] if baseline else None)
        if done < spec.trials:  # a resumed study whose trials all finished runs none
            scheduler = ASHAScheduler(time_attr="env_steps", metric=METRIC, mode="min", max_t=spec.timesteps,
                                      grace_period=max(1, spec.timesteps // REDUCTION_FACTOR ** 2),
                                      reduction_factor=REDUCTION_FACTOR)
            cbs = [_TrialLog(out)] + ([_Progress(spec.trials, done)] if progress else []) + list(callbacks or [])
            tuner = tune.Tuner(
                trainable,
                tune_config=tune.TuneConfig(search_alg=searcher, scheduler=scheduler, num_samples=spec.trials - done,
                                            trial_dirname_creator=_trial_dirname),
                run_config=tune.RunConfig(name=EXPERIMENT, storage_path=out, verbose=0, callbacks=cbs))
            tuner.fit()
    finally:
        if started:
            ray.shutdown()
    rows = trials_table(out)
    complete = len(rows) >= spec.trials and all(r["status"] in ("complete", "stopped early", "error") for r in rows)
    files = write_outputs(out, spec, rows, complete=complete)
    finished = [r for r in rows if r["status"] == "complete"]
    best = min(finished, key=lambda r: r[METRIC]) if finished else None
    return StudyResult(out=out, rows=rows, best=best, complete=complete, seconds=time.perf_counter() - t0,
                       files=files)
