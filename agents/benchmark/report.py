"""Benchmark reporting: the rows of the results table from the runs' records (rliable statistics with
the training run as the unit, :mod:`agents.stats`), the text and Markdown tables, the figures, and the
files ``<out>/<env>/results.{json,csv,md}``, ``error_norms.png``, ``learning_curves.png`` and
``<out>/summary.{json,png}`` (:func:`write_env_report`, :func:`write_summary`). On an environment with communication
faults (``tracking_lossy``) every row also has the degradation ``J / J_paper,fault-free`` (:data:`DEGRADATION_DOC`).
"""
from __future__ import annotations

import csv
import json
import os

import numpy as np

from ..config.envs import FAULT_FREE
from ..evaluate import STEADY_S, TRANSIENT_S
from .plan import ANALYTIC_INFO, PAPER, BenchmarkPlan, agent_spec
from ..stats import improvement_estimate, interval_estimate, iqm, mean_estimate, run_scores
from .tasks import mean_trajectory

__all__ = ["write_env_report", "write_summary", "format_table", "format_markdown", "aggregate_over_envs",
           "summarise_dicts", "TABLE_COLUMNS", "DEGRADATION_COLUMNS", "STATISTICS_DOC", "DEGRADATION_DOC",
           "FAULTS_NOTE", "PAPER_NOTES"]


#: what the "paper (separation)" row is where the paper prints no controller for the task
PAPER_NOTES = {
    "hetero_mas": ("hetero_mas: the paper prints no controller for this task (NE1's input is prescribed); the "
                   "reference is this project's rendezvous law u^k = K^k xhat (an LQR rendezvous gain, "
                   "dobs_envs/scenarios/mas_tasks.py) on the paper's distributed estimates: the paper's separation "
                   "principle, not a controller printed in the paper"),
}
STATISTICS_DOC = (
    "rliable definitions with the training run as the statistical unit: a run's score is the mean over its "
    "evaluation episodes of J / J_paper (a failed episode at its cost with the termination penalty); IQM = "
    "25%-trimmed mean of the run scores; 95% CI: percentile bootstrap over runs (50000 replicates; over several "
    "envs, runs resampled within each env); mean J / J_paper with the same CI; P(J < J_paper): probability of "
    "improvement over the matched (run, episode) pairs (rliable's Mann-Whitney form, ties 1/2), CI by resampling "
    "whole runs; transient cost and errors: IQM over runs of the run means; analytic controllers are "
    "deterministic (one run: no interval)")
#: the degradation columns of an environment with communication faults (``degradation_*`` keys of its rows)
DEGRADATION_DOC = (
    "degradation = J_policy / J_paper,fault-free: the policy's cost on the environment with communication faults over "
    "the cost of the paper's controller on its fault-free counterpart (the same task with faults=None, "
    "agents.config.envs.FAULT_FREE) on the same episode: the same seed gives the same initial state and reference (the "
    "faulted environment draws its fault seed last from the episode's generator; the report checks x(0)). One "
    "yardstick for every row: 1 is what the paper's controller achieves on the ideal network, the paper's own row is "
    "its degradation under the faults. Statistics as for J / J_paper: a run's score is the mean over the episodes; IQM "
    "over runs with a 95% percentile-bootstrap CI over runs, the mean with its CI; analytic controllers one run")
#: what the policies of an environment with communication faults observe (results.md's note, results.json
#: ``fault_note``)
FAULTS_NOTE = (
    "{env} has communication faults: every policy acts on what reached it (measured outputs with sensor noise, the "
    "estimate its C-O link delivered, held when a packet is lost, the copies of the neighbours' estimates its node "
    "holds, and the 'received' flags), so the information column means the received values; the oracle reads the true "
    "state. The degradation columns divide by the paper's controller's cost on {fault_free} (no faults) on the same "
    "episodes (mean cost {ff_mean:.4g} there, {paper_mean:.4g} here)")


def _run_means(run: dict, key: str) -> np.ndarray:
    """A run's mean trajectory of ``key`` (results stored before 2026-12-02 hold every episode's)."""
    return np.asarray(run[f"{key}_mean"]) if f"{key}_mean" in run else mean_trajectory(run[key])


# ---------------------------------------------------------------------- aggregation
def _matrix(runs: list[dict], key: str) -> np.ndarray:
    return np.array([[e[key] for e in r["episodes"]] for r in runs], dtype=np.float64)


