"""``dobs-envs reproduce``: the paper's numerical examples, figures and metrics.

Each scenario is simulated with its paper controller applied at every Euler
step (control period = dt, i.e. the continuous-time laws up to the O(dt) of
the scheme), from the printed initial conditions. Per scenario the command
writes one PNG per paper figure and ``metrics.json`` (see :func:`metrics`).
"""
from __future__ import annotations

import json
import os
import numpy as np

from .paths import OutputPathError, check_output_dir
from .rollout import Trajectory, rollout, rollout_reference, window_stats
from .scenarios.paper import PAPER_SCENARIOS

#: studies run by ``dobs-envs reproduce <study>`` (:mod:`dobs_envs.studies`)
STUDIES = ("convergence", "theorem6", "faults")

__all__ = ["Trajectory", "simulate", "metrics", "reproduce", "add_parser"]


def simulate(sc, *, t_end: float | None = None, dt: float | None = None, backend: str = "numba",
             progress: bool = False) -> Trajectory:
    """Simulate scenario ``sc`` with its paper controller at control period ``dt``.

    ``backend="numba"``: the compiled closed loop (:func:`dobs_envs.rollout.rollout`);
    ``"numpy"``: its reference, a Python loop over the numpy step
    (:func:`dobs_envs.rollout.rollout_reference`, ``progress`` shows a bar).
    """
    if backend == "numba":
        return rollout(sc, dt=dt, t_end=t_end)[0]
    if backend == "numpy":
        return rollout_reference(sc, dt=dt, t_end=t_end, backend="numpy", progress=progress)
    raise ValueError(f"backend must be 'numba' or 'numpy', got {backend!r}")


def metrics(sc, traj: Trajectory, dt: float) -> dict:
    """Summary figures of a run.

    - ``final_estimation_error``: ``max_i ||xhat_i - x||`` at ``t_end``
    - ``final_tracking_error``: ``||x - x_r||`` (``||x||`` without reference) at ``t_end``
    - ``estimation_error_last_5s`` / ``task_error_last_5s``: ``{"rms", "peak", "end"}`` of
      ``max_i ||xhat_i - x||`` / of the task error over the last 5 s (a snapshot at ``t_end``
      can land on a re-adaptation spike: NE3's estimation error is ~0.01 most of the time and
      spikes to ~0.2 when gamma_is leaks below the unknown-input bound)
    - ``max_gamma``, ``max_gamma_s``, ``max_beta``: largest adaptive gains over the run (null if absent)
    - ``gain_growth_last_quarter``: per gain, ``max_i (g_i(t_end) - g_i(0.75 t_end))``
    - ``control_total_variation_smoothed_last_5s`` (the chattering figure):
      ``sum_k sum_j |u_j(t_{k+1}) - u_j(t_k)|`` over the last 5 s after a 51-sample (0.05 s
      at dt = 1e-3) moving average
    - ``control_total_variation_raw_last_5s``: the same without smoothing; it is dominated
      by the step-sized O(dt gamma_is) ripple of the observers' switching term
    - ``control_max_increment_last_5s``: ``max_{k,j} |u_j(t_{k+1}) - u_j(t_k)|``, the chattering amplitude
    - ``max_abs_u``: largest input magnitude over the run
    """
    t_end = float(traj.t[-1])
    q = int(np.searchsorted(traj.t, 0.75 * t_end))
    last5 = int(np.searchsorted(traj.t, max(0.0, t_end - 5.0)))
    growth = {"gamma": float(np.max(traj.gamma[-1] - traj.gamma[q])),
              "gamma_s": float(np.max(traj.gamma_s[-1] - traj.gamma_s[q]))}
    if traj.beta is not None:
        growth["beta"] = float(np.max(traj.beta[-1] - traj.beta[q]))
    u = traj.u[last5:-1]
    win = min(51, len(u))
    u_smooth = (np.array([np.convolve(u[:, j], np.ones(win) / win, mode="valid") for j in range(u.shape[1])]).T
                if win > 1 else u)
    def window(y):
        return window_stats(traj.t, y)

    open_loop = sc.controller == "open_loop"
    return {
        "scenario": sc.name,
        "final_estimation_error": float(np.max(traj.est_err[-1])),
        "estimation_error_last_5s": window(np.max(traj.est_err, axis=1)),
        "task_error_last_5s": None if open_loop else window(traj.tracking_error),
        # NE1 applies prescribed open-loop inputs: there is no tracking/stabilisation objective
        "final_tracking_error": None if sc.controller == "open_loop" else float(traj.tracking_error[-1]),
        "error_kind": ("none (open-loop inputs)" if sc.controller == "open_loop"
                       else "tracking ||x - x_r||" if traj.x_r is not None else "stabilisation ||x||"),
        "max_gamma": float(np.max(traj.gamma)),
        "max_gamma_s": float(np.max(traj.gamma_s)),
        "max_beta": None if traj.beta is None else float(np.max(traj.beta)),
        "gain_growth_last_quarter": growth,
        "control_total_variation_raw_last_5s": float(np.sum(np.abs(np.diff(u, axis=0)))) if len(u) > 1 else 0.0,
        "control_total_variation_smoothed_last_5s": float(np.sum(np.abs(np.diff(u_smooth, axis=0)))) if len(u_smooth) > 1 else 0.0,
        "control_max_increment_last_5s": float(np.max(np.abs(np.diff(u, axis=0)))) if len(u) > 1 else 0.0,
        "max_abs_u": float(np.max(np.abs(traj.u))),
        "t_end": t_end,
        "dt": float(dt),
    }


