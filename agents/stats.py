"""Statistics over training runs, as defined by rliable (Agarwal et al., 2021).

*Deep Reinforcement Learning at the Edge of the Statistical Precipice* (NeurIPS 2021) works
on a score matrix ``scores (runs, tasks)`` with **one score per training run and task**:

- the **interquartile mean** (IQM): the 25 %-trimmed mean of all ``runs x tasks`` scores
  (``rliable.metrics.aggregate_iqm`` = ``scipy.stats.trim_mean(scores, 0.25, axis=None)``);
- the **stratified bootstrap** confidence interval: each replicate resamples the runs *with
  replacement independently within every task* (rliable's ``StratifiedBootstrap``,
  ``task_bootstrap=False``), applies the aggregate, and the ``(1 - size)/2`` and
  ``(1 + size)/2`` percentiles of the replicates bound the interval (``method="percentile"``);
- the **probability of improvement** ``P(X > Y)`` of algorithm X over Y: per task the
  Mann-Whitney statistic over every pair of runs, ``mean_{i,j} [x_i > y_j] + 1/2 [x_i = y_j]``,
  averaged over tasks (``rliable.metrics.probability_of_improvement``).

How the benchmark (``agents.benchmark``) uses them; the recipe comparison (``agents.tune.compare``) uses
the IQM and the probability of improvement over its runs' scores:

- The **training run is the statistical unit.** The score of a run on an environment is the
  mean over its evaluation episodes of the cost ratio ``J / J_paper`` (a failed episode at its
  cost with the termination penalty). One environment is one task: the matrix is
  ``(runs, 1)``, whose stratified bootstrap resamples whole runs. Several environments
  aggregated together are several tasks (``(runs, envs)``; runs resampled within each
  environment, as rliable does over games). The episodes of one run come from the same
  network, so they are never resampled independently (that would average away the spread
  between training runs, which the interval has to show).
- The **probability of improvement** over the paper's controller is computed on matched
  (run, episode) pairs: every evaluation episode is one task of rliable's definition, on which
  the agent's runs meet the deterministic paper controller (one run), with "X better" meaning
  a lower cost. Its interval resamples whole runs (:func:`run_bootstrap`), again so that the
  spread between runs shows.

Why not ``rliable`` itself: its import chain (``arch``) fails with pandas 3
(``TypeError`` in ``arch.univariate.base`` at import, measured with rliable 1.2.0,
arch 7.2.0, pandas 3.1.1), which would pin every user's pandas. The functions below are the
definitions, vectorised in numpy; ``tests/test_agents_stats.py`` checks them against
rliable's own implementation.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import trim_mean

__all__ = ["iqm", "stratified_bootstrap_ci", "interval_estimate", "run_bootstrap", "run_scores",
           "probability_of_improvement", "improvement_estimate", "mean_estimate", "REPS"]

#: bootstrap replicates (rliable's default)
REPS = 50_000


def _as_scores(scores, name: str = "scores") -> np.ndarray:
    a = np.asarray(scores, dtype=np.float64)
    if a.ndim == 1:
        a = a[:, None]  # one score per run, one task
    if a.ndim != 2 or a.size == 0:
        raise ValueError(f"{name} must be a non-empty (runs, tasks) matrix, got shape {np.shape(scores)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (a failed episode must be scored, not NaN)")
    return a


def _check_size(size: float) -> None:
    if not 0.0 < size < 1.0:
        raise ValueError(f"size must be in (0, 1), got {size!r}")


def _percentiles(stats: np.ndarray, size: float) -> tuple[float, float]:
    lo, hi = np.percentile(stats, [50.0 * (1.0 - size), 50.0 * (1.0 + size)])
    return float(lo), float(hi)


def iqm(scores, axis=None) -> np.ndarray | float:
    """Interquartile mean: ``scipy.stats.trim_mean(scores, 0.25, axis)`` (rliable's ``aggregate_iqm``)."""
    return trim_mean(np.asarray(scores, dtype=np.float64), proportiontocut=0.25, axis=axis)


def run_scores(matrix) -> np.ndarray:
    """One score per run: the mean over its episodes of a ``(runs, episodes)`` matrix -> ``(runs,)``."""
    return _as_scores(np.atleast_2d(np.asarray(matrix, dtype=np.float64)), "matrix").mean(axis=1)


def stratified_bootstrap_ci(scores, *, statistic=iqm, reps: int = REPS, size: float = 0.95, seed: int = 0,
                            chunk: int = 5_000) -> tuple[float, float]:
    """Percentile CI of ``statistic`` under rliable's stratified bootstrap over runs.

    Parameters
    ----------
    scores : (runs, tasks) array, one score per run and task (a 1-D array: one task).
    statistic : aggregate of a ``(reps, runs * tasks)`` array along ``axis=1`` (default :func:`iqm`;
        ``np.mean`` for the mean).
    reps : bootstrap replicates (rliable's default 50 000).
    size : coverage of the interval.
    seed : seed of the resampling (the interval is reproducible).

    Returns
    -------
    (low, high) : the ``100 (1 - size)/2`` and ``100 (1 + size)/2`` percentiles of the replicates.
    """
    a = _as_scores(scores)
    _check_size(size)
    runs, tasks = a.shape
    rng = np.random.default_rng(seed)
    cols = np.arange(tasks)[None, None, :]
    stats = []
    for start in range(0, int(reps), chunk):
        r = min(chunk, int(reps) - start)
        idx = rng.integers(0, runs, size=(r, runs, tasks))  # runs resampled within each task
        stats.append(statistic(a[idx, cols].reshape(r, -1), axis=1))
    return _percentiles(np.concatenate(stats), size)


def interval_estimate(scores, **kw) -> dict:
    """``{"iqm", "ci_low", "ci_high", "runs", "tasks"}`` of a (runs, tasks) score matrix (IQM and its
    stratified-bootstrap CI)."""
    a = _as_scores(scores)
    lo, hi = stratified_bootstrap_ci(a, **kw)
    return {"iqm": float(iqm(a)), "ci_low": lo, "ci_high": hi, "runs": int(a.shape[0]), "tasks": int(a.shape[1])}


def mean_estimate(scores, **kw) -> dict:
    """``{"mean", "ci_low", "ci_high"}``: the mean of a (runs, tasks) score matrix and its
    stratified-bootstrap CI (the aggregate a failure cannot hide: no trimming)."""
    a = _as_scores(scores)
    lo, hi = stratified_bootstrap_ci(a, statistic=np.mean, **kw)
    return {"mean": float(a.mean()), "ci_low": lo, "ci_high": hi}


def run_bootstrap(runs: int, *, reps: int = REPS, seed: int = 0) -> np.ndarray:
    """Resampled run indices ``(reps, runs)``: whole runs drawn with replacement (every episode of
    a drawn run comes with it)."""
    if isinstance(runs, bool) or not isinstance(runs, (int, np.integer)) or runs < 1:
        raise ValueError(f"runs must be a positive integer, got {runs!r}")
    return np.random.default_rng(seed).integers(0, int(runs), size=(int(reps), int(runs)))


def probability_of_improvement(cost, reference) -> float:
    """``P(J < J_ref)`` over matched (run, episode) pairs (rliable's definition, lower cost = better).

    Parameters
    ----------
    cost : (runs, episodes) costs (or cost ratios) of the policy.
    reference : (ref_runs, episodes) or (episodes,) costs of the reference on the same episodes
        (one run for the deterministic paper controller).

    Returns
    -------
    The mean over episodes of ``mean_{i, j} ([cost_i < ref_j] + 1/2 [cost_i = ref_j])``, which is
    ``rliable.metrics.probability_of_improvement(-cost, -reference)``.
    """
    x = _as_scores(np.atleast_2d(np.asarray(cost, dtype=np.float64)), "cost")
    y = _as_scores(np.atleast_2d(np.asarray(reference, dtype=np.float64)), "reference")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"cost and reference must have the same episodes, got {x.shape[1]} and {y.shape[1]}")
    return float(_poi(x[None], y)[0])


