"""Wall-time projection of independent one-CPU tasks on ``P`` workers (issue 22: distributed design
and the full benchmark on a cluster), from measured per-task durations.

Pure Python (no numpy, no Ray): imported by ``benchmarks/bench_design_ray.py`` and tested by
``tests/test_bench_projection.py`` on hand-computed schedules.

Model
-----
:func:`list_schedule` is greedy list scheduling: the tasks are taken in a given order and each
starts on the worker that becomes free first (ties: the lowest worker index). With ``order="submission"``
that is what a FIFO task queue does (Ray's scheduler with identical one-CPU tasks, the process pool);
``order="lpt"`` sorts longest-first first (Graham's LPT rule, makespan <= (4/3 - 1/(3P)) x optimum).
Any schedule's makespan is at least :func:`lower_bound` ``= max(longest task, total / P)``.

:func:`design_wall_time` adds what the driver does outside the tasks and a per-task overhead, in one
of two forms that bracket where the overhead goes:

* ``"worker"``: each task takes ``d_i + o`` on its worker (deserialising arguments, storing results,
  worker-side scheduling): ``T(P) = S + makespan(d + o, P)``; the overhead spreads over the workers;
* ``"driver"``: the overhead is serial in the driver (submitting every task, fetching and
  deserialising every result): ``T(P) = S + N o + makespan(d, P)``.

:func:`calibrate_overhead` solves either form for ``o`` from one measured wall time.
"""
from __future__ import annotations

import heapq
from typing import Sequence

__all__ = ["ORDERS", "OVERHEAD_MODELS", "list_schedule", "lower_bound", "design_wall_time", "calibrate_overhead"]

ORDERS = ("submission", "lpt")
OVERHEAD_MODELS = ("worker", "driver")


def _check(durations: Sequence[float], workers: int) -> list[float]:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    d = [float(x) for x in durations]
    bad = [x for x in d if not x >= 0.0 or x == float("inf")]
    if bad:
        raise ValueError(f"durations must be finite and >= 0, got {bad[:3]}")
    return d


def list_schedule(durations: Sequence[float], workers: int, order: str = "submission") -> tuple[float, list[int]]:
    """Greedy list schedule of ``durations`` (seconds) on ``workers`` identical workers.

    Returns
    -------
    makespan : float
        When the last task ends (0 for no tasks).
    assignment : list of int, length ``len(durations)``
        The worker (0-based) each task runs on, in the caller's task order.
    """
    d = _check(durations, workers)
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
    idx = list(range(len(d)))
    if order == "lpt":
        idx.sort(key=lambda k: (-d[k], k))  # stable: equal durations keep submission order
    free = [(0.0, w) for w in range(workers)]  # (time the worker becomes free, worker)
    assignment = [0] * len(d)
    end = 0.0
    for k in idx:
        t, w = heapq.heappop(free)
        assignment[k] = w
        t += d[k]
        end = max(end, t)
        heapq.heappush(free, (t, w))
    return end, assignment


def lower_bound(durations: Sequence[float], workers: int) -> float:
    """``max(longest task, total / workers)``: no schedule on ``workers`` workers ends earlier."""
    d = _check(durations, workers)
    return max(max(d, default=0.0), sum(d) / workers)


def design_wall_time(durations: Sequence[float], workers: int, *, serial: float = 0.0, overhead: float = 0.0,
                     model: str = "worker", order: str = "submission") -> float:
    """Projected wall time: driver-side serial part ``serial`` plus the tasks on ``workers`` workers
    with a per-task ``overhead`` placed as ``model`` says (module docstring)."""
    if model not in OVERHEAD_MODELS:
        raise ValueError(f"model must be one of {OVERHEAD_MODELS}, got {model!r}")
    d = _check(durations, workers)
    if model == "worker":
        return serial + list_schedule([x + overhead for x in d], workers, order)[0]
    return serial + len(d) * overhead + list_schedule(d, workers, order)[0]


def calibrate_overhead(durations: Sequence[float], workers: int, wall: float, *, serial: float = 0.0,
                       model: str = "worker", order: str = "submission") -> float:
    """The per-task overhead ``o`` with ``design_wall_time(..., overhead=o) == wall``.

    ``"driver"``: ``o = (wall - serial - makespan(d, workers)) / N`` (closed form). ``"worker"``:
    bisection on ``o`` (to 1e-12 s). A list schedule's makespan can in rare cases jump when a tie
    between workers flips (Graham's anomalies), so the fit is exact only up to such a jump: check
    ``design_wall_time(..., overhead=o)`` against ``wall``. A measured ``wall`` below the
    overhead-free projection gives a negative ``o`` (the durations or ``serial`` were measured slower
    than in the run being fitted), at most ``min(d)`` in size for ``"worker"``.
    """
    d = _check(durations, workers)
    if not d:
        raise ValueError("durations must hold at least one task to calibrate a per-task overhead")
    base = design_wall_time(d, workers, serial=serial, overhead=0.0, model=model, order=order)
    if model == "driver":
        return (wall - base) / len(d)

    def f(o):
        return design_wall_time(d, workers, serial=serial, overhead=o, model="worker", order=order) - wall

    # bracket: makespan(d + o) moves by at least o and at most N o, so |o| <= |wall - base|
    # (within min(d) when negative, where the makespan can no longer shrink by o)
    span = abs(wall - base) + 1e-12
    lo, hi = (-min(span, min(d)), 0.0) if wall < base else (0.0, span)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if f(mid) > 0:
            hi = mid
        else:
            lo = mid
        if hi - lo < 1e-12:
            break
    return 0.5 * (lo + hi)
