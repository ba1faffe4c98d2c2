"""Communication faults against the paper's controller on NE2 (issue 23): degradation curves and table.

What is run
-----------
NE2 (:func:`~dobs_envs.scenarios.paper.ne2`, Theorem reftrackthm) with its paper controller
``u^k = K^k xhat_k + r^k`` in the compiled closed loop :func:`dobs_envs.rollout.rollout`: the law is
applied at every Euler step (``dt = 1 ms``: the continuous-time law up to O(dt)), the observer
network carrying the communication faults of :mod:`dobs_envs.sim.faults`. Every setting changes one
fault of the ideal network (one factor at a time; :func:`settings`):

- ``oo_period``: the O-O exchange period, 1 / 5 / 10 / 25 / 50 / 100 ms (1 ms is the Euler step:
  the ideal exchange except inside split Euler steps);
- ``oo_loss``: the O-O loss probability 0 / 0.1 / 0.3 / 0.5 at the ideal exchange (a packet every
  Euler step), and ``oo_loss@50ms``: the same losses at a 50 ms exchange period (one packet per
  control period of the environments);
- ``oo_delay`` and ``co_delay``: the O-O and the C-O delay, 0 / 2 / 5 / 10 control periods (two
  sweeps);
- ``switching``: the O-O graph follows a Markov chain over NE2's ring and two disconnected graphs
  (the ring without two opposite edges: two paths of three nodes, the two cuts different, so the
  union of the graphs is the ring) at 0 / 0.1 / 1 / 10 switches per second, starting on the ring.
  Two thirds of the long-run time are spent on a disconnected graph: Assumption ooconnected holds
  only on average.

Units: the control period
-------------------------
The paper's controller is continuous-time and :func:`~dobs_envs.rollout.rollout` applies it at
every Euler step, so the fault model's control period there is ``dt`` (rollout's module doc). The
study expresses delays in the environments' control period ``T = dt * substeps = 50 ms``
(:class:`~dobs_envs.envs.options.EnvOptions`' defaults ``dt = 1 ms``, ``substeps = 50``;
:func:`control_period_steps`): a delay of ``D``
control periods is passed to rollout as ``D * 50`` Euler steps, the same delay in seconds as
``oo_delay = D`` / ``co_delay = D`` in ``tracking_v0`` (an O-O packet carries the sender's estimate
of ``D T`` seconds before; a controller reads, at every Euler step, the estimate its observer node
had ``D T`` seconds before). Losses are drawn per Euler step and link in rollout, which is per
packet: at the ideal exchange a lost packet costs one millisecond of staleness; at a 50 ms exchange
every packet is one control period's, and a per-packet loss is then exactly the environments'
per-period loss of a link. Switching rates are per second: rollout steps the chain every Euler
step (leave probability ``1 - exp(-rate dt)``), the environments every 50 ms (``1 - exp(-rate T)``),
the same continuous-time chain up to the step at which a switch is seen. The engine's semantics are
not changed; the rollout-level fault values of every setting are in the JSON (``faults``).

Seeds and initial states
------------------------
Seed ``s`` (default 0..9) draws what ``tracking_v0``'s ``reset(seed=s)`` draws, in its order, from
``numpy.random.default_rng(s)``: the initial plant state (NE2's printed ``x0`` plus ``U[-a, a]^9``,
``a = init_noise``, default 1 as in the environments;
:class:`~dobs_envs.envs.distributions.ResetDistribution`), then the copy's fault seed
(:mod:`dobs_envs.sim.fault_rng`). The other initial conditions are the printed ones (``z_i(0) = 0``,
``x_r(0) = 0``, ``gamma_i(0) = gamma_is(0) = 0.1``). So the spread over seeds holds the initial
state's and, where faults are random, the faults' variability; ``init_noise = 0`` starts every copy
from the printed ``x0`` (deterministic faults then give equal copies). The seeds of a setting run as
one batch (one rollout call).

Metrics
-------
Per copy, from samples every millisecond: the tracking error ``||x - x_r||`` and the estimation
error ``max_i ||xhat_i - x||`` (:attr:`~dobs_envs.rollout.Trajectory.tracking_error`,
``est_err``), their RMS over the last ``window`` seconds (5 s) and over the ``window`` before it, the
largest adaptive gains ``gamma_i`` and ``gamma_is`` of the run (the observers' gains are
non-decreasing in NE2: no leakage) and their growth over its last quarter
(``max_i (g_i(t_end) - g_i(0.75 t_end))``). Per setting: mean, sample standard deviation (ddof 1),
minimum and maximum over the copies whose figures are finite (``per_seed`` keeps every copy).

Settled. A copy has settled when, for both errors, the RMS of the last window is within
``SETTLE_RTOL`` (10 %) of the RMS of the window before (``|a - b| <= rtol max(a, b)``) or both are
below ``SETTLE_ATOL`` (1e-3, under the O(dt) band of the ideal run at ``dt = 1 ms``, ~5e-3: it
never decides at the study's defaults); a setting has settled (``settled``) when every finite copy
has. ``settled_mean`` applies the same test to the means over the finite copies: under random
switching a single copy's 5 s windows differ by which graphs they happened to hold, while their
mean over seeds may be stationary. A setting that has not settled (``settled`` false) is run again,
with the same seeds, at ``long_factors`` (2, 4, 8) times the horizon in turn, until it settles, all its
copies diverge or the factors run out; every rerun is kept (``long_runs``). Diverged: a copy whose figures are not finite (the compiled loop runs with numpy's
error model, so an overflow gives inf/NaN, not an exception); it is counted in ``n_diverged`` and
left out of the aggregates, and ``None`` stands for its figures in the JSON.

Outputs (``out``): ``faults.json`` (:func:`faults_study`'s dict), ``faults.png`` (the degradation
curves: RMS of both errors against each swept value, mean and min-max band over seeds, log scale)
and ``faults_trajectories.png`` (seed 0's errors and gains at a few settings, :data:`TRAJECTORIES`).
"""
from __future__ import annotations

