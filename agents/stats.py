"""Aggregate statistics over training runs, as defined by rliable (Agarwal et al., 2021).

*Deep Reinforcement Learning at the Edge of the Statistical Precipice* (NeurIPS 2021)
defines, for a score matrix ``scores (runs, tasks)``:

- the **interquartile mean** (IQM): the 25 %-trimmed mean of all ``runs x tasks``
  scores (``rliable.metrics.aggregate_iqm`` = ``scipy.stats.trim_mean(scores, 0.25,
  axis=None)``);
- the **stratified bootstrap** confidence interval: each replicate resamples the
  runs *with replacement independently within every task* (``task_bootstrap=False``,
  rliable's default), applies the aggregate, and the ``(1 - size)/2`` and
  ``(1 + size)/2`` percentiles of the replicates bound the interval (rliable's
  ``method="percentile"``).

In this benchmark a *run* is a training seed and a *task* is an evaluation episode
(the same seeded initial condition for every policy), so the interval is the
uncertainty due to training seeds on a fixed set of evaluation conditions. A
deterministic analytic controller has one run: its interval collapses to the point.

Why not ``rliable`` itself: its import chain (``arch``) fails with pandas 3
(``TypeError`` in ``arch.univariate.base`` at import, measured with rliable 1.2.0,
arch 7.2.0, pandas 3.1.1), which would pin every user's pandas. The two functions
below are the definitions, vectorised in numpy; ``tests/test_agents_stats.py``
checks them against rliable's own implementation.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import trim_mean

__all__ = ["iqm", "stratified_bootstrap_ci", "interval_estimate"]


def _as_scores(scores) -> np.ndarray:
    a = np.asarray(scores, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.size == 0:
        raise ValueError(f"scores must be a non-empty (runs, tasks) matrix, got shape {np.shape(scores)}")
    if not np.all(np.isfinite(a)):
        raise ValueError("scores must be finite (a failed episode must be scored, not NaN)")
    return a


def iqm(scores, axis=None) -> np.ndarray | float:
    """Interquartile mean: ``scipy.stats.trim_mean(scores, 0.25, axis)`` (rliable's ``aggregate_iqm``)."""
    return trim_mean(np.asarray(scores, dtype=np.float64), proportiontocut=0.25, axis=axis)


def stratified_bootstrap_ci(scores, *, reps: int = 50_000, size: float = 0.95, seed: int = 0,
                            chunk: int = 5_000) -> tuple[float, float]:
    """Percentile CI of :func:`iqm` under the stratified bootstrap over runs.

    Parameters
    ----------
    scores : (runs, tasks) array (a 1-D array is one run).
    reps : bootstrap replicates (rliable's default 50 000).
    size : coverage of the interval.
    seed : seed of the resampling (the interval is reproducible).

    Returns
    -------
    (low, high) : the ``100 (1 - size)/2`` and ``100 (1 + size)/2`` percentiles of the
        replicated IQMs.
    """
    a = _as_scores(scores)
    if not 0.0 < size < 1.0:
        raise ValueError(f"size must be in (0, 1), got {size!r}")
    runs, tasks = a.shape
    rng = np.random.default_rng(seed)
    cols = np.arange(tasks)[None, None, :]
    stats = []
    for start in range(0, int(reps), chunk):
        r = min(chunk, int(reps) - start)
        idx = rng.integers(0, runs, size=(r, runs, tasks))  # runs resampled within each task
        stats.append(iqm(a[idx, cols].reshape(r, -1), axis=1))
    s = np.concatenate(stats)
    lo, hi = np.percentile(s, [50.0 * (1.0 - size), 50.0 * (1.0 + size)])
    return float(lo), float(hi)


def interval_estimate(scores, **kw) -> dict:
    """``{"iqm", "ci_low", "ci_high", "runs", "tasks"}`` of a (runs, tasks) score matrix."""
    a = _as_scores(scores)
    lo, hi = stratified_bootstrap_ci(a, **kw)
    return {"iqm": float(iqm(a)), "ci_low": lo, "ci_high": hi, "runs": int(a.shape[0]), "tasks": int(a.shape[1])}
