"""Theorem 6 (adsmthm): the NE3 residual set against epsilon and the adaptation step sizes.

The theorem says the residual set of ``x`` and of the estimation errors "can be made
arbitrarily small by decreasing epsilon in (hepsfunc) and by increasing phi^k, phi_i and
phi_is in (gagasbeta)". :func:`theorem6_study` measures it on NE3 over a grid of
``epsilon`` x gain scale ``s`` (``phi^k, phi_i, phi_is`` all multiplied by ``s``; the
printed setting is ``epsilon = 0.2, s = 1``): per cell the peak of ``||x||`` and of
``max_i ||xhat_i - x||`` over the last 5 s of a 20 s run.

Step size per cell. The boundary layer of (hepsfunc) is stiff (slope ``beta^2 / epsilon``)
and the switching terms leave an O(dt) band, so a too large ``dt`` reports Euler artefacts
(at ``phi^k = 500, dt = 1e-3`` beta runs away). Each cell starts at ``dt = DT0`` and halves
``dt`` until both metrics change by less than ``RTOL`` (5 %) between two successive steps
(or are both below ``ATOL``); the finer run is reported with the ``dt`` used and
``resolved = False`` when ``DT_MIN`` is reached first. Runs of one gain scale share a batch
(the copies differ in ``epsilon``; :func:`dobs_envs.rollout.rollout`).

The *oracle* variant applies the same controller to the true state ``x`` (the observers
still run): it separates what the controller's boundary layer costs from what the
estimation errors cost.
"""
from __future__ import annotations

import numpy as np

from ..rollout import rollout, window_stats
from ..scenarios.paper import ne3
from ._common import run_cells, write_results

__all__ = ["EPSILONS", "GAIN_SCALES", "theorem6_study"]

#: boundary layers of the grid (printed: 0.2)
EPSILONS = (0.2, 0.1, 0.05, 0.02, 0.01)
#: gain scales of the grid (phi^k, phi_i, phi_is multiplied together; printed: 1)
GAIN_SCALES = (1.0, 3.0, 10.0)
PRINTED = (0.2, 1.0)
DT0 = 1e-3
DT_MIN = 3.125e-5
RTOL = 0.05
ATOL = 1e-4
SAMPLE = 1e-3


def _metrics(sc, scale, dt, eps, oracle, t_end):
    stride = max(1, int(round(SAMPLE / dt)))
    trs = rollout(sc, dt=dt, t_end=t_end, batch=len(eps), epsilon=eps, phi_beta=scale * sc.phi_beta,
                  oracle=oracle, record_every=stride)
    out = []
    for tr in trs:
        xs = window_stats(tr.t, np.linalg.norm(tr.x, axis=1))["peak"]
        es = window_stats(tr.t, np.max(tr.est_err, axis=1))["peak"]
        finite = bool(np.isfinite(xs) and np.isfinite(es))
        out.append((xs if finite else float("inf"), es if finite else float("inf"), float(np.max(tr.beta))))
    return out


def _close(a, b):
    return all(abs(p - q) <= max(RTOL * max(abs(p), abs(q)), ATOL) for p, q in zip(a, b))


def _scale_row(scale, epsilons, oracle, t_end, dt0, dt_min):
    sc = ne3()
    sc = sc.replace(phi=scale * sc.phi, phi_s=scale * sc.phi_s)
    eps = list(epsilons)
    cells = {}
    pending = list(range(len(eps)))
    dt = dt0
    prev = dict(zip(pending, _metrics(sc, scale, dt, eps, oracle, t_end)))
    while pending:
        finer = dt / 2
        res = _metrics(sc, scale, finer, [eps[i] for i in pending], oracle, t_end)
        still = []
        for i, r in zip(pending, res):
            ok = _close(prev[i][:2], r[:2])
            if ok or finer / 2 < dt_min:
                cells[i] = {"epsilon": eps[i], "gain_scale": scale, "dt": finer, "resolved": ok,
                            "peak_state_norm_last_5s": r[0], "peak_estimation_error_last_5s": r[1],
                            "max_beta": r[2], "previous_dt_values": [prev[i][0], prev[i][1]]}
            else:
                still.append(i)
            prev[i] = r
        pending, dt = still, finer
    return [cells[i] for i in range(len(eps))]


