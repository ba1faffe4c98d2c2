"""What a study leaves besides Ray Tune's experiment: ``trials.csv`` (one row per trial), ``trials.png``
(score vs trial) and ``best.yml`` (the best complete trial's recipe as an rl-zoo3 section)."""
from __future__ import annotations

import csv
import json
import math
import os

from ..config.envs import gym_id
from ..training.seeds import EVALUATION, TUNING
from .spec import EXPERIMENT, METRIC, TRIAL_LOG, StudySpec, read_study_json, stored_spec

__all__ = ["read_trial_log", "trials_table", "recipe_section", "write_best_recipe", "write_outputs"]


def _json_objects(path: str):
    """The JSON objects of a file of one JSON value per line, in order; a line that is not a JSON object (a torn
    last line of a killed writer) is skipped; nothing if the file cannot be read."""
    try:
        with open(path) as fh:
            lines = fh.readlines()
    except OSError:
        return
    for line in lines:
        try:
            obj = json.loads(line)
        except ValueError:
            continue
        if isinstance(obj, dict):
            yield obj


def read_trial_log(out: str) -> list[dict]:
    """The events of the study's trial log (``study/trials.jsonl``, :data:`~agents.tune.spec.TRIAL_LOG`), in the order
    they were written: dicts with ``event`` (``start``, ``complete``, ``error``, ``superseded``) and ``trial_id``; a
    start also has ``path`` (the trial's directory relative to ``out``) and ``config`` (its searched values). Plain
    JSON only; a line that is not such an object (a torn last line of a killed study) is skipped."""
    return [e for e in _json_objects(os.path.join(out, EXPERIMENT, TRIAL_LOG))
            if isinstance(e.get("event"), str) and isinstance(e.get("trial_id"), str)]


def _last_result(trial_dir: str) -> dict:
    """The trial's last report: the last JSON object of Tune's ``result.json`` (one per line), ``{}`` if none."""
    last = {}
    for last in _json_objects(os.path.join(trial_dir, "result.json")):
        pass
    return last


def trials_table(out: str) -> list[dict]:
    """One row per trial of the study in ``out``, in the order the trials started: ``trial``, ``trial_id``,
    ``status`` (complete: trained the whole budget; stopped early: by ASHA; error; unfinished: not yet finished
    when the study was interrupted or killed), ``env_steps`` reached, the last ``score``, ``seconds``, the trial's
    directory and its searched values. Read from the study's trial log and each trial's ``result.json`` (JSON
    only: Tune's pickled experiment state is never read); a trial superseded by a resume (it was unfinished and
    ran again as a new trial) is left out. ``trial`` numbers the rows, so leaving a superseded trial out moves the
    trials after it up by one; ``trial_id`` never changes."""
    spec = stored_spec(out)
    exp = os.path.realpath(os.path.join(out, EXPERIMENT))
    trials, order = {}, []
    for e in read_trial_log(out):
        tid = e["trial_id"]
        if e["event"] == "start" and tid not in trials:
            path = os.path.realpath(os.path.join(out, str(e.get("path", ""))))
            if os.path.dirname(path) != exp or not isinstance(e.get("config"), dict):
                continue  # not a trial directory of this study: never read
            trials[tid] = {"path": path, "config": e["config"], "end": None}
            order.append(tid)
        elif tid in trials and e["event"] in ("complete", "error", "superseded"):
            trials[tid]["end"] = e["event"]
    rows = []
    for tid in order:
        t = trials[tid]
        if t["end"] == "superseded":
            continue
        last = _last_result(t["path"])
        steps = last.get("env_steps")
        if t["end"] == "error":
            status = "error"
        elif steps is not None and int(steps) >= spec.timesteps:
            status = "complete"
        elif t["end"] == "complete":
            status = "stopped early"
        else:
            status = "unfinished"
        score = last.get(METRIC)
        rows.append({"trial": len(rows), "trial_id": tid, "status": status,
                     "env_steps": int(steps) if steps is not None else None,
                     METRIC: float(score) if score is not None else None,
                     "seconds": round(float(last.get("time_total_s", 0.0)), 1),
                     "path": os.path.relpath(t["path"], os.path.realpath(out)),
                     **{k: v for k, v in sorted(t["config"].items())}})
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


def write_best_recipe(path: str, spec: StudySpec, best: dict, rows: list[dict], *, baseline: dict | None = None) -> None:
    """``best.yml``: the best trial's run hyperparameters as the rl-zoo3 section of the env's Gymnasium
    id, with a comment header (env, algorithm, trials, score, seeds; ``baseline``: the recipe's own searched values,
    whose trial the header quotes)."""
    import yaml

    base = next((r for r in rows if baseline and all(r.get(k) == v for k, v in baseline.items())), None)

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
        + (f"trial {base['trial']} (the recipe before tuning): {base[METRIC]:.4g} ({base['status']})"
           if base is not None and base[METRIC] is not None else
           "the recipe before tuning lies outside the search space (not a trial)" if not baseline else
           "the recipe before tuning did not finish"),
        f"# use: dobs-envs train --env {spec.env} --algo {spec.algo} --recipe {os.path.basename(path)}; or replace "
        f"the {gym_id(spec.env)} section of agents/config/hyperparams/{spec.algo}.yaml with it "
        f"(the benchmark's recipe)",
    ]
    text = yaml.safe_dump({gym_id(spec.env): section}, sort_keys=False, default_flow_style=None)
    with open(path + ".tmp", "w") as fh:
        fh.write("\n".join(header) + "\n" + text)
    os.replace(path + ".tmp", path)


def write_outputs(out: str, spec: StudySpec, rows: list[dict], *, complete: bool) -> list[str]:
    files = []
    if rows:
        _write_csv(os.path.join(out, "trials.csv"), rows)
        _plot(os.path.join(out, "trials.png"), rows, spec)
        files += ["trials.csv", "trials.png"]
    finished = [r for r in rows if r["status"] == "complete" and r[METRIC] is not None]
    if complete and finished:
        write_best_recipe(os.path.join(out, "best.yml"), spec, min(finished, key=lambda r: r[METRIC]), rows,
                          baseline=read_study_json(out).get("baseline"))
        files.append("best.yml")
    return [os.path.join(out, f) for f in files]