def _plot(traj: Trajectory, sc, outdir: str) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []

    def fig(name, ys, ylabel, labels, logy=False):
        f, ax = plt.subplots(figsize=(6, 3.4))
        for y, lab in zip(ys, labels):
            ax.plot(traj.t, y, lw=1.0, label=lab)
        ax.set_xlabel("t (s)")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{sc.name}: {ylabel}")
        if logy:
            ax.set_yscale("log")
        if len(labels) > 1:
            ax.legend(fontsize=7, ncol=3)
        ax.grid(alpha=0.3)
        f.tight_layout()
        path = os.path.join(outdir, name)
        f.savefig(path, dpi=110)
        plt.close(f)
        files.append(path)

    N = traj.est_err.shape[1]
    open_loop = sc.controller == "open_loop"
    fig("estimation_error.png", traj.est_err.T,
        r"$\|\hat x_i - x\|$" + (" (the objective: open-loop inputs)" if open_loop else ""),
        [f"node {i + 1}" for i in range(N)], logy=open_loop)
    fig("gamma.png", traj.gamma.T, r"$\gamma_i$", [f"node {i + 1}" for i in range(N)])
    fig("gamma_s.png", traj.gamma_s.T, r"$\gamma_{is}$", [f"node {i + 1}" for i in range(N)])
    if open_loop:  # NE1: prescribed inputs, no control objective; the state norm is context only
        fig("state_norm_open_loop.png", [traj.tracking_error], r"$\|x\|$ under the open-loop inputs (no objective)",
            ["state norm"], logy=True)
    elif traj.x_r is not None:
        fig("tracking_error.png", [traj.tracking_error], r"$\|x - x_r\|$", ["tracking error"])
    else:
        fig("stabilisation_error.png", [traj.tracking_error], r"$\|x\|$", ["state norm"])
    fig("control_inputs.png", traj.u.T, r"$u$", [f"u{j + 1}" for j in range(traj.u.shape[1])])
    if traj.beta is not None:
        fig("beta.png", traj.beta.T, r"$\beta^k$", [f"controller {k + 1}" for k in range(traj.beta.shape[1])])
    return files


def reproduce(names, out: str, *, t_end: float | None = None, dt: float | None = None,
              backend: str = "numba", progress: bool = True, plots: bool = True) -> dict:
    """Run the named paper scenarios; write figures and ``metrics.json`` under ``out/<name>/``."""
    results = {}
    for name in names:
        if name not in PAPER_SCENARIOS:
            raise ValueError(f"unknown scenario {name!r}; choose from {sorted(PAPER_SCENARIOS)} or 'all'")
        sc = PAPER_SCENARIOS[name]()
        dt_ = sc.dt if dt is None else dt
        traj = simulate(sc, t_end=t_end, dt=dt_, backend=backend, progress=progress)
        met = metrics(sc, traj, dt_)
        outdir = os.path.join(out, name)
        os.makedirs(outdir, exist_ok=True)
        if plots:
            met["figures"] = [os.path.basename(f) for f in _plot(traj, sc, outdir)]
        with open(os.path.join(outdir, "metrics.json"), "w") as fh:
            json.dump(met, fh, indent=2)
        results[name] = met
    return results


def _positive_float(text: str) -> float:
    import argparse
    import math

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text!r}")
    return v