def _ratio_columns(key: str, cost: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, dict]:
    """The run scores of ``cost (runs, episodes) / reference (episodes,)`` (a run's score: the mean of its
    episodes' ratios) and their statistics as row entries: ``<key>_iqm``, ``<key>_ci_low``, ``<key>_ci_high``
    (IQM over runs, 95 % percentile-bootstrap CI over runs) and ``<key>_mean``, ``<key>_mean_ci_low``,
    ``<key>_mean_ci_high`` (:mod:`agents.stats`). The one computation behind ``cost_ratio`` (``J / J_paper``)
    and ``degradation`` (``J / J_paper,fault-free``)."""
    scores = run_scores(cost / reference[None, :])
    est, mean = interval_estimate(scores), mean_estimate(scores)
    return scores, {f"{key}_iqm": est["iqm"], f"{key}_ci_low": est["ci_low"], f"{key}_ci_high": est["ci_high"],
                    f"{key}_mean": mean["mean"], f"{key}_mean_ci_low": mean["ci_low"],
                    f"{key}_mean_ci_high": mean["ci_high"]}


def _aggregate(label: str, kind: str, runs: list[dict], paper_cost: np.ndarray, *, information: str,
               steps: int | None = None, fault_free_cost: np.ndarray | None = None) -> dict:
    """Row of the results table from ``runs`` (one payload per training run; one for a deterministic
    analytic controller).

    The training run is the statistical unit (:mod:`agents.stats`): a run's score is the mean of its
    per-episode values (cost ratio ``J / J_paper``, failed episodes at their penalty cost; likewise the
    transient cost and the errors); the row gives the IQM of the run scores with a 95 % percentile
    bootstrap CI over runs, the mean cost ratio with its CI (a failure cannot be trimmed away), the
    probability of improvement ``P(J < J_paper)`` over the matched (run, episode) pairs with its CI
    over runs, and the failure rate over every episode. ``cost_ratio_episode_iqm`` is the IQM over
    every (run, episode): the spread over episodes, reported for reference only.

    ``fault_free_cost (episodes,)``: an environment with communication faults: the paper's controller's
    costs on the fault-free counterpart on the same episodes; the row then has the degradation
    ``J / J_paper,fault-free`` with the same statistics (``degradation_*``, :data:`DEGRADATION_DOC`)."""
    cost = _matrix(runs, "cost")
    ratio = cost / paper_cost[None, :]
    row = {"policy": label, "kind": kind, "information": information, "runs": len(runs), "episodes": cost.shape[1],
           "env_steps": steps, "train_seconds_median": None}
    if steps is not None:
        row["train_seconds_median"] = float(np.median([r["train_seconds"] for r in runs]))
    ratio_scores, columns = _ratio_columns("cost_ratio", cost, paper_cost)
    row.update(columns)
    for key, scores in (("transient_cost", run_scores(_matrix(runs, "transient_cost"))),
                        ("steady_state_error", run_scores(_matrix(runs, "steady_state_error"))),
                        ("final_tracking_error", run_scores(_matrix(runs, "final_tracking_error")))):
        est = interval_estimate(scores)
        row[f"{key}_iqm"], row[f"{key}_ci_low"], row[f"{key}_ci_high"] = est["iqm"], est["ci_low"], est["ci_high"]
    if fault_free_cost is not None:
        degradation_scores, columns = _ratio_columns("degradation", cost, fault_free_cost)
        row.update(columns)
        row["degradation_run_scores"] = degradation_scores.tolist()
    poi = improvement_estimate(cost, paper_cost)
    row["poi"], row["poi_ci_low"], row["poi_ci_high"] = poi["poi"], poi["ci_low"], poi["ci_high"]
    row["cost_ratio_episode_iqm"] = float(iqm(ratio))
    row["failure_rate"] = float(np.mean(_matrix(runs, "failed")))
    row["run_scores"] = ratio_scores.tolist()
    flat = [e for r in runs for e in r["episodes"]]
    row.update(summarise_dicts(flat))
    return row


def summarise_dicts(episodes: list[dict]) -> dict:
    """Mean and std over episodes of the per-episode metrics (as :func:`agents.evaluate.summarise`)."""
    out = {}
    for key in ("return", "cost", "transient_cost", "steady_state_error", "final_tracking_error",
                "rms_estimation_error", "control_effort", "length"):
        a = np.array([e[key] for e in episodes], dtype=np.float64)
        out[f"{key}_mean"], out[f"{key}_std"] = float(a.mean()), float(a.std())
    return out


