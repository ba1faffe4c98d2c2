"""agents.stats implements rliable's IQM and stratified bootstrap: checked against rliable itself."""
from __future__ import annotations

import numpy as np
import pytest

from agents.stats import interval_estimate, iqm, stratified_bootstrap_ci


def test_iqm_is_the_25_percent_trimmed_mean():
    x = np.arange(1.0, 9.0)  # 8 values: the middle four are 3, 4, 5, 6
    assert iqm(x) == pytest.approx(4.5)
    x[-1] = 1e9  # an outlier does not move it
    assert iqm(x) == pytest.approx(4.5)


def test_single_run_interval_collapses_to_the_point():
    est = interval_estimate(np.array([[0.5, 0.7, 1.1, 0.9]]))
    assert est["ci_low"] == est["ci_high"] == pytest.approx(est["iqm"])
    assert est["runs"] == 1 and est["tasks"] == 4


def test_resampling_is_within_tasks():
    # every run scores the same on a task: resampling runs within tasks cannot change the IQM
    x = np.tile(np.array([0.2, 0.4, 3.0, 7.0]), (5, 1))
    lo, hi = stratified_bootstrap_ci(x, reps=2000)
    assert lo == hi == pytest.approx(iqm(x))


def test_bad_scores_are_named():
    with pytest.raises(ValueError, match="finite"):
        interval_estimate(np.array([[1.0, np.nan]]))
    with pytest.raises(ValueError, match="runs, tasks"):
        interval_estimate(np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="size"):
        stratified_bootstrap_ci(np.ones((2, 2)), size=1.5)


@pytest.mark.filterwarnings("ignore:random_state is deprecated:FutureWarning")
def test_matches_rliable():
    from rliable import library as rly, metrics  # the test extra installs rliable
    rng = np.random.default_rng(3)
    for shape in ((5, 8), (3, 10), (10, 2)):
        x = rng.lognormal(size=shape)
        pe, ie = rly.get_interval_estimates({"a": x}, lambda m: np.array([metrics.aggregate_iqm(m)]), reps=50_000,
                                            random_state=np.random.RandomState(0))
        est = interval_estimate(x, reps=50_000, seed=1)
        assert est["iqm"] == pytest.approx(float(pe["a"][0]), rel=1e-12)
        # two independent 50 000-replicate bootstraps: the percentiles agree to Monte Carlo
        # error (measured <= 0.4 % of the interval width between rliable seeds)
        width = float(ie["a"][1, 0] - ie["a"][0, 0])
        assert abs(est["ci_low"] - float(ie["a"][0, 0])) < 0.03 * width
        assert abs(est["ci_high"] - float(ie["a"][1, 0])) < 0.03 * width
