"""The compiled closed loop (dobs_envs.rollout) against its reference, and the studies built on it.

Parity tolerance: both paths evaluate the same formulas per Euler step in double precision
(the law's dot products and the estimate sums in a different order), so they differ by
round-off, measured <= 1e-15 relative over 300 steps; 1e-9 leaves room for the growth of
round-off through the switching terms without hiding a wrong formula (which shows at 1e-3).
"""
import json

import numpy as np
import pytest

from dobs_envs.cli import main
from dobs_envs.rollout import rollout, rollout_reference
from dobs_envs.scenarios.paper import PAPER_SCENARIOS, ne2, ne3
from dobs_envs.studies.convergence import convergence_study, fit_slope
from dobs_envs.studies.theorem6 import theorem6_study

FIELDS = ("x", "est_err", "gamma", "gamma_s", "u")


def _assert_same(a, b, rtol=1e-9):
    for f in FIELDS:
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=rtol, atol=rtol, err_msg=f)
    if b.beta is not None:
        np.testing.assert_allclose(a.beta, b.beta, rtol=rtol, atol=rtol)
    if b.x_r is not None:
        np.testing.assert_allclose(a.x_r, b.x_r, rtol=rtol, atol=rtol)
    np.testing.assert_allclose(a.t, b.t)


@pytest.mark.parametrize("name", sorted(PAPER_SCENARIOS))
def test_compiled_loop_matches_reference(name):
    sc = PAPER_SCENARIOS[name]()
    _assert_same(rollout(sc, t_end=0.3)[0], rollout_reference(sc, t_end=0.3, backend="numpy"))


def test_copies_with_different_epsilon_match_single_reference_runs():
    sc = ne3()
    eps = [0.2, 0.05, 0.01]
    batch = rollout(sc, t_end=0.5, batch=3, epsilon=eps, phi_beta=20.0)
    for e, tr in zip(eps, batch):
        _assert_same(tr, rollout_reference(sc.replace(epsilon=e, phi_beta=20.0), t_end=0.5))
    # the copies really differ (beta saturates the boundary layer differently)
    assert not np.allclose(batch[0].u, batch[2].u)


def test_oracle_uses_the_true_state():
    sc = ne3()
    a = rollout(sc, t_end=0.3, oracle=True)[0]
    _assert_same(a, rollout_reference(sc, t_end=0.3, oracle=True))
    assert not np.allclose(a.u, rollout(sc, t_end=0.3)[0].u)


def test_record_every_samples_the_full_run():
    sc = ne2()
    full = rollout(sc, t_end=0.2)[0]
    sub = rollout(sc, t_end=0.2, record_every=10)[0]
    np.testing.assert_array_equal(sub.x, full.x[::10])
    np.testing.assert_array_equal(sub.est_err, full.est_err[::10])
    np.testing.assert_array_equal(sub.u[:-1], full.u[:-1:10])
    np.testing.assert_allclose(sub.t, full.t[::10])


@pytest.mark.parametrize("kwargs, match", [
    ({"batch": 0}, "batch must be >= 1"),
    ({"record_every": 0}, "record_every must be >= 1"),
    ({"epsilon": -0.1}, "epsilon must be positive"),
    ({"phi_beta": [1.0, np.nan], "batch": 2}, "phi_beta must be positive"),
    ({"dt": 0.0}, "dt must be positive"),
    ({"t_end": np.inf}, "t_end must be positive and finite"),
])
def test_rollout_rejects_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        rollout(ne3(), **{"t_end": 0.1, **kwargs})


def test_fit_slope_of_a_power_law():
    dts = np.array([1e-3, 5e-4, 2e-4])
    assert fit_slope(dts, 3.0 * dts ** 1.5) == pytest.approx(1.5)
    assert np.isnan(fit_slope(dts, [1.0, 0.0, 1.0]))


def test_ne2_late_errors_are_an_euler_band(tmp_path):
    """NE2 converges asymptotically (Theorem reftrackthm): its late error is the O(dt) band of
    the switching term, so halving dt halves it (slope 1; measured 1.00 over 2e-3..1e-4)."""
    res = convergence_study(str(tmp_path), dts=(1e-3, 5e-4), scenarios=("ne2",))  # 20 s: past the transient
    slopes = res["scenarios"]["ne2"]["slopes"]
    assert slopes["estimation_error_last_5s.rms"] == pytest.approx(1.0, abs=0.15)
    assert slopes["task_error_last_5s.rms"] == pytest.approx(1.0, abs=0.15)
    assert json.loads((tmp_path / "convergence.json").read_text()) == res
    assert (tmp_path / "convergence.png").stat().st_size > 1000