def aggregate_over_envs(per_env: dict) -> list[dict]:
    """Every policy present on all of ``per_env``'s environments with the same number of runs:
    IQM and mean of its run scores over the ``(runs, envs)`` matrix, with rliable's stratified
    bootstrap (runs resampled within each environment)."""
    envs = list(per_env)
    out = []
    if len(envs) < 2:
        return out
    for label in dict.fromkeys(r["policy"] for r in per_env[envs[0]]):
        rows = [next((r for r in per_env[e] if r["policy"] == label), None) for e in envs]
        if any(r is None for r in rows) or len({len(r["run_scores"]) for r in rows}) != 1:
            continue
        m = np.array([r["run_scores"] for r in rows]).T  # (runs, envs)
        est, mean = interval_estimate(m), mean_estimate(m)
        out.append({"policy": label, "kind": rows[0]["kind"], "envs": envs, "runs": m.shape[0],
                    "cost_ratio_iqm": est["iqm"], "cost_ratio_ci_low": est["ci_low"], "cost_ratio_ci_high": est["ci_high"],
                    "cost_ratio_mean": mean["mean"], "cost_ratio_mean_ci_low": mean["ci_low"],
                    "cost_ratio_mean_ci_high": mean["ci_high"]})
    return out


def _curve_stats(runs: list[dict]) -> dict | None:
    """IQM and CI over runs of the learning curves (a run's score at a point: the mean of its cost
    ratios over the curve episodes), at the points all runs share."""
    curves = [r.get("curve") or [] for r in runs]
    if not curves or not all(curves):
        return None
    n = min(len(c) for c in curves)
    steps, iq, lo, hi = [], [], [], []
    for i in range(n):
        est = interval_estimate(np.array([np.mean(c[i]["cost_ratio"]) for c in curves]), reps=5_000)
        steps.append(int(np.median([c[i]["env_steps"] for c in curves])))
        iq.append(est["iqm"]); lo.append(est["ci_low"]); hi.append(est["ci_high"])
    return {"env_steps": steps, "iqm": iq, "ci_low": lo, "ci_high": hi}


def _overlaps(rows: list[dict]) -> list[list[str]]:
    """Pairs of policies whose cost-ratio CIs overlap (a secondary remark; the paired comparison with
    the paper's controller is the probability of improvement)."""
    out = []
    for i, a in enumerate(rows):
        for b in rows[i + 1:]:
            if a["cost_ratio_ci_low"] <= b["cost_ratio_ci_high"] and b["cost_ratio_ci_low"] <= a["cost_ratio_ci_high"]:
                out.append([a["policy"], b["policy"]])
    return out


def _interval(r: dict, value: str, prefix: str, fmt: str = ".3g") -> str:
    """``r[value] [r[prefix_ci_low], r[prefix_ci_high]]``, or the value alone for a deterministic
    controller (one run: the interval is the point)."""
    m = f"{r[value]:{fmt}}"
    return m if r["runs"] == 1 else f"{m} [{r[f'{prefix}_ci_low']:{fmt}}, {r[f'{prefix}_ci_high']:{fmt}}]"


def _cells(r: dict) -> dict:
    """The table's cells of a row (shared by the text and the Markdown tables)."""
    n = r.get("env_steps")
    steps = "-" if n is None else (f"{n // 1000}k" if n >= 1000 and n % 1000 == 0 else str(n))
    secs = "-" if r.get("train_seconds_median") is None else f"{r['train_seconds_median']:.0f} s"
    cells = {"policy": r["policy"], "kind": r["kind"], "information": r["information"], "runs": str(r["runs"]),
             "steps": steps, "time": secs, "iqm": _interval(r, "cost_ratio_iqm", "cost_ratio"),
             "mean": _interval(r, "cost_ratio_mean", "cost_ratio_mean"), "poi": _interval(r, "poi", "poi", ".2f"),
             "transient": f"{r['transient_cost_iqm']:.4g}", "steady": f"{r['steady_state_error_iqm']:.3g}",
             "fail": f"{r['failure_rate']:.0%}"}
    if "degradation_iqm" in r:
        cells["degradation"] = _interval(r, "degradation_iqm", "degradation")
        cells["degradation_mean"] = _interval(r, "degradation_mean", "degradation_mean")
    return cells