import os
import math

import numpy as np

from ..envs.distributions import ResetDistribution
from ..envs.options import EnvOptions
from ..rollout import rollout
from ..scenarios.paper import ne2
from ..sim.faults import MAX_DELAY, Faults
from ._common import run_cells, write_results

__all__ = ["EXCHANGE_PERIODS", "LOSSES", "DELAYS", "SWITCHING_RATES", "LOSS_EXCHANGE_PERIOD", "T_END", "WINDOW",
           "SETTLE_RTOL", "SETTLE_ATOL", "LONG_FACTORS", "SWEEPS", "TRAJECTORIES", "faults_study", "settings",
           "switching_graphs", "markdown_table", "summary"]

#: O-O exchange periods of the sweep (s): the Euler step .. 0.1 s
EXCHANGE_PERIODS = (0.001, 0.005, 0.01, 0.025, 0.05, 0.1)
#: O-O loss probabilities of the two loss sweeps
LOSSES = (0.0, 0.1, 0.3, 0.5)
#: exchange period of the second loss sweep (s): one packet per control period of the environments
LOSS_EXCHANGE_PERIOD = 0.05
#: O-O and C-O delays of the sweeps (control periods of the environments, 50 ms)
DELAYS = (0, 2, 5, 10)
#: switching rates of the graph chain (switches per second)
SWITCHING_RATES = (0.0, 0.1, 1.0, 10.0)
#: horizon (s) and the length of the error windows (s)
T_END = 20.0
WINDOW = 5.0
#: settled criterion (module doc): relative change between the last two windows, absolute floor
SETTLE_RTOL = 0.1
SETTLE_ATOL = 1e-3
#: horizon factors of the successive reruns of a setting that has not settled (module doc)
LONG_FACTORS = (2.0, 4.0, 8.0)
#: spacing of the recorded samples (s)
SAMPLE = 1e-3