def test_theorem6_cell_halves_dt_until_the_metrics_settle(tmp_path):
    res = theorem6_study(str(tmp_path), epsilons=(0.2,), gain_scales=(1.0,), t_end=8.0, dt0=1e-3, dt_min=2.5e-4)
    for variant in ("observer_based", "oracle"):
        (cell,) = res[variant]
        assert cell["dt"] <= 5e-4 and cell["epsilon"] == 0.2 and cell["gain_scale"] == 1.0
        now = [cell["peak_state_norm_last_5s"], cell["peak_estimation_error_last_5s"]]
        assert all(np.isfinite(now))
        if cell["resolved"]:
            assert np.allclose(now, cell["previous_dt_values"], rtol=0.05, atol=1e-4)
    assert (tmp_path / "theorem6.png").stat().st_size > 1000
    with pytest.raises(ValueError, match="epsilons must be positive"):
        theorem6_study(None, epsilons=(0.0,))


def test_cli_study_rejects_step_options(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", "convergence", "--out", "unused", "--dt", "1e-3"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--dt does not apply" in err


def test_cli_reproduce_refuses_to_overwrite_a_previous_run(tmp_path, capsys):
    out = tmp_path / "paper"
    assert main(["reproduce", "ne2", "--out", str(out), "--t-end", "0.2", "--no-progress"]) == 0
    first = (out / "ne2" / "metrics.json").read_text()
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", "ne2", "--out", str(out), "--t-end", "0.3", "--no-progress"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--overwrite" in err and "metrics.json" in err
    assert (out / "ne2" / "metrics.json").read_text() == first  # untouched
    assert main(["reproduce", "ne2", "--out", str(out), "--t-end", "0.3", "--no-progress", "--overwrite"]) == 0
    assert json.loads((out / "ne2" / "metrics.json").read_text())["t_end"] == pytest.approx(0.3)
    afile = tmp_path / "a_file"
    afile.write_text("x")
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", "ne2", "--out", str(afile)])
    assert exc.value.code == 2 and "is a file" in capsys.readouterr().err


def test_study_cells_in_worker_processes_match_the_serial_run():
    kw = dict(dts=(1e-3, 5e-4), scenarios=("ne1",), t_end=6.0)
    assert convergence_study(None, workers=2, **kw) == convergence_study(None, workers=1, **kw)


ROLLOUT_FAULTS = {"oo_period": 0.003, "oo_loss": 0.2, "oo_delay": 2, "co_loss": 0.3, "co_delay": 1,
                  "measurement_noise": 0.02}


@pytest.mark.parametrize("name", ["NE2", "NE3"])
def test_faulted_compiled_loop_matches_reference(name):
    """With communication faults (periods = Euler steps here) the compiled loop follows the numpy reference
    (noisy estimates, C-O links, faulted steps) to the same tolerance as without faults."""
    sc = {"NE2": ne2, "NE3": ne3}[name]()
    a = rollout(sc, t_end=0.3, faults=ROLLOUT_FAULTS, fault_seed=7)[0]
    b = rollout_reference(sc, t_end=0.3, faults=ROLLOUT_FAULTS, fault_seed=7)
    _assert_same(a, b)
    ideal = rollout(sc, t_end=0.3)[0]
    assert np.abs(a.est_err - ideal.est_err).max() > 1e-3  # the faults act


def test_faulted_rollout_seeds_and_zero_rates():
    """Copies draw their faults from their own seeds (copy c of a batch = the copy alone with its seed); every
    rate zero reproduces the ideal run to rounding; a bad faults value names its key."""
    sc = ne2()
    batch = rollout(sc, t_end=0.2, batch=3, faults={"co_loss": 0.5, "measurement_noise": 0.05}, fault_seed=[4, 5, 6])
    one = rollout(sc, t_end=0.2, faults={"co_loss": 0.5, "measurement_noise": 0.05}, fault_seed=[5])[0]
    np.testing.assert_array_equal(batch[1].x, one.x)
    assert not np.array_equal(batch[0].x, batch[1].x)
    _assert_same(rollout(sc, t_end=0.2, faults={})[0], rollout(sc, t_end=0.2)[0], rtol=1e-10)
    with pytest.raises(ValueError, match="faults: co_loss must be"):
        rollout(sc, t_end=0.1, faults={"co_loss": 2.0})