TABLE_COLUMNS = (("policy", "policy"), ("kind", "kind"), ("information", "information"), ("runs", "runs"),
                 ("steps", "env steps per run"), ("time", "train time per run (median)"),
                 ("iqm", "J / J_paper: IQM over runs [95% CI]"), ("mean", "mean J / J_paper [95% CI]"),
                 ("poi", "P(J < J_paper) [95% CI]"), ("transient", f"transient cost (first {TRANSIENT_S:g} s)"),
                 ("steady", f"steady-state error (RMS, last {STEADY_S:g} s)"), ("fail", "failures"))
#: the columns an environment with communication faults adds after ``poi`` (:data:`DEGRADATION_DOC`)
DEGRADATION_COLUMNS = (("degradation", "J / J_paper,fault-free: IQM over runs [95% CI]"),
                       ("degradation_mean", "mean J / J_paper,fault-free [95% CI]"))


def _columns(rows: list[dict]) -> tuple:
    """:data:`TABLE_COLUMNS`, with :data:`DEGRADATION_COLUMNS` after ``poi`` when the rows have them (an
    environment with communication faults)."""
    if not rows or not all("degradation_iqm" in r for r in rows):
        return TABLE_COLUMNS
    k = [key for key, _ in TABLE_COLUMNS].index("poi") + 1
    return TABLE_COLUMNS[:k] + DEGRADATION_COLUMNS + TABLE_COLUMNS[k:]


def format_table(rows: list[dict]) -> str:
    """Text table of :data:`TABLE_COLUMNS` (and :data:`DEGRADATION_COLUMNS` where the rows have them)."""
    columns = _columns(rows)
    cells = [_cells(r) for r in rows]
    width = {k: max(len(h), *(len(c[k]) for c in cells)) for k, h in columns}
    head = " | ".join(f"{h:{width[k]}s}" for k, h in columns)
    lines = [head, "-" * len(head)]
    lines += [" | ".join(f"{c[k]:{width[k]}s}" for k, _ in columns) for c in cells]
    return "\n".join(lines)