#: the sweeps: key -> (axis label, unit of the values)
SWEEPS = {
    "ideal": ("ideal network (faults=None)", ""),
    "oo_period": ("O-O exchange period", "ms"),
    "oo_loss": ("O-O loss probability (exchange every Euler step)", ""),
    "oo_loss@50ms": ("O-O loss probability (exchange every 50 ms)", ""),
    "oo_delay": ("O-O delay (control periods of 50 ms)", "T"),
    "co_delay": ("C-O delay (control periods of 50 ms)", "T"),
    "switching": ("graph switching rate (ring + 2 disconnected graphs)", "1/s"),
}
#: settings whose seed-0 trajectories are drawn: (sweep, value)
TRAJECTORIES = (("ideal", None), ("oo_period", 50.0), ("oo_loss@50ms", 0.3), ("oo_delay", 10), ("co_delay", 10),
                ("switching", 1.0))


def control_period_steps(dt: float) -> int:
    """Euler steps of length ``dt`` per control period of the environments (``EnvOptions``' defaults:
    ``dt * substeps = 1 ms * 50``)."""
    opts = EnvOptions()
    q = opts.dt * opts.substeps / dt
    if abs(q - round(q)) > 1e-9 * q:
        raise ValueError(f"the environments' control period {opts.dt * opts.substeps:g} s is not a multiple of dt = {dt:g} s")
    return int(round(q))


def switching_graphs(sc) -> list:
    """NE2's ring (``sc``'s graph) and the two disconnected graphs of the switching sweep: the ring without
    edges 3-4 and 6-1 (paths 1-2-3, 4-5-6), and without edges 1-2 and 4-5 (paths 2-3-4, 5-6-1)."""
    ring = np.array(sc.graph.adjacency, dtype=float)
    out = [ring]
    for cut in (((2, 3), (5, 0)), ((0, 1), (3, 4))):
        a = ring.copy()
        for i, j in cut:
            if a[i, j] == 0:
                raise ValueError(f"switching_graphs: the scenario's graph has no edge {i + 1}-{j + 1} (expected NE2's ring)")
            a[i, j] = a[j, i] = 0.0
        out.append(a)
    return out


def settings(sc, *, exchange_periods=EXCHANGE_PERIODS, losses=LOSSES, loss_exchange_period=LOSS_EXCHANGE_PERIOD,
             delays=DELAYS, switching_rates=SWITCHING_RATES, graphs=None) -> list[dict]:
    """The settings of the study, one factor at a time from the ideal network (module doc).

    Returns
    -------
    list of dict
        ``{"sweep", "value", "faults"}``: ``value`` in the sweep's unit (:data:`SWEEPS`; ``None`` for the
        ideal network), ``faults`` the :class:`~dobs_envs.sim.faults.Faults` keys given to rollout
        (Euler-step units; ``None``: no fault code runs).
    """
    S = control_period_steps(sc.dt)
    out = [{"sweep": "ideal", "value": None, "faults": None}]
    for h in exchange_periods:
        out.append({"sweep": "oo_period", "value": round(float(h) * 1e3, 9), "faults": {"oo_period": float(h)}})
    for p in losses:
        out.append({"sweep": "oo_loss", "value": float(p), "faults": {"oo_loss": float(p)}})
    if loss_exchange_period is not None:
        for p in losses:
            out.append({"sweep": "oo_loss@50ms", "value": float(p),
                        "faults": {"oo_period": float(loss_exchange_period), "oo_loss": float(p)}})
    for key in ("oo_delay", "co_delay"):
        for d in delays:
            out.append({"sweep": key, "value": int(d), "faults": {key: int(d) * S}})
    gs = switching_graphs(sc) if graphs is None else [np.asarray(g, dtype=float) for g in graphs]
    for r in switching_rates:
        out.append({"sweep": "switching", "value": float(r),
                    "faults": {"switching": {"graphs": [g.tolist() for g in gs], "rate": float(r), "initial": 0}}})
    for s in out:  # validated here, in the caller's process, with the engine's own messages
        if s["faults"] is not None:
            Faults.from_value(s["faults"]).exchange_steps(sc.dt)
    return out


def _seeds(seeds) -> list[int]:
    if isinstance(seeds, (int, np.integer)) and not isinstance(seeds, bool):
        if seeds < 1:
            raise ValueError(f"seeds must be a positive count or a list of non-negative ints, got {seeds!r}")
        return list(range(int(seeds)))
    try:
        out = list(seeds)
    except TypeError:
        raise ValueError(f"seeds must be a positive count or a list of non-negative ints, got {seeds!r}") from None
    if not out or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in out) \
            or len(set(out)) != len(out):
        raise ValueError(f"seeds must be a positive count or a list of distinct non-negative ints, got {seeds!r}")
    return [int(s) for s in out]


