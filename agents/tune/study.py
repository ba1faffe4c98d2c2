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

An interrupted study (Ctrl-C: Tune saves its state; finished trials are kept) continues with
``resume=True`` (``Tuner.restore``): finished trials are not run again, unfinished ones restart.
"""
from __future__ import annotations

import csv
import json
import math
import os
import shutil
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..config.hyperparam_files import ALGOS
from ..config.envs import ENVS, gym_id
from ..training.seeds import EVALUATION, TUNING, check_episode_seeds, check_training_seeds

__all__ = ["SearchSpace", "StudySpec", "StudyResult", "StudyDirError", "run_study", "stored_spec", "check_constructor_keys",
           "write_best_recipe", "trials_table", "recipe_section", "STUDY_FILES", "METRIC"]

#: the reported score (lower is better): mean J_policy / J_paper over the tuning episodes
METRIC = "score"
#: ASHA's halving rate: rungs at max_t / 9, max_t / 3, max_t
REDUCTION_FACTOR = 3
#: the entries :func:`run_study` writes in its output directory
STUDY_FILES = ("study.json", "study", "trials.csv", "trials.png", "best.yml")
_EXPERIMENT = "study"

#: the named network sizes of the search space (Optuna's categorical values must be scalars)
NETS = {"64x64": [64, 64], "128x128": [128, 128], "256x256": [256, 256], "400x300": [400, 300]}


class StudyDirError(ValueError):
    """The output directory cannot take the study (occupied without resume/overwrite, nothing to resume,
    or a definition that differs from the stored one)."""


# ------------------------------------------------------------------------------------ search space
def _net_name(net_arch) -> str | None:
    for name, arch in NETS.items():
        if list(net_arch or []) == arch:
            return name
    return None


class SearchSpace:
    """Optuna define-by-run search space of one algorithm around a recipe (``hp``: the merged
    hyperparameters in :mod:`agents.config.hyperparam_files`'s vocabulary) for a budget of ``timesteps`` env steps.

    ``space(trial)`` samples the parameters (Ray's ``OptunaSearch(space=...)``);
    :meth:`overrides` turns the sampled values into hyperparameter overrides (merged over the recipe
    by :func:`agents.training.recipes.resolve_recipe`); :meth:`baseline` is the recipe itself as a point of
    the space (None when one of its values lies outside).

    Sizes that cannot work with the budget are left out: PPO rollouts ``n_steps * n_envs`` of at most a
    quarter of the budget, minibatches no larger than a rollout (clipped), off-policy
    ``gradient_steps`` at most the samples collected per update (``train_freq * n_envs``) and
    ``learning_starts`` at most a quarter of the budget.
    """

    GAMMAS = (0.95, 0.98, 0.99, 0.995, 0.999)

    def __init__(self, algo: str, hp: dict, timesteps: int):
        if algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
        self.algo, self.hp, self.timesteps = algo, dict(hp), int(timesteps)
        self.n_envs = int(hp.get("n_envs", 1))
        bound = (hp.get("env_kwargs") or {}).get("state_bound")
        self.state_bounds = tuple(float(f * bound) for f in (0.5, 1, 2, 4)) if bound else ()
        rollouts = [c for c in (64, 128, 256, 512, 1024, 2048) if c * self.n_envs <= self.timesteps // 4]
        self.n_steps = tuple(rollouts or [64])
        starts = [c for c in (100, 1000, 5000, 10000) if c <= self.timesteps // 4]
        self.learning_starts = tuple(starts or [0])

    # the parameters: (name, kind, choices or (low, high)); categorical choices are scalars
    def params(self) -> list[tuple[str, str, Any]]:
        common = [("learning_rate", "log", (1e-5, 3e-3)), ("lr_schedule", "cat", ("constant", "linear")),
                  ("gamma", "cat", self.GAMMAS)]
        if self.algo == "ppo":
            p = common + [("n_steps", "cat", self.n_steps), ("batch_size", "cat", (64, 128, 256, 512)),
                          ("n_epochs", "cat", (5, 10, 20)), ("gae_lambda", "cat", (0.9, 0.95, 0.98)),
                          ("clip_range", "cat", (0.1, 0.2, 0.3)), ("log_std_init", "float", (-4.0, -1.0)),
                          ("use_sde", "cat", (False, True)), ("net_arch", "cat", ("64x64", "128x128", "256x256"))]
        else:
            p = common + [("batch_size", "cat", (64, 128, 256, 512)), ("tau", "cat", (0.005, 0.01, 0.02, 0.05)),
                          ("train_freq", "cat", (1, 4, 8, 16)), ("gradient_steps", "cat", (1, 2, 4, 8, 16)),
                          ("learning_starts", "cat", self.learning_starts),
                          ("net_arch", "cat", ("64x64", "256x256", "400x300"))]
            if self.algo == "sac":
                p += [("log_std_init", "float", (-4.0, 0.0)), ("use_sde", "cat", (False, True))]
            else:
                p += [("noise_std", "cat", (0.02, 0.05, 0.1, 0.2, 0.3))]
        if self.state_bounds:
            p.append(("state_bound", "cat", self.state_bounds))
        return p

    def __call__(self, trial) -> None:
        for name, kind, arg in self.params():
            if kind == "cat":
                trial.suggest_categorical(name, list(arg))
            else:
                trial.suggest_float(name, *arg, log=kind == "log")

    def overrides(self, params: dict) -> dict:
        """Hyperparameter overrides of the sampled ``params`` (agents' vocabulary; ``policy_kwargs`` and
        ``env_kwargs`` are merged into the recipe's, keeping e.g. its activation)."""
        p = dict(params)
        unknown = set(p) - {name for name, _, _ in self.params()}
        if unknown:
            raise ValueError(f"parameters {sorted(unknown)} are not in the {self.algo} search space")
        out: dict = {}
        lr = float(p.pop("learning_rate"))
        out["learning_rate"] = f"lin_{lr:.6g}" if p.pop("lr_schedule") == "linear" else lr
        pk = {"net_arch": list(NETS[p.pop("net_arch")])}
        if "log_std_init" in p:
            pk["log_std_init"] = float(p.pop("log_std_init"))
        out["policy_kwargs"] = pk
        if "state_bound" in p:
            out["env_kwargs"] = {"state_bound": float(p.pop("state_bound"))}
        if self.algo == "ppo":
            p["batch_size"] = min(int(p["batch_size"]), int(p["n_steps"]) * self.n_envs)
        else:
            p["gradient_steps"] = min(int(p["gradient_steps"]), int(p["train_freq"]) * self.n_envs)
        out.update(p)
        return out

    def baseline(self) -> dict | None:
        """The recipe's own values as a point of the space (None if one lies outside it)."""
        hp, pk = self.hp, dict(self.hp.get("policy_kwargs") or {})
        lr = hp.get("learning_rate", 3e-4)
        sched = "constant"
        if isinstance(lr, str) and lr.startswith("lin_"):
            lr, sched = lr[4:], "linear"
        defaults = {"ppo": {"log_std_init": 0.0, "net_arch": [64, 64]},
                    "sac": {"log_std_init": -3.0, "net_arch": [256, 256]}, "td3": {"net_arch": [400, 300]}}[self.algo]
        values = {"learning_rate": float(lr), "lr_schedule": sched,
                  "net_arch": _net_name(pk.get("net_arch", defaults["net_arch"])),
                  "log_std_init": float(pk.get("log_std_init", defaults.get("log_std_init", 0.0))),
                  "use_sde": bool(hp.get("use_sde", False)),
                  "state_bound": float((hp.get("env_kwargs") or {}).get("state_bound", 0.0))}
        point = {}
        for name, kind, arg in self.params():
            v = values.get(name, hp.get(name))
            if kind == "cat":
                if v not in arg:
                    return None
            elif v is None or not arg[0] <= float(v) <= arg[1]:
                return None
            point[name] = v
        return point


# ------------------------------------------------------------------------------------ the study
@dataclass(frozen=True)
class StudySpec:
    """What defines a study (``study.json``): the trainable receives it with every trial."""

    env: str
    algo: str
    trials: int
    timesteps: int
    episodes: int = 5
    tune_seed: int = TUNING.start
    seed: int = 0
    report_points: int = 6
    cpus_per_trial: int = 1
    hyperparams: dict = field(default_factory=dict)
    env_kwargs: dict = field(default_factory=dict)

    @property
    def episode_seeds(self) -> list[int]:
        return list(range(self.tune_seed, self.tune_seed + self.episodes))

    @property
    def report_every(self) -> int:
        return max(1, self.timesteps // self.report_points)

    def check(self) -> None:
        """ValueError naming the argument for anything out of range (before Ray starts)."""
        if self.env not in ENVS:
            raise ValueError(f"env must be one of {sorted(ENVS)}, got {self.env!r}")
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {self.algo!r}")
        for name in ("trials", "timesteps", "episodes", "report_points", "cpus_per_trial"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        check_training_seeds(self.seed, 1, name="seed")
        check_episode_seeds(self.tune_seed, self.episodes, TUNING, name="tune_seed")
        _assert_tuning_only(self.episode_seeds)


def _assert_tuning_only(seeds) -> None:
    """Tuning never sees an evaluation episode (agents/training/seeds.py): checked again inside every trial."""
    bad = [s for s in seeds if s in EVALUATION or s not in TUNING]
    if bad:
        raise AssertionError(f"tuning episodes {bad} lie outside the {TUNING} (the {EVALUATION} is the "
                             f"benchmark's and never used for tuning)")


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
    _assert_tuning_only(seeds)
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

    def __new__(cls, total: int):
        from ray.tune import Callback

        class _Bar(Callback):
            dobs_envs_progress = True  # what run_study replaces in a restored experiment

            def __init__(self):
                self.total, self.bar = total, None

            def __getstate__(self):  # Tune pickles its callbacks with the experiment
                return {"total": self.total, "bar": None}

            def _update(self, trials):
                from tqdm.auto import tqdm

                if self.bar is None:
                    self.bar = tqdm(total=self.total, desc="trials", unit="trial", dynamic_ncols=True)
                done = [t for t in trials if t.status in ("TERMINATED", "ERROR")]
                scores = [t.last_result.get(METRIC) for t in done if t.last_result]
                scores = [s for s in scores if isinstance(s, (int, float))]
                self.bar.n = len(done)
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


def _read_study_json(out: str) -> dict:
    path = os.path.join(out, "study.json")
    try:
        with open(path) as fh:
            d = json.load(fh)
        return d if isinstance(d, dict) else {}
    except (OSError, ValueError):
        return {}


def _claim(out: str, spec: StudySpec, *, resume: bool, overwrite: bool) -> None:
    """Refuse an occupied ``out`` unless resuming its study (same definition) or overwriting."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise StudyDirError(f"{out!r} is a file, not a directory")
    entries = sorted(os.listdir(out)) if os.path.isdir(out) else []
    if resume:
        stored = _read_study_json(out).get("spec")
        if not stored or not os.path.isdir(os.path.join(out, _EXPERIMENT)):
            raise StudyDirError(f"{out!r} holds no study to resume (study.json and study/ of dobs-envs tune)")
        from ray.tune import Tuner

        if not Tuner.can_restore(os.path.join(out, _EXPERIMENT)):
            raise StudyDirError(f"{out!r}: the study stopped before Ray Tune saved its state; nothing to resume "
                                f"(start it again with --overwrite)")
        mine = json.loads(json.dumps(asdict(spec)))
        diff = [f"{k} {mine[k]!r} (the study has {stored.get(k)!r})" for k in mine if stored.get(k) != mine[k]]
        if diff:
            raise StudyDirError(f"{out!r}: the study's definition differs: {'; '.join(diff)}")
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


def stored_spec(out: str) -> StudySpec:
    """The :class:`StudySpec` recorded in ``out/study.json`` (StudyDirError if there is none)."""
    d = _read_study_json(out).get("spec")
    if not isinstance(d, dict):
        raise StudyDirError(f"{out!r} holds no study to resume (study.json of dobs-envs tune)")
    try:
        return StudySpec(**d)
    except TypeError as exc:
        raise StudyDirError(f"{out}/study.json: {exc}") from None


def run_study(spec: StudySpec, out: str, *, resume: bool = False, overwrite: bool = False,
              address: str | None = None, cpus: int | None = None, progress: bool = True,
              callbacks: list | None = None) -> StudyResult:
    """Run (or continue, ``resume``) the study ``spec`` into ``out`` (see the module doc).

    Ray: an already initialised Ray is used as it is; else ``address`` joins a cluster
    (``ray.init(address=...)``) or a local Ray of ``cpus`` CPUs (default: the machine's) starts and is
    shut down at the end, also on Ctrl-C. Each trial takes ``spec.cpus_per_trial`` CPUs (and as many
    torch threads). ``callbacks``: more Ray Tune callbacks (stored with the experiment: a resumed study
    keeps the first run's). Returns a :class:`StudyResult`; ``complete`` is False after an interruption (the
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
    exp = os.path.join(out, _EXPERIMENT)
    try:
        trainable = tune.with_resources(tune.with_parameters(_trial, spec=spec), {"cpu": spec.cpus_per_trial})
        if resume:
            tuner = tune.Tuner.restore(exp, trainable, resume_unfinished=True, resume_errored=False)
            # Tune restores the callbacks stored with the experiment: this call's progress choice replaces
            # the stored bar (Tune's private attribute; left alone if a Ray version lacks it)
            run_config = getattr(getattr(tuner, "_local_tuner", None), "_run_config", None)
            if run_config is not None:
                kept = [cb for cb in (run_config.callbacks or []) if not getattr(cb, "dobs_envs_progress", False)]
                run_config.callbacks = ([_Progress(spec.trials)] if progress else []) + kept
        else:
            searcher = OptunaSearch(space=space, metric=METRIC, mode="min", seed=spec.seed,
                                    points_to_evaluate=[baseline] if baseline else None)
            scheduler = ASHAScheduler(time_attr="env_steps", metric=METRIC, mode="min", max_t=spec.timesteps,
                                      grace_period=max(1, spec.timesteps // REDUCTION_FACTOR ** 2),
                                      reduction_factor=REDUCTION_FACTOR)
            tuner = tune.Tuner(
                trainable,
                tune_config=tune.TuneConfig(search_alg=searcher, scheduler=scheduler, num_samples=spec.trials,
                                            trial_dirname_creator=_trial_dirname),
                run_config=tune.RunConfig(name=_EXPERIMENT, storage_path=out, verbose=0,
                                          callbacks=([_Progress(spec.trials)] if progress else [])
                                          + list(callbacks or [])))
        tuner.fit()
    finally:
        if started:
            ray.shutdown()
    rows = trials_table(out)
    complete = len(rows) >= spec.trials and all(r["status"] in ("complete", "stopped early", "error") for r in rows)
    files = _write_outputs(out, spec, rows, complete=complete)
    finished = [r for r in rows if r["status"] == "complete"]
    best = min(finished, key=lambda r: r[METRIC]) if finished else None
    return StudyResult(out=out, rows=rows, best=best, complete=complete, seconds=time.perf_counter() - t0,
                       files=files)


# ------------------------------------------------------------------------------------ outputs
def trials_table(out: str) -> list[dict]:
    """One row per trial of the study in ``out``, in the order the trials were created: ``trial``,
    ``trial_id``, ``status`` (complete: trained the whole budget; stopped early: by ASHA; error;
    unfinished: not yet finished when the study was interrupted), ``env_steps`` reached, the last
    ``score``, ``seconds``, the trial's directory and its searched values."""
    from ray.tune import ExperimentAnalysis

    import logging

    spec = stored_spec(out)
    quiet = logging.getLogger("ray.tune.analysis")  # "Failed to fetch metrics" of trials that never reported
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        analysis = ExperimentAnalysis(os.path.join(out, _EXPERIMENT))
    finally:
        quiet.setLevel(level)
    # in the order Tune created them (its experiment tag starts with that counter; a restored experiment
    # lists them in another order)
    trials = sorted(analysis.trials, key=lambda t: int(str(t.experiment_tag).split("_")[0] or 0))
    rows = []
    for i, t in enumerate(trials):
        last = t.last_result or {}
        steps = last.get("env_steps")
        if t.status == "ERROR":
            status = "error"
        elif t.status != "TERMINATED":
            status = "unfinished"
        elif steps is not None and int(steps) >= spec.timesteps:
            status = "complete"
        else:
            status = "stopped early"
        score = last.get(METRIC)
        rows.append({"trial": i, "trial_id": t.trial_id, "status": status,
                     "env_steps": int(steps) if steps is not None else None,
                     METRIC: float(score) if score is not None else None,
                     "seconds": round(float(last.get("time_total_s", 0.0)), 1),
                     "path": os.path.relpath(t.path, out),
                     **{k: v for k, v in sorted(t.config.items())}})
    return rows


def _write_csv(path: str, rows: list[dict]) -> None:
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(path + ".tmp", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    os.replace(path + ".tmp", path)


def _plot(path: str, rows: list[dict], spec: StudySpec) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(figsize=(7, 4))
    for status, style in (("complete", dict(marker="o", color="C0", label="complete")),
                          ("stopped early", dict(marker="o", mfc="none", color="C1", label="stopped early (ASHA)"))):
        pts = [(r["trial"], r[METRIC]) for r in rows if r["status"] == status and r[METRIC] is not None]
        if pts:
            ax.plot(*zip(*pts), ls="none", **style)
    best, line = math.inf, []
    for r in rows:
        if r["status"] == "complete" and r[METRIC] is not None:
            best = min(best, r[METRIC])
        line.append(best)
    if any(math.isfinite(b) for b in line):
        ax.step(range(len(line)), line, where="post", color="C2", label="best complete so far")
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="paper's controller (1)")
    finite = [r[METRIC] for r in rows if r[METRIC] is not None and math.isfinite(r[METRIC]) and r[METRIC] > 0]
    if finite and max(finite) / min(finite) > 20:
        ax.set_yscale("log")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_xlabel("trial")
    ax.set_ylabel(r"score: mean $J/J_{paper}$ (tuning episodes)")
    ax.set_title(f"tune {spec.algo} on {spec.env}: {spec.timesteps} env steps per trial, episodes "
                 f"{spec.episode_seeds[0]}-{spec.episode_seeds[-1]}", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path + ".tmp.png", dpi=100)
    plt.close(fig)
    os.replace(path + ".tmp.png", path)


def recipe_section(hp: dict) -> dict:
    """Merged hyperparameters (agents' vocabulary, a run's ``config.json`` ``hyperparams``) as an
    rl-zoo3 section: ``policy_kwargs`` as its ``"dict(...)"`` string with ``nn.<Activation>``,
    ``normalize_actions`` as the ``RescaleAction`` ``env_wrapper``."""
    from ..config.hyperparam_files import ACTIVATIONS, RESCALE_WRAPPER

    sec = {}
    for k, v in hp.items():
        if k == "normalize_actions":
            if v:
                sec["env_wrapper"] = [{RESCALE_WRAPPER: {"min_action": -1, "max_action": 1}}]
        elif k == "policy_kwargs":
            items = []
            for pk, pv in (v or {}).items():
                items.append(f"{pk}=nn.{ACTIVATIONS[pv]}" if pk == "activation_fn" else f"{pk}={pv!r}")
            sec[k] = f"dict({', '.join(items)})"
        else:
            sec[k] = v
    return sec


def write_best_recipe(path: str, spec: StudySpec, best: dict, rows: list[dict], *, baseline: bool = False) -> None:
    """``best.yml``: the best trial's run hyperparameters as the rl-zoo3 section of the env's Gymnasium
    id, with a comment header (env, algorithm, trials, score, seeds)."""
    import yaml

    with open(os.path.join(os.path.dirname(path), best["path"], "run", "config.json")) as fh:
        hp = json.load(fh)["hyperparams"]
    hp["n_timesteps"] = spec.timesteps  # the budget the values were chosen for
    section = recipe_section(hp)
    counts = {s: sum(r["status"] == s for r in rows) for s in ("complete", "stopped early", "error")}
    seeds = spec.episode_seeds
    header = [
        f"# dobs-envs tune: best {spec.algo} recipe for {spec.env} ({gym_id(spec.env)}), rl-zoo3 format",
        f"# {len(rows)} trials ({counts['complete']} complete, {counts['stopped early']} stopped early by ASHA, "
        f"{counts['error']} failed); Optuna TPE (seed {spec.seed}) + ASHA on the learning-curve score",
        f"# score (lower is better): mean J_policy/J_paper {best[METRIC]:.4g} over tuning episodes "
        f"{seeds[0]}-{seeds[-1]} ({TUNING}; the {EVALUATION} was not used), after {spec.timesteps} env steps, "
        f"training seed {spec.seed}",
        f"# best trial {best['trial']} ({best['trial_id']}); "
        + (f"trial 0 (the recipe before tuning): {rows[0][METRIC]:.4g} ({rows[0]['status']})"
           if baseline and rows and rows[0][METRIC] is not None else "the recipe before tuning lies outside the "
                                                                      "search space (not a trial)"),
        f"# use: dobs-envs train --env {spec.env} --algo {spec.algo} --recipe {os.path.basename(path)}; or replace "
        f"the {gym_id(spec.env)} section of agents/config/hyperparams/{spec.algo}.yaml with it (the benchmark's recipe)",
    ]
    text = yaml.safe_dump({gym_id(spec.env): section}, sort_keys=False, default_flow_style=None)
    with open(path + ".tmp", "w") as fh:
        fh.write("\n".join(header) + "\n" + text)
    os.replace(path + ".tmp", path)


def _write_outputs(out: str, spec: StudySpec, rows: list[dict], *, complete: bool) -> list[str]:
    files = []
    if rows:
        _write_csv(os.path.join(out, "trials.csv"), rows)
        _plot(os.path.join(out, "trials.png"), rows, spec)
        files += ["trials.csv", "trials.png"]
    finished = [r for r in rows if r["status"] == "complete" and r[METRIC] is not None]
    if complete and finished:
        write_best_recipe(os.path.join(out, "best.yml"), spec, min(finished, key=lambda r: r[METRIC]), rows,
                          baseline=_read_study_json(out).get("baseline") is not None)
        files.append("best.yml")
    return [os.path.join(out, f) for f in files]