def theorem6_study(out: str | None = None, *, epsilons=EPSILONS, gain_scales=GAIN_SCALES, t_end: float = 20.0,
                   dt0: float = DT0, dt_min: float = DT_MIN, oracle: bool = True, workers: int = 1,
                   plot: bool = True) -> dict:
    """NE3's residual over ``epsilons`` x ``gain_scales``; optionally writes ``theorem6.{json,png}``.

    Returns
    -------
    dict
        ``{"observer_based": [cell, ...], "oracle": [cell, ...] or None, "printed": [0.2, 1.0], ...}``;
        a cell holds ``epsilon``, ``gain_scale``, the ``dt`` used, ``resolved`` and the peaks of
        ``||x||`` and ``max_i ||xhat_i - x||`` over the last 5 s.
    """
    for name, vals in (("epsilons", epsilons), ("gain_scales", gain_scales)):
        if not len(vals) or any(not (np.isfinite(v) and v > 0) for v in vals):
            raise ValueError(f"{name} must be positive finite numbers, got {vals!r}")
    if not (0 < dt_min <= dt0):
        raise ValueError(f"need 0 < dt_min <= dt0, got dt_min={dt_min!r}, dt0={dt0!r}")
    jobs = [(s, tuple(epsilons), o, t_end, dt0, dt_min) for o in ((False, True) if oracle else (False,))
            for s in gain_scales]
    rows = run_cells(_scale_row, jobs, workers)
    res = {"scenario": "ne3", "printed": list(PRINTED), "epsilons": list(epsilons), "gain_scales": list(gain_scales),
           "t_end": t_end, "rtol": RTOL, "atol": ATOL, "dt0": dt0, "dt_min": dt_min,
           "observer_based": [c for (s, e, o, *_), r in zip(jobs, rows) if not o for c in r],
           "oracle": [c for (s, e, o, *_), r in zip(jobs, rows) if o for c in r] if oracle else None}
    write_results(res, out, "theorem6", _plot if plot else None)
    return res


def _grid(res, cells, key):
    E, S = res["epsilons"], res["gain_scales"]
    g = np.full((len(S), len(E)), np.nan)
    for c in cells:
        g[S.index(c["gain_scale"]), E.index(c["epsilon"])] = float(c[key])
    return g


def _plot(res: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("observer_based", "peak_state_norm_last_5s", r"peak $\|x\|$ (last 5 s)"),
              ("observer_based", "peak_estimation_error_last_5s", r"peak $\max_i\|\hat x_i - x\|$ (last 5 s)")]
    if res["oracle"] is not None:
        panels.append(("oracle", "peak_state_norm_last_5s", r"oracle: peak $\|x\|$ (last 5 s)"))
    E, S = res["epsilons"], res["gain_scales"]
    f, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.6))
    for ax, (variant, key, title) in zip(np.atleast_1d(axes), panels):
        g = _grid(res, res[variant], key)
        unresolved = _grid(res, res[variant], "resolved") == 0
        lg = np.log10(g)
        im = ax.imshow(lg, origin="lower", cmap="viridis", aspect="auto")
        lo, hi = np.nanmin(lg), np.nanmax(lg)
        for i in range(len(S)):
            for j in range(len(E)):
                bright = hi > lo and (lg[i, j] - lo) / (hi - lo) > 0.6
                ax.text(j, i, f"{g[i, j]:.2g}" + ("*" if unresolved[i, j] else ""), ha="center", va="center",
                        fontsize=7, color="k" if bright else "w")
        if PRINTED[0] in E and PRINTED[1] in S:
            ax.add_patch(plt.Rectangle((E.index(PRINTED[0]) - 0.5, S.index(PRINTED[1]) - 0.5), 1, 1, fill=False,
                                       ec="red", lw=2))
        ax.set_xticks(range(len(E)), [f"{e:g}" for e in E])
        ax.set_yticks(range(len(S)), [f"{s:g}" for s in S])
        ax.set_xlabel(r"$\epsilon$")
        ax.set_ylabel(r"gain scale ($\phi^k, \phi_i, \phi_{is}$)")
        ax.set_title(title, fontsize=9)
        f.colorbar(im, ax=ax, label="log10")
    f.suptitle("NE3, Theorem 6 residual (red: printed setting; *: dt_min reached before the 5 % criterion)",
               fontsize=10)
    f.tight_layout()
    f.savefig(path, dpi=110)
    plt.close(f)