def initial_draws(sc, seeds, init_noise=None) -> tuple[np.ndarray, np.ndarray]:
    """``(x0 (B, n), fault seeds (B,) uint64)``: per seed, what ``tracking_v0``'s ``reset(seed=s)`` draws
    from ``default_rng(s)`` (module doc): the initial state, then the fault seed."""
    dist = ResetDistribution(sc, init_noise, "none", 0.0)
    X0 = np.empty((len(seeds), sc.n_states))
    fseeds = np.empty(len(seeds), dtype=np.uint64)
    for b, s in enumerate(seeds):
        rng = np.random.default_rng(s)
        X0[b] = dist.x0(rng)
        fseeds[b] = rng.integers(0, 2**64, dtype=np.uint64)
    return X0, fseeds


def _rms(t, y, lo, hi):
    """RMS of the samples ``y`` at ``lo <= t < hi`` (to half a sample spacing: ``t`` is ``k * spacing``)."""
    h = 0.5 * (t[1] - t[0])
    sel = (t >= lo - h) & (t < hi - h)
    return float(np.sqrt(np.mean(np.asarray(y)[sel] ** 2)))


def _copy_metrics(tr, window: float) -> dict:
    """The figures of one copy (module doc); non-finite ones as they are (the caller marks the copy)."""
    t = tr.t
    t_end = float(t[-1])
    e_tr, e_est = tr.tracking_error, np.max(tr.est_err, axis=1)
    q = int(np.searchsorted(t, 0.75 * t_end))
    return {
        "tracking_rms_last": _rms(t, e_tr, t_end - window, t_end + 1),
        "tracking_rms_previous": _rms(t, e_tr, t_end - 2 * window, t_end - window),
        "estimation_rms_last": _rms(t, e_est, t_end - window, t_end + 1),
        "estimation_rms_previous": _rms(t, e_est, t_end - 2 * window, t_end - window),
        "max_gamma": float(np.max(tr.gamma)),
        "max_gamma_s": float(np.max(tr.gamma_s)),
        "gamma_growth_last_quarter": float(np.max(tr.gamma[-1] - tr.gamma[q])),
        "gamma_s_growth_last_quarter": float(np.max(tr.gamma_s[-1] - tr.gamma_s[q])),
    }


def _settled_copy(m: dict, rtol: float, atol: float) -> bool:
    for key in ("tracking", "estimation"):
        a, b = m[f"{key}_rms_last"], m[f"{key}_rms_previous"]
        if not (max(a, b) <= atol or abs(a - b) <= rtol * max(a, b)):
            return False
    return True


def _run_setting(faults, seeds, init_noise, t_end, window, trace):
    """One setting, all seeds in one batch: per-copy figures and (``trace``) seed 0's downsampled errors."""
    sc = ne2(t_end=t_end)
    X0, fseeds = initial_draws(sc, seeds, init_noise)
    stride = max(1, int(round(SAMPLE / sc.dt)))
    trs = rollout(sc, t_end=t_end, batch=len(seeds), x0=X0, faults=faults, fault_seed=fseeds, record_every=stride)
    copies = [_copy_metrics(tr, window) for tr in trs]
    tr0 = None
    if trace:
        tr = trs[0]
        k = max(1, int(round(0.02 / (tr.t[1] - tr.t[0]))))  # every 20 ms
        tr0 = {"t": tr.t[::k].tolist(), "tracking_error": tr.tracking_error[::k].tolist(),
               "estimation_error": np.max(tr.est_err, axis=1)[::k].tolist(),
               "max_gamma": np.max(tr.gamma, axis=1)[::k].tolist(),
               "max_gamma_s": np.max(tr.gamma_s, axis=1)[::k].tolist()}
    return {"copies": copies, "trace": tr0}


def _finite(v):
    return v if v is not None and math.isfinite(v) else None


