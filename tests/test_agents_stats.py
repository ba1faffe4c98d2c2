"""agents.stats implements rliable's IQM and stratified bootstrap: checked against rliable itself."""
from __future__ import annotations

import numpy as np
import pytest

from agents.stats import (improvement_estimate, interval_estimate, iqm, mean_estimate,
                                    probability_of_improvement, run_bootstrap, run_scores, stratified_bootstrap_ci)


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


# ---------------------------------------------------------------------- the training run as the statistical unit
def _rliable():
    from rliable import library as rly, metrics  # the test extra installs rliable
    return rly, metrics


@pytest.mark.filterwarnings("ignore:random_state is deprecated:FutureWarning")
@pytest.mark.parametrize("runs", [3, 10])
def test_run_scores_interval_matches_rliable_on_the_runs_x_1_matrix(runs):
    rly, metrics = _rliable()
    rng = np.random.default_rng(runs)
    per_episode = rng.lognormal(size=(runs, 20)) * rng.lognormal(sigma=0.8, size=(runs, 1))  # run effects
    s = run_scores(per_episode)
    assert s.shape == (runs,) and np.allclose(s, per_episode.mean(axis=1))
    m = s[:, None]
    for name, func, ours in (("iqm", metrics.aggregate_iqm, interval_estimate(s, seed=2)),
                             ("mean", metrics.aggregate_mean, mean_estimate(s, seed=2))):
        pe, ie = rly.get_interval_estimates({"a": m}, lambda x, f=func: np.array([f(x)]), reps=50_000,
                                            random_state=np.random.RandomState(0))
        assert ours[name] == pytest.approx(float(pe["a"][0]), rel=1e-12)
        # independent 50 000-replicate bootstraps of the same statistic: equal to Monte Carlo error
        width = float(ie["a"][1, 0] - ie["a"][0, 0])
        assert abs(ours["ci_low"] - float(ie["a"][0, 0])) < 0.03 * width
        assert abs(ours["ci_high"] - float(ie["a"][1, 0])) < 0.03 * width


def test_whole_run_resampling_shows_the_spread_between_runs():
    # ten networks, each with its own cost level (0.5 ... 2) on every episode. Resampling whole runs
    # shows that spread; resampling the run independently per episode (the old method) mixes networks
    # within a replicate and averages it away.
    rng = np.random.default_rng(0)
    levels = np.linspace(0.5, 2.0, 10)
    eps = levels[:, None] * (1.0 + 0.01 * rng.standard_normal((10, 20)))
    est = interval_estimate(run_scores(eps), reps=5_000)
    assert est["ci_low"] < 1.0 < 1.5 < est["ci_high"]
    per_episode = interval_estimate(eps, reps=5_000)  # the episode-stratified interval, for contrast
    assert per_episode["ci_high"] - per_episode["ci_low"] < 0.5 * (est["ci_high"] - est["ci_low"])


@pytest.mark.parametrize("shape", [(3, 10), (10, 20), (1, 5)])
def test_probability_of_improvement_matches_rliable(shape):
    _, metrics = _rliable()
    rng = np.random.default_rng(shape[0])
    ref = rng.lognormal(size=shape[1])
    cost = ref[None, :] * rng.lognormal(sigma=0.3, size=shape)
    cost[0, :2] = ref[:2]  # ties count one half
    ours = probability_of_improvement(cost, ref)
    theirs = metrics.probability_of_improvement(-cost, -ref[None, :])  # rliable: higher is better
    assert ours == pytest.approx(float(theirs), abs=1e-12)
    assert probability_of_improvement(ref[None, :], ref) == pytest.approx(0.5)  # the reference against itself


def test_improvement_interval_resamples_whole_runs_as_rliable_defines_each_replicate():
    _, metrics = _rliable()
    rng = np.random.default_rng(7)
    ref = rng.lognormal(size=12)
    cost = ref[None, :] * rng.lognormal(mean=[[-0.2], [0.1], [0.0], [0.3]], sigma=0.2, size=(4, 12))
    est = improvement_estimate(cost, ref, reps=400, seed=5)
    idx = run_bootstrap(4, reps=400, seed=5)
    reps = [metrics.probability_of_improvement(-cost[i], -ref[None, :]) for i in idx]
    lo, hi = np.percentile(reps, [2.5, 97.5])
    assert est["ci_low"] == pytest.approx(lo, abs=1e-12) and est["ci_high"] == pytest.approx(hi, abs=1e-12)
    assert est["poi"] == pytest.approx(float(metrics.probability_of_improvement(-cost, -ref[None, :])), abs=1e-12)


def test_the_mean_sees_a_failure_the_iqm_trims():
    ratios = np.ones((10, 20))
    ratios[3, 5] = 1e12 / 1e3  # one failed episode at its penalty cost
    s = run_scores(ratios)
    assert iqm(s) == pytest.approx(1.0)  # trimmed away
    assert mean_estimate(s, reps=2_000)["mean"] > 4.0


def test_improvement_inputs_are_checked():
    with pytest.raises(ValueError, match="same episodes"):
        probability_of_improvement(np.ones((2, 3)), np.ones(4))
    with pytest.raises(ValueError, match="cost must be finite"):
        improvement_estimate(np.array([[np.nan, 1.0]]), np.ones(2))
    with pytest.raises(ValueError, match="runs must be a positive integer"):
        run_bootstrap(0)


def test_the_former_import_path_gives_the_same_functions():
    import agents.benchmark.stats as former
    import agents.stats as stats

    assert former.__all__ == stats.__all__
    assert all(getattr(former, n) is getattr(stats, n) for n in stats.__all__)