def _poi(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``(reps, runs, episodes)`` against ``(ref_runs, episodes)`` -> ``(reps,)``."""
    less = (x[:, :, None, :] < y[None, None, :, :]).mean(axis=(1, 2))
    ties = (x[:, :, None, :] == y[None, None, :, :]).mean(axis=(1, 2))
    return (less + 0.5 * ties).mean(axis=1)


def improvement_estimate(cost, reference, *, reps: int = REPS, size: float = 0.95, seed: int = 0,
                         chunk: int = 2_000) -> dict:
    """``{"poi", "ci_low", "ci_high"}``: :func:`probability_of_improvement` and its percentile CI
    under :func:`run_bootstrap` (the policy's runs resampled whole; the reference is deterministic
    or fixed)."""
    x = _as_scores(np.atleast_2d(np.asarray(cost, dtype=np.float64)), "cost")
    y = _as_scores(np.atleast_2d(np.asarray(reference, dtype=np.float64)), "reference")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"cost and reference must have the same episodes, got {x.shape[1]} and {y.shape[1]}")
    _check_size(size)
    idx = run_bootstrap(x.shape[0], reps=reps, seed=seed)
    stats = np.concatenate([_poi(x[idx[s:s + chunk]], y) for s in range(0, len(idx), chunk)])
    lo, hi = _percentiles(stats, size)
    return {"poi": float(_poi(x[None], y)[0]), "ci_low": lo, "ci_high": hi}