def format_markdown(rows: list[dict], overlaps: list[list[str]] | None = None, note: str | None = None) -> str:
    """The table of :func:`format_table` in Markdown (``results.md``), then the note (the paper's row, the
    faults; if any) and, as a secondary remark, the pairs of policies whose cost-ratio CIs overlap."""
    columns = _columns(rows)
    lines = ["| " + " | ".join(h for _, h in columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(c[k] for k, _ in columns) + " |" for c in map(_cells, rows)]
    if note:
        lines += ["", f"Note: {note}."]
    if overlaps is not None:
        lines += ["", "Overlapping 95% CIs of the IQM of J / J_paper: " +
                  ("; ".join(f"{a} / {b}" for a, b in overlaps) if overlaps else "none") + "."]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- figures
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plot_error_norms(payloads: dict, path: str, title: str, task_label: str, reference: dict | None = None) -> None:
    """The mean error norms of every policy of ``payloads`` (label -> runs); ``reference`` (label -> runs, e.g. the
    paper's controller on the fault-free counterpart) drawn dashed black."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    styles = {**{name: {} for name in payloads}, **{name: {"color": "k", "ls": "--"} for name in reference or {}}}
    for name, runs in {**payloads, **(reference or {})}.items():
        # the mean over every (run, episode): runs of one benchmark have the same episodes, so the mean
        # of the runs' means (padded as the episodes are) is that mean
        t = max((np.asarray(r["t"]) for r in runs), key=len)
        for ax, key in zip(axes, ("tracking_error", "estimation_error")):
            ax.plot(t, mean_trajectory([_run_means(r, key) for r in runs]), lw=1.2, label=name, **styles[name])
    axes[0].set_ylabel(f"mean {task_label} over episodes")
    axes[1].set_ylabel(r"mean RMS$_i$ $\|\hat x_i - x\|$ (env observers)")
    for ax in axes:
        ax.set_yscale("log")
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=6)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_curves(curves: dict, path: str, title: str) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4))
    for name, c in curves.items():
        if c is None:
            continue
        line, = ax.plot(c["env_steps"], c["iqm"], marker="o", ms=3, lw=1.3, label=name)
        ax.fill_between(c["env_steps"], c["ci_low"], c["ci_high"], color=line.get_color(), alpha=0.2)
    ax.axhline(1.0, color="k", lw=1, ls="--", label="paper controller")
    ax.set_yscale("log")
    ax.set_xlabel("environment steps")
    ax.set_ylabel(r"$J / J_{paper}$ (IQM, 95% CI over runs)")
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


SUMMARY_XMAX = 10.0  # the summary figure's axis ends here; larger cost ratios are marked at the edge


def _plot_summary(per_env: dict, path: str, title: str) -> None:
    """Per env, every policy's IQM cost ratio and its 95 % CI on a log axis from below the best ratio
    to :data:`SUMMARY_XMAX`; a ratio beyond the axis is drawn as an arrow at its edge. Each row is
    labelled with its figures, so the CIs near 1 stay readable next to failures at 1e4."""
    plt = _plt()
    envs = list(per_env)
    from matplotlib.ticker import NullFormatter

    labels = list(dict.fromkeys(r["policy"] for rows in per_env.values() for r in rows))  # every env's, in order
    ypos = {label: len(labels) - 1 - k for k, label in enumerate(labels)}
    ncols = min(2, len(envs))  # four envs: a 2 x 2 grid
    nrows = -(-len(envs) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.6 * ncols + 3.0, (0.42 * len(labels) + 1.3) * nrows + 0.5),
                             squeeze=False, sharey=True)
    for ax in axes.flat[len(envs):]:
        ax.set_visible(False)
    x_lo = min(0.25, 0.8 * min(r["cost_ratio_ci_low"] for rows in per_env.values() for r in rows))
    for ax, env in zip(axes.flat, envs):
        for r in per_env[env]:
            yi = ypos[r["policy"]]
            color = {"RL": "tab:blue", "hybrid": "tab:green"}.get(r["kind"], "tab:gray")
            lo, hi, m = r["cost_ratio_ci_low"], r["cost_ratio_ci_high"], r["cost_ratio_iqm"]
            if lo < SUMMARY_XMAX:
                ax.plot([lo, min(hi, SUMMARY_XMAX)], [yi, yi], color=color, lw=6, alpha=0.45, solid_capstyle="butt")
            if m < SUMMARY_XMAX:
                ax.plot([m], [yi], "|", color="k", ms=12)
            else:
                ax.plot([SUMMARY_XMAX], [yi], ">", color=color, ms=7, clip_on=False)
            text = f"{m:.3g}" if lo == hi else f"{m:.3g} [{lo:.3g}, {hi:.3g}]"
            if r.get("failure_rate"):
                text += f", {100 * r['failure_rate']:.0f}% fail"
            ax.annotate(text, (1.0, yi), xycoords=("axes fraction", "data"), ha="left", va="center", fontsize=6.5,
                        xytext=(8, 0), textcoords="offset points", annotation_clip=False)
        ax.axvline(1.0, color="k", ls="--", lw=1)
        ax.set_yticks([ypos[label] for label in labels], labels, fontsize=7)
        ax.set_xscale("log")
        ax.set_xlim(x_lo, SUMMARY_XMAX)
        ax.set_ylim(-0.6, len(labels) - 0.4)
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(r"$J / J_{paper}$ (IQM, 95% CI)")
        ax.set_title(env)
        ax.grid(alpha=0.3, axis="x")
    fig.suptitle(f"{title}\n(< 1: cheaper than the paper's controller; bars: 95% CI, whole training runs resampled; "
                 f"> {SUMMARY_XMAX:g}: arrow at the edge)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------- the files
#: the columns of ``results.csv``
CSV_COLUMNS = ["policy", "kind", "information", "runs", "episodes", "env_steps", "train_seconds_median"] + [
    f"{k}_{s}" for k in ("cost_ratio", "transient_cost", "steady_state_error", "final_tracking_error")
    for s in ("iqm", "ci_low", "ci_high")] \
    + ["cost_ratio_mean", "cost_ratio_mean_ci_low", "cost_ratio_mean_ci_high", "poi", "poi_ci_low",
       "poi_ci_high", "cost_ratio_episode_iqm", "failure_rate", "return_mean", "return_std",
       "control_effort_mean", "rms_estimation_error_mean"]
#: the columns of ``results.csv`` an environment with communication faults adds (:data:`DEGRADATION_DOC`)
DEGRADATION_CSV_COLUMNS = [f"degradation_{s}" for s in
                           ("iqm", "ci_low", "ci_high", "mean", "mean_ci_low", "mean_ci_high")]


def _recipe_files(plan: BenchmarkPlan) -> dict:
    """The recipe-file agents' provenance, ``{agent: {"agent", "label", "file", "sha256"}}`` (``{}`` without)."""
    return {k: {**v, "label": agent_spec(k).label} for k, v in plan.recipes.items()}


def _fault_free_cost(env: str, paper: dict, fault_free: dict) -> np.ndarray:
    """The paper's costs on the fault-free counterpart of ``env``, ``(episodes,)``, after checking that its
    episodes are ``env``'s: the same seeds and the same recorded ``x(0)`` (else ``ValueError``: the degradation
    would compare different episodes)."""
    here, there = paper["episodes"], fault_free["episodes"]
    same = [e["seed"] for e in here] == [e["seed"] for e in there] and \
        np.array_equal(np.array([e["x0"] for e in here]), np.array([e["x0"] for e in there]))
    if not same:
        raise ValueError(f"{env}: the paper's controller on the fault-free counterpart {FAULT_FREE[env]!r} was not "
                         f"evaluated on the same episodes (seeds or x(0) differ); the degradation columns need them")
    return np.array([e["cost"] for e in there])


def write_env_report(out: str, env: str, plan: BenchmarkPlan, results: dict, analytic: dict,
                     fault_free: dict | None = None) -> tuple[list, dict]:
    """Aggregate ``env``'s runs and write ``<out>/<env>/results.{json,md,csv}``, ``error_norms.png`` and
    ``learning_curves.png``; returns ``(rows, results document)``.

    ``results``: ``{(env, agent, seed): run payload}`` for every run of ``plan``; ``analytic``: the
    analytic controllers' payloads on ``env`` by label (:func:`agents.benchmark.tasks.analytic_results`);
    ``fault_free``: for an environment with communication faults (:data:`agents.config.envs.FAULT_FREE`, where it
    is required), the paper's controller's payload on the fault-free counterpart
    (:func:`agents.benchmark.tasks.fault_free_paper`): every row then has the degradation columns
    (:data:`DEGRADATION_DOC`) and ``results.json`` the counterpart's episodes under ``fault_free``."""
    if (fault_free is not None) != (env in FAULT_FREE):
        raise ValueError(f"{env}: fault_free is the paper's payload on the fault-free counterpart of an env with "
                         f"communication faults ({sorted(FAULT_FREE)}): "
                         + ("missing" if fault_free is None else "given for an env without faults"))
    budget, training_seeds = plan.budget, plan.training_seeds
    agent_seeds = {k: v for k, v in plan.agent_seeds.items() if k in plan.steps}
    edir = os.path.join(out, env)
    os.makedirs(edir, exist_ok=True)
    paper = analytic[PAPER]
    paper_cost = np.array([ep["cost"] for ep in paper["episodes"]])
    ff_cost = None if fault_free is None else _fault_free_cost(env, paper, fault_free)
    payloads, rows, curves, detail, train_s = {}, [], {}, {}, {}
    for key in plan.steps:
        a = agent_spec(key)
        runs = [results[(env, key, s)] for s in plan.seeds_of(key)]
        payloads[a.label] = runs
        rows.append(_aggregate(a.label, a.kind, runs, paper_cost, information=a.information, steps=plan.steps[key],
                               fault_free_cost=ff_cost))
        curves[a.label] = _curve_stats(runs)
        detail[a.label] = {f"s{r['seed']}": r["episodes"] for r in runs}
        train_s[key] = [0.0 if r.get("cached") or r.get("reevaluated") else r["train_seconds"] for r in runs]
    for label in analytic:
        payloads[label] = [analytic[label]]
        rows.append(_aggregate(label, "analytic", [analytic[label]], paper_cost, information=ANALYTIC_INFO[label],
                               fault_free_cost=ff_cost))
        detail[label] = {"deterministic": analytic[label]["episodes"]}
    note = PAPER_NOTES.get(env)
    reference = None
    if fault_free is not None:
        reference = {f"{PAPER}, {FAULT_FREE[env]} (no faults)": [fault_free]}  # the error-norm figure's reference
        fault_note = FAULTS_NOTE.format(env=env, fault_free=FAULT_FREE[env], ff_mean=float(ff_cost.mean()),
                                        paper_mean=float(paper_cost.mean()))
        note = fault_note if note is None else f"{note}. {fault_note}"
    table = format_table(rows)
    task_label = r"disagreement $\|p - \bar p 1\|$" if env == "hetero_mas" else r"task error $\|x - x_r\|$ or $\|x\|$"
    _plot_error_norms(payloads, os.path.join(edir, "error_norms.png"), f"{env}: {budget} budget", task_label,
                      reference)
    _plot_curves(curves, os.path.join(edir, "learning_curves.png"), f"{env}: learning curves ({budget})")
    metrics_doc = {
        "cost_ratio": "J_policy / J_paper on the same episode; J = -return (LQ cost incl. termination penalty)",
        "transient_cost": f"cost incurred in the first {TRANSIENT_S:g} s",
        "steady_state_error": f"RMS of the task error over the last {STEADY_S:g} s",
        "failure_rate": "fraction of episodes terminated early (state bound exceeded / non-finite)",
        "poi": "probability of improvement P(J_policy < J_paper) over matched (run, episode) pairs",
        "cost_ratio_episode_iqm": "IQM over every (run, episode): the spread over episodes, for reference",
        "train_seconds_median": "median over runs of the training wall time when the run was trained (a jitted "
                                "agent's seeds train vmapped in one task: a run's time is the task's training wall "
                                "time, compilation and learning curves included, divided by its number of seeds; "
                                "each run's result.json train_seconds_shared has the whole)",
    }
    if fault_free is not None:
        metrics_doc["degradation"] = DEGRADATION_DOC
    doc = {
        "env": env, "budget": budget, "training_seeds": list(training_seeds),
        **({"agent_training_seeds": agent_seeds} if agent_seeds else {}), "eval_seeds": plan.eval_seeds,
        "curve_seeds": plan.curve_seeds, "episodes": len(plan.eval_seeds), "env_kwargs": plan.env_kwargs,
        "train_steps": plan.steps, "train_seconds": train_s, "paper_cost": paper_cost.tolist(),
        "recipe_files": _recipe_files(plan),
        "statistics": STATISTICS_DOC,
        "metrics_doc": metrics_doc,
        "paper_note": PAPER_NOTES.get(env),
        "results": rows, "ci_overlaps": _overlaps(rows), "learning_curves": curves, "episodes_detail": detail,
        "table": table,
    }
    if fault_free is not None:
        doc["fault_free"] = {"env": FAULT_FREE[env], "paper_cost": ff_cost.tolist(), "episodes": fault_free["episodes"]}
        doc["fault_note"] = fault_note
    with open(os.path.join(edir, "results.json"), "w") as fh:
        json.dump(doc, fh, indent=1)
    with open(os.path.join(edir, "results.md"), "w") as fh:
        fh.write(format_markdown(rows, doc["ci_overlaps"], note))
    with open(os.path.join(edir, "results.csv"), "w", newline="") as fh:
        columns = CSV_COLUMNS + (DEGRADATION_CSV_COLUMNS if fault_free is not None else [])
        w = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow(r)
    return rows, doc


def write_summary(out: str, plan: BenchmarkPlan, per_env_rows: dict, docs: dict, **extra) -> dict:
    """Write ``<out>/summary.png`` and ``<out>/summary.json`` (every env's table and rows, the aggregate
    over envs, and ``extra`` entries such as the backend and the timings); returns the summary. An env with
    communication faults is named in ``fault_free`` (``{env: its fault-free counterpart}``) and its rows carry
    the ``degradation_*`` keys (``degradation``: :data:`DEGRADATION_DOC`)."""
    _plot_summary(per_env_rows, os.path.join(out, "summary.png"),
                  f"{plan.budget} budget: cost relative to the paper's controller")
    faulted = {e: FAULT_FREE[e] for e in plan.envs if e in FAULT_FREE}
    summary = {"budget": plan.budget, "envs": plan.envs, "training_seeds": list(plan.training_seeds),
               **({"agent_training_seeds": plan.agent_seeds} if plan.agent_seeds else {}),
               "eval_seeds": plan.eval_seeds, "recipe_files": _recipe_files(plan), **extra,
               "statistics": STATISTICS_DOC,
               **({"fault_free": faulted, "degradation": DEGRADATION_DOC} if faulted else {}),
               "tables": {e: docs[e]["table"] for e in plan.envs},
               "results": {e: per_env_rows[e] for e in plan.envs},
               "aggregate_over_envs": aggregate_over_envs(per_env_rows)}
    with open(os.path.join(out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    return summary