def add_parser(sub) -> None:
    p = sub.add_parser("reproduce", help="reproduce the paper's numerical examples (figures + metrics.json)")
    p.add_argument("scenario", choices=sorted(PAPER_SCENARIOS) + ["all"] + list(STUDIES),
                   help="a paper example, 'all' of them, or a study: 'convergence' (errors vs Euler step, "
                        "log-log slopes), 'theorem6' (NE3 residual over epsilon x gain scale) or 'faults' "
                        "(NE2 under communication faults: exchange period, loss, delays, switching; 10 seeds)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--t-end", type=_positive_float, default=None,
                   help="horizon in seconds (default: the scenario's: NE1 30 s, NE2/NE3 20 s)")
    p.add_argument("--dt", type=_positive_float, default=None, help="Euler step (default 1e-3)")
    p.add_argument("--backend", choices=["numba", "numpy"], default="numba",
                   help="numba: compiled closed loop; numpy: the reference Python loop (slow)")
    p.add_argument("--workers", type=int, choices=[1, 2, 4, 8], default=2,
                   help="processes running the cells of a study (default 2)")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of a previous run in --out (refused otherwise)")
    p.set_defaults(func=_run, parser=p)


def _check_out(args) -> None:
    """Usage error (exit 2) when ``--out`` is a file or already holds this command's results."""
    try:
        check_output_dir(args.out, "--out")
    except OutputPathError as exc:
        args.parser.error(str(exc))
    if args.scenario in STUDIES:
        targets = [os.path.join(args.out, f"{args.scenario}.json")]
    else:
        names = list(PAPER_SCENARIOS) if args.scenario == "all" else [args.scenario]
        targets = [os.path.join(args.out, n, "metrics.json") for n in names]
    done = [t for t in targets if os.path.exists(t)]
    if done and not args.overwrite:
        args.parser.error(f"--out {args.out!r} already holds results ({done[0]}); pass --overwrite to replace them "
                          "or choose another --out")


def _run_study(args) -> int:
    from .studies import convergence_study, faults_study, theorem6_study
    from .studies.faults import summary as faults_summary

    for name, val in (("--t-end", args.t_end), ("--dt", args.dt)):
        if val is not None:
            args.parser.error(f"{name} does not apply to the {args.scenario} study (it chooses its own steps)")
    if args.scenario == "convergence":
        res = convergence_study(args.out, workers=args.workers)
        for name, d in res["scenarios"].items():
            sl = ", ".join(f"{k} {v:.2f}" for k, v in d["slopes"].items())
            print(f"{name:5s} slopes of log(error) vs log(dt): {sl}")
    elif args.scenario == "faults":
        print(faults_summary(faults_study(args.out, workers=args.workers)))
    else:
        res = theorem6_study(args.out, workers=args.workers)
        for variant in ("observer_based", "oracle"):
            for c in res[variant] or ():
                print(f"{variant:14s} eps={c['epsilon']:<5g} scale={c['gain_scale']:<4g} dt={c['dt']:.3g}"
                      f"{'' if c['resolved'] else ' (unresolved)'}  peak ||x|| {c['peak_state_norm_last_5s']:.3g}"
                      f"  peak est. err {c['peak_estimation_error_last_5s']:.3g}")
    print(f"wrote {args.out}")
    return 0


def _run(args) -> int:
    _check_out(args)
    if args.scenario in STUDIES:
        return _run_study(args)
    names = list(PAPER_SCENARIOS) if args.scenario == "all" else [args.scenario]
    res = reproduce(names, args.out, t_end=args.t_end, dt=args.dt, backend=args.backend, progress=not args.no_progress)
    for name, met in res.items():
        ee, te = met["estimation_error_last_5s"], met["task_error_last_5s"]
        task = "n/a (open loop)" if te is None else f"{te['end']:.3g} (rms {te['rms']:.3g}, peak {te['peak']:.3g})"
        print(f"{name:13s} estimation error end {ee['end']:.3g} (last 5 s: rms {ee['rms']:.3g}, peak {ee['peak']:.3g})"
              f"  task error {task}  max_gamma={met['max_gamma']:.4g}  max_gamma_s={met['max_gamma_s']:.4g}"
              f"  max_beta={met['max_beta']}  TV_u smoothed(last 5 s)={met['control_total_variation_smoothed_last_5s']:.3g}")
    print(f"wrote {args.out}")
    return 0
