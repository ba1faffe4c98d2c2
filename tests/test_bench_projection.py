"""The list-scheduling projection of benchmarks/projection.py (issue 22) on hand-computed schedules."""
from __future__ import annotations

import importlib.util
import os

import pytest

_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks", "projection.py")
_spec = importlib.util.spec_from_file_location("bench_projection", _PATH)
proj = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(proj)


def test_submission_order_schedule_by_hand():
    # 2 workers, FIFO: t=0 w0<-3, w1<-1; t=1 w1<-2 (ends 3); t=3 tie, w0 (lower index) <-4 (ends 7),
    # w1 <-1 (ends 4); makespan 7
    makespan, assignment = proj.list_schedule([3, 1, 2, 4, 1], 2)
    assert makespan == 7.0
    assert assignment == [0, 1, 1, 0, 1]


def test_lpt_schedule_by_hand():
    # LPT on the same tasks: 4 -> w0, 3 -> w1, 2 -> w1 (ends 5), 1 -> w0 (ends 5), 1 -> w0 (ends 6)
    makespan, assignment = proj.list_schedule([3, 1, 2, 4, 1], 2, order="lpt")
    assert makespan == 6.0
    assert assignment == [1, 0, 1, 0, 0]
    assert proj.lower_bound([3, 1, 2, 4, 1], 2) == 5.5
    assert proj.lower_bound([3, 1, 2, 4, 1], 100) == 4.0


def test_more_workers_than_tasks_and_no_tasks():
    assert proj.list_schedule([2.0, 5.0], 128)[0] == 5.0
    assert proj.list_schedule([], 4) == (0.0, [])


def test_overhead_models_and_their_calibration():
    d = [1.0] * 10
    # worker model: each task 1 + 0.1 on 2 workers -> 5 tasks each -> 5.5, plus serial 2
    assert proj.design_wall_time(d, 2, serial=2.0, overhead=0.1, model="worker") == pytest.approx(7.5)
    # driver model: 2 + 10 * 0.1 + 5
    assert proj.design_wall_time(d, 2, serial=2.0, overhead=0.1, model="driver") == pytest.approx(8.0)
    assert proj.calibrate_overhead(d, 2, 7.5, serial=2.0, model="worker") == pytest.approx(0.1, abs=1e-9)
    assert proj.calibrate_overhead(d, 2, 8.0, serial=2.0, model="driver") == pytest.approx(0.1, abs=1e-12)
    # a run faster than the overhead-free projection: negative overhead
    assert proj.calibrate_overhead(d, 2, 6.5, serial=2.0, model="worker") == pytest.approx(-0.1, abs=1e-9)


@pytest.mark.parametrize("bad, match", [(dict(workers=0), "workers must be an integer >= 1"),
                                        (dict(durations=[1.0, -1.0]), "durations must be finite and >= 0"),
                                        (dict(order="random"), "order must be one of")])
def test_bad_arguments_are_named(bad, match):
    kw = dict(durations=[1.0, 2.0], workers=2, order="submission")
    kw.update(bad)
    with pytest.raises(ValueError, match=match):
        proj.list_schedule(**kw)