def _aggregate(copies: list[dict], rtol: float, atol: float, t_end: float) -> dict:
    """Mean / std / min / max over the finite copies, ``per_seed`` lists, diverged and settled counts."""
    keys = list(copies[0])
    ok = [all(math.isfinite(c[k]) for k in keys) for c in copies]
    res = {"t_end": t_end, "n_diverged": int(len(copies) - sum(ok))}
    for k in keys:
        vals = np.array([c[k] for c, f in zip(copies, ok) if f])
        stats = None
        if vals.size:
            stats = {"mean": float(vals.mean()), "std": float(vals.std(ddof=1)) if vals.size > 1 else 0.0,
                     "min": float(vals.min()), "max": float(vals.max())}
        res[k] = dict(stats or {"mean": None, "std": None, "min": None, "max": None},
                      per_seed=[_finite(c[k]) if f else None for c, f in zip(copies, ok)])
    settled = [_settled_copy(c, rtol, atol) for c, f in zip(copies, ok) if f]
    res["n_settled"] = int(sum(settled))
    res["settled"] = bool(settled) and all(settled)
    res["settled_mean"] = bool(settled) and _settled_copy({k: res[k]["mean"] for k in keys}, rtol, atol)
    return res


def faults_study(out: str | None = None, *, seeds=10, t_end: float = T_END, window: float = WINDOW,
                 init_noise: float | None = None, exchange_periods=EXCHANGE_PERIODS, losses=LOSSES,
                 loss_exchange_period: float | None = LOSS_EXCHANGE_PERIOD, delays=DELAYS,
                 switching_rates=SWITCHING_RATES, graphs=None, long_factors=LONG_FACTORS,
                 workers: int = 1, plot: bool = True) -> dict:
    """The paper's controller on NE2 under each fault (module doc); optionally writes ``faults.json``,
    ``faults.png`` and ``faults_trajectories.png`` to ``out``.

    Parameters
    ----------
    out : str, optional
        Output directory (created); ``None``: nothing is written.
    seeds : int or sequence of int
        The seeds (a count ``k``: ``0 .. k-1``), one copy each in every setting.
    t_end, window : float
        Horizon and length of the error windows (s); ``2 window <= t_end``.
    init_noise : float, optional
        Half-width of the uniform noise on NE2's printed ``x0`` (default: the environments', 1).
    exchange_periods, losses, loss_exchange_period, delays, switching_rates : sequences (and a float or None)
        The swept values (module doc, :func:`settings`); ``loss_exchange_period=None`` leaves out the
        second loss sweep. Delays in control periods of 50 ms.
    graphs : list of (6, 6) adjacency matrices, optional
        The graphs of the switching chain (default :func:`switching_graphs`; the chain starts on the first).
    long_factors : sequence of float
        Increasing horizon factors (> 1) of the successive reruns of a setting that has not settled
        (empty: no reruns).
    workers : int
        Processes running the settings.
    plot : bool
        Draw the figures (when ``out`` is given).

    Returns
    -------
    dict
        The study's constants and ``settings``: per setting ``sweep``, ``value``, ``faults`` (rollout's
        keys) and the figures of :func:`_aggregate` (``tracking_rms_last`` .. ``gamma_s_growth_last_quarter``,
        each ``{"mean", "std", "min", "max", "per_seed"}``; ``n_diverged``, ``n_settled``, ``settled``,
        ``settled_mean``),
        with ``long_runs`` the same for each rerun, at ``long_factors[k] * t_end`` in turn (each with its
        ``t_end``; empty when settled at ``t_end``).
    """
    seeds = _seeds(seeds)
    for name, v in (("t_end", t_end), ("window", window)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive number of seconds, got {v!r}")
    if 2 * window > t_end:
        raise ValueError(f"t_end must hold two error windows (2 window = {2 * window:g} s), got t_end={t_end!r}")
    factors = [float(f) for f in long_factors]
    if any(not (math.isfinite(f) and f > 1) for f in factors) or factors != sorted(set(factors)):
        raise ValueError(f"long_factors must be increasing factors > 1 (empty: no reruns), got {list(long_factors)!r}")
    if init_noise is not None and not (math.isfinite(init_noise) and init_noise >= 0):
        raise ValueError(f"init_noise must be >= 0 or None, got {init_noise!r}")
    sc = ne2(t_end=t_end)
    S = control_period_steps(sc.dt)
    bad = [d for d in delays if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or not 0 <= d * S <= MAX_DELAY]
    if bad:
        raise ValueError(f"delays must be integers in [0, {MAX_DELAY // S}] (control periods of {S} Euler steps), "
                         f"got {list(delays)!r}")
    rates = [float(r) for r in switching_rates]
    if any(not (math.isfinite(r) and r >= 0) for r in rates):
        raise ValueError(f"switching_rates must be >= 0 (switches per second), got {list(switching_rates)!r}")
    cells = settings(sc, exchange_periods=exchange_periods, losses=losses, loss_exchange_period=loss_exchange_period,
                     delays=delays, switching_rates=rates, graphs=graphs)
    traced = [any(c["sweep"] == s and (v is None or c["value"] == v) for s, v in TRAJECTORIES) for c in cells]
    runs = run_cells(_run_setting, [(c["faults"], tuple(seeds), init_noise, t_end, window, tr)
                                    for c, tr in zip(cells, traced)], workers)
    results = [dict(c, **_aggregate(r["copies"], SETTLE_RTOL, SETTLE_ATOL, t_end)) for c, r in zip(cells, runs)]
    for r in results:
        r["long_runs"] = []
    long_ts = [float(f * t_end) for f in factors]
    for long_t in long_ts:  # rerun, longer each time, what has not settled and has a finite copy left
        last = [_last_rerun(r) or r for r in results]
        redo = [i for i, a in enumerate(last) if not a["settled"] and a["n_diverged"] < len(seeds)]
        reruns = run_cells(_run_setting, [(cells[i]["faults"], tuple(seeds), init_noise, long_t, window, False)
                                          for i in redo], workers)
        for i, r in zip(redo, reruns):
            results[i]["long_runs"].append(_aggregate(r["copies"], SETTLE_RTOL, SETTLE_ATOL, long_t))
    res = {
        "scenario": "ne2",
        "controller": "paper (u^k = K^k xhat_k + r^k at every Euler step, dobs_envs.rollout.rollout)",
        "dt": sc.dt,
        "control_period_s": sc.dt * S,
        "control_period_steps": S,
        "t_end": float(t_end),
        "window_s": float(window),
        "long_t_ends": long_ts,
        "sample_spacing_s": SAMPLE,
        "seeds": seeds,
        "init_noise": init_noise,
        "initial_state": "NE2's printed x0 + U[-a, a]^9 drawn from default_rng(seed) as tracking_v0's reset, "
                         "then the fault seed; z(0) = 0, x_r(0) = 0, gamma(0) = gamma_s(0) = 0.1",
        "metrics": {"tracking_rms_last": "RMS of ||x - x_r|| over the last window",
                    "tracking_rms_previous": "RMS of ||x - x_r|| over the window before",
                    "estimation_rms_last": "RMS of max_i ||xhat_i - x|| over the last window",
                    "estimation_rms_previous": "RMS of max_i ||xhat_i - x|| over the window before",
                    "max_gamma": "largest gamma_i over the run", "max_gamma_s": "largest gamma_is over the run",
                    "gamma_growth_last_quarter": "max_i gamma_i(t_end) - gamma_i(0.75 t_end)",
                    "gamma_s_growth_last_quarter": "max_i gamma_is(t_end) - gamma_is(0.75 t_end)",
                    "aggregates": "mean, std (ddof 1), min, max over the finite copies; per_seed: None = diverged"},
        "settled_criterion": {"rtol": SETTLE_RTOL, "atol": SETTLE_ATOL,
                              "text": "a copy has settled when, for both errors, |last - previous| <= rtol * "
                                      "max(last, previous) or both <= atol; a setting (settled) when all its "
                                      "finite copies have, settled_mean: the same test on the means over the "
                                      "finite copies; settings not settled are rerun at each of long_t_ends "
                                      "in turn until they settle or all their copies diverge"},
        "sweeps": {k: {"label": v[0], "unit": v[1]} for k, v in SWEEPS.items()},
        "settings": results,
    }
    write_results(res, out, "faults", _plot if plot else None)
    if out is not None and plot:
        tr = [(c, r["trace"]) for c, r in zip(cells, runs) if r["trace"] is not None]
        _plot_trajectories(tr, os.path.join(out, "faults_trajectories.png"))
    return res


def _fmt(stats: dict) -> str:
    if stats["mean"] is None:
        return "diverged"
    return f"{stats['mean']:.3g} ± {stats['std']:.2g} [{stats['min']:.3g}, {stats['max']:.3g}]"


def _value_text(s: dict) -> str:
    if s["sweep"] == "ideal":
        return "-"
    unit = SWEEPS[s["sweep"]][1]
    return f"{s['value']:g}" + (f" {unit}" if unit else "")


def _last_rerun(setting: dict) -> dict | None:
    """The longest rerun of ``setting`` (the last of ``long_runs``), or None if it was not rerun."""
    return setting["long_runs"][-1] if setting["long_runs"] else None


def markdown_table(res: dict) -> str:
    """The degradation table (Markdown): per setting the RMS errors over the last window (mean ± std
    [min, max] over seeds), the settled flags (settled copies / finite copies; the means), for a setting rerun the
    errors of its last (longest) rerun, and the largest adaptive gains over the seeds."""
    w, n = f"{res['window_s']:g} s", len(res["seeds"])
    lines = [f"| fault | value | tracking RMS, last {w} | estimation RMS, last {w} | settled by {res['t_end']:g} s "
             f"| last rerun: tracking / estimation RMS (settled) | max gamma_i / gamma_is |", "|" + "---|" * 7]

    def flag(a):
        if a["n_diverged"] == n:
            return "all diverged"
        txt = f"{a['n_settled']}/{n - a['n_diverged']} copies, mean {'yes' if a['settled_mean'] else 'no'}"
        return txt + (f", {a['n_diverged']} diverged" if a["n_diverged"] else "")

    for s in res["settings"]:
        lg = _last_rerun(s)
        long_txt = ("-" if lg is None else f"all diverged by {lg['t_end']:g} s" if lg["n_diverged"] == n else
                    f"at {lg['t_end']:g} s: {_fmt(lg['tracking_rms_last'])} / {_fmt(lg['estimation_rms_last'])} "
                    f"({flag(lg)})")
        g, gs = s["max_gamma"]["max"], s["max_gamma_s"]["max"]
        gains = "diverged" if g is None else f"{g:.3g} / {gs:.3g}"
        lines.append(f"| {s['sweep']} | {_value_text(s)} | {_fmt(s['tracking_rms_last'])} | "
                     f"{_fmt(s['estimation_rms_last'])} | {flag(s)} | {long_txt} | {gains} |")
    return "\n".join(lines)


def summary(res: dict) -> str:
    """A compact text table of the study (one line per setting), what ``dobs-envs reproduce faults`` prints."""
    out = [f"NE2, paper's controller: RMS over the last {res['window_s']:g} s of {res['t_end']:g} s, mean ± std over "
           f"{len(res['seeds'])} seeds (delays in control periods of {res['control_period_s']:g} s)"]
    for c in res["settings"]:
        tr, es = c["tracking_rms_last"], c["estimation_rms_last"]
        fig = ("diverged" if tr["mean"] is None else
               f"tracking {tr['mean']:.3g} ± {tr['std']:.2g}  estimation {es['mean']:.3g} ± {es['std']:.2g}")
        late = "".join(f"  at {lg['t_end']:g} s: all diverged" if lg["tracking_rms_last"]["mean"] is None
                       else (f"  at {lg['t_end']:g} s: {lg['tracking_rms_last']['mean']:.3g} / "
                             f"{lg['estimation_rms_last']['mean']:.3g}{'' if lg['settled'] else ' (not settled)'}"
                             f"{', ' + str(lg['n_diverged']) + ' diverged' if lg['n_diverged'] else ''}")
                       for lg in c["long_runs"])
        div = f", {c['n_diverged']} diverged" if c["n_diverged"] else ""
        flag = "settled" if c["settled"] else (f"NOT settled ({c['n_settled']} copies"
                                               f"{', mean settled' if c['settled_mean'] else ''})")
        out.append(f"{c['sweep']:13s} {_value_text(c):>8s}  {fig}  {flag}{div}{late}")
    return "\n".join(out)


def _plot(res: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sweeps = [k for k in SWEEPS if k != "ideal" and any(s["sweep"] == k for s in res["settings"])]
    ideal = next((s for s in res["settings"] if s["sweep"] == "ideal"), None)
    f, axes = plt.subplots(2, len(sweeps), figsize=(3.0 * len(sweeps), 5.6), squeeze=False)
    for col, key in enumerate(sweeps):
        ss = [s for s in res["settings"] if s["sweep"] == key]
        x = np.arange(len(ss))
        for row, (metric, name) in enumerate((("tracking_rms_last", "tracking"), ("estimation_rms_last", "estimation"))):
            ax = axes[row, col]
            st = [s[metric] for s in ss]
            mean = np.array([np.nan if v["mean"] is None else v["mean"] for v in st])
            lo = np.array([np.nan if v["min"] is None else v["min"] for v in st])
            hi = np.array([np.nan if v["max"] is None else v["max"] for v in st])
            ax.fill_between(x, lo, hi, color="C0", alpha=0.25, lw=0, label="min-max over seeds")
            ax.plot(x, mean, "o-", color="C0", label="mean over seeds")
            for xi, s, m in zip(x, ss, mean):
                if not s["settled"]:
                    ax.plot(xi, m, "o", mfc="w", mec="C3", ms=9, label="not settled (some copy)")
                if s["n_diverged"]:
                    ax.axvline(xi, color="C3", ls=":", lw=1, label="copies diverged")
                lg = _last_rerun(s)
                if lg is not None and lg[metric]["mean"] is not None:
                    ax.plot(xi, lg[metric]["mean"], "x", color="0.3", ms=7, label=f"mean at {lg['t_end']:g} s")
                elif lg is not None:
                    ax.plot(xi, m, "^", color="C3", ms=8, label=f"all diverged by {lg['t_end']:g} s")
            if ideal is not None and ideal[metric]["mean"] is not None:
                ax.axhline(ideal[metric]["mean"], color="k", ls="--", lw=0.8, label="ideal network")
            ax.set_yscale("log")
            ax.set_xticks(x, [f"{s['value']:g}" for s in ss])
            label, unit = SWEEPS[key]
            if row == 1:
                ax.set_xlabel(label + (f" ({unit})" if unit and unit != "T" else ""), fontsize=7)
            if col == 0:
                ax.set_ylabel(f"{name} error RMS, last {res['window_s']:g} s")
            ax.grid(alpha=0.3, which="both")
    handles = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    f.legend(handles.values(), handles.keys(), fontsize=7, loc="lower center", ncol=len(handles))
    f.suptitle(f"NE2, paper's controller: RMS errors over the last {res['window_s']:g} s of {res['t_end']:g} s "
               f"({len(res['seeds'])} seeds)", fontsize=10)
    f.tight_layout(rect=(0, 0.05, 1, 1))
    f.savefig(path, dpi=110)
    plt.close(f)


def _plot_trajectories(traces, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    for c, (cell, tr) in enumerate(traces):
        lab = "ideal" if cell["sweep"] == "ideal" else f"{cell['sweep']} = {_value_text(cell)}"
        t = np.array(tr["t"])
        for ax, key in zip(axes, ("tracking_error", "estimation_error", "max_gamma_s")):
            ax.plot(t, tr[key], lw=0.8, color=f"C{c}", label=lab)
    for ax, title in zip(axes, (r"tracking error $\|x - x_r\|$", r"estimation error $\max_i\|\hat x_i - x\|$",
                                r"$\max_i \gamma_{is}$")):
        ax.set_yscale("log")
        ax.set_xlabel("t (s)")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=6)
    f.suptitle("NE2, paper's controller, seed 0 (sampled every 20 ms)", fontsize=10)
    f.tight_layout()
    f.savefig(path, dpi=110)
    plt.close(f)
