"""Step-size convergence of the paper's examples: which residuals are Euler artefacts.

The discontinuous consensus term of the observers (eqs. zidynamic, H_idefine, gammaiis)
leaves, in any fixed-step scheme, a chattering band of width O(dt gamma_is) around the
sliding surface; the theory's limit is zero. NE1 and NE2 converge asymptotically, so their
late errors should fall like ``dt`` (slope 1 on log-log axes); NE3 (leakage in every
adaptive law, Theorem 6's residual set) keeps an O(1) residual whatever ``dt`` (slope ~ 0).

:func:`convergence_study` runs each example at every ``dt`` (compiled closed loop,
:func:`dobs_envs.rollout.rollout`), records every ``1 ms`` of simulated time and reports
the RMS and peak over the last 5 s of the largest estimation error ``max_i ||xhat_i - x||``
and of the task error, with the least-squares slope of ``log(error)`` against ``log(dt)``.
"""
from __future__ import annotations

import numpy as np

from ..rollout import rollout, window_stats
from ..scenarios.paper import PAPER_SCENARIOS
from ._common import run_cells, write_results

__all__ = ["DTS", "SCENARIOS", "convergence_study", "fit_slope"]

#: Euler steps of the study (s)
DTS = (2e-3, 1e-3, 5e-4, 2e-4, 1e-4)
#: examples of the study (the ablation has no switching term to converge)
SCENARIOS = ("ne1", "ne2", "ne3")
#: spacing of the recorded samples (s)
SAMPLE = 1e-3


def fit_slope(dts, errors) -> float:
    """Least-squares slope of ``log(errors)`` against ``log(dts)`` (NaN if an error is not positive)."""
    e = np.asarray(errors, dtype=float)
    if e.size < 2 or np.any(~(e > 0)):
        return float("nan")
    return float(np.polyfit(np.log(np.asarray(dts, dtype=float)), np.log(e), 1)[0])


def _run(name: str, dt: float, t_end: float | None) -> dict:
    sc = PAPER_SCENARIOS[name]()
    stride = max(1, int(round(SAMPLE / dt)))
    tr = rollout(sc, dt=dt, t_end=t_end, record_every=stride)[0]
    est = window_stats(tr.t, np.max(tr.est_err, axis=1))
    task = None if sc.controller == "open_loop" else window_stats(tr.t, tr.tracking_error)
    return {"dt": dt, "estimation_error_last_5s": est, "task_error_last_5s": task}


def convergence_study(out: str | None = None, *, dts=DTS, scenarios=SCENARIOS, t_end: float | None = None,
                      workers: int = 1, plot: bool = True) -> dict:
    """Errors of NE1-NE3 against the Euler step; optionally writes ``convergence.{json,png}`` to ``out``.

    Parameters
    ----------
    out : str, optional
        Output directory (created); ``None``: nothing is written.
    dts : sequence of float
        Euler steps (s), each positive.
    scenarios : sequence of str
        Paper scenario names.
    t_end : float, optional
        Horizon (s); default each scenario's (NE1 30 s, NE2/NE3 20 s).
    workers : int
        Processes running the (scenario, dt) cells in parallel.

    Returns
    -------
    dict
        ``{"dts": [...], "scenarios": {name: {"runs": [...], "slopes": {metric: slope}}}}``; the
        slopes fit ``rms`` and ``peak`` of both errors over all ``dts``.
    """
    dts = [float(d) for d in dts]
    if not dts or any(not (np.isfinite(d) and d > 0) for d in dts):
        raise ValueError(f"dts must be positive finite Euler steps, got {dts!r}")
    unknown = [s for s in scenarios if s not in PAPER_SCENARIOS]
    if unknown:
        raise ValueError(f"unknown scenarios {unknown}; choose from {sorted(PAPER_SCENARIOS)}")
    cells = [(s, d) for s in scenarios for d in dts]
    runs = run_cells(_run, [(s, d, t_end) for s, d in cells], workers)
    res = {"dts": dts, "sample_spacing_s": SAMPLE, "scenarios": {}}
    for s in scenarios:
        rs = [r for (name, _), r in zip(cells, runs) if name == s]
        slopes = {}
        for key in ("estimation_error_last_5s", "task_error_last_5s"):
            if rs[0][key] is None:
                continue
            for stat in ("rms", "peak"):
                slopes[f"{key}.{stat}"] = fit_slope(dts, [r[key][stat] for r in rs])
        res["scenarios"][s] = {"runs": rs, "slopes": slopes}
    write_results(res, out, "convergence", _plot if plot else None)
    return res


def _plot(res: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dts = np.array(res["dts"])
    f, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharex=True)
    for ax, key, title in zip(axes, ("estimation_error_last_5s", "task_error_last_5s"),
                              (r"estimation error $\max_i\|\hat x_i - x\|$", "task error")):
        for c, (s, d) in enumerate(res["scenarios"].items()):
            if d["runs"][0][key] is None:
                continue
            y = [r[key]["rms"] for r in d["runs"]]
            ax.loglog(dts, y, "o-", color=f"C{c}", label=f"{s} (slope {d['slopes'][key + '.rms']:.2f})")
        ref = dts / dts[0]
        ax.loglog(dts, ref * ax.get_ylim()[1] * 0.5, "k:", lw=0.8, label="slope 1")
        ax.set_xlabel("Euler step dt (s)")
        ax.set_ylabel("RMS over the last 5 s")
        ax.set_title(title)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    f.tight_layout()
    f.savefig(path, dpi=110)
    plt.close(f)
