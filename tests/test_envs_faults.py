"""Communication faults in the environments (issue 23, phase 2): the ``faults=`` option of every
environment and the core, the compiled faulted step against its numpy reference, what the agents
observe (noisy outputs, the C-O hold, the received/stale mask), determinism per seed, named errors,
and ``tracking_lossy_v0``."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import dobs_envs  # noqa: F401
from dobs_envs import registry, tracking_lossy_v0, tracking_v0
from dobs_envs.envs import TrackingEnv
from dobs_envs.envs.numpy_advance import advance_reference
from dobs_envs.envs.step_kernel import advance_batch
from dobs_envs.envs.tracking import TRACKING_LOSSY_FAULTS
from dobs_envs.scenarios.paper import ne2
from dobs_envs.sim.fault_state import FaultState
from dobs_envs.sim.faults import Faults

RING = ne2().graph.adjacency
CUT = RING.copy()
CUT[0, 1] = CUT[1, 0] = CUT[3, 4] = CUT[4, 3] = 0.0

SETTINGS = {
    "lossy": TRACKING_LOSSY_FAULTS,
    "delays": dict(oo_period=0.01, oo_loss=0.2, oo_delay=1, co_loss=0.3, co_delay=2, measurement_noise=0.02),
    "burst_switching": dict(oo_burst={"p_good_bad": 0.2, "p_bad_good": 0.3},
                            switching={"graphs": [RING, CUT, np.zeros((6, 6))], "rate": 4.0}),
}


@pytest.mark.parametrize("setting", list(SETTINGS))
def test_compiled_step_matches_the_numpy_reference(setting):
    """advance_batch vs advance_reference with faults, from the same core state at every step of a 12-step
    run of 3 copies: masks, discrete fault state and float32 observations exactly; features, rewards and the
    continuous fault state to 1e-12 relative (the simulation's rounding, ``tests/test_fault_kernel.py``)."""
    core = TrackingEnv.make_core(3, faults=SETTINGS[setting], observation="full", obs_dtype="float64")
    core.reset(None, [1, 2, 3])
    rng = np.random.default_rng(0)
    for k in range(12):
        u = 5 * rng.normal(size=(3, core.n_inputs))
        a, b = core.kernel_arguments(), core.kernel_arguments()
        assert advance_batch(u=u, **a) == -1
        assert advance_reference(u=u, **b) == -1
        _, fs_a, rx_a, _ = a["fault"]
        _, fs_b, rx_b, _ = b["fault"]
        for x, y in zip(rx_a, rx_b):
            np.testing.assert_array_equal(x, y)
        for name, x, y in zip(FaultState._fields, fs_a, fs_b):
            if x.dtype.kind in "biu" or name == "noise":
                np.testing.assert_array_equal(x, y, err_msg=name)
            else:
                np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * max(1, np.abs(y).max()), err_msg=name)
        for name in ("W", "obs"):
            np.testing.assert_allclose(a[name], b[name], rtol=0, atol=1e-12 * np.abs(b[name]).max(), err_msg=name)
        for x, y in zip(a["outs"], b["outs"]):
            np.testing.assert_allclose(x, y, rtol=1e-12)
        core.advance(u)


def _run(env, seed, steps, action=None):
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, info)]
    for _ in range(steps):
        acts = {a: np.zeros(1, np.float32) if action is None else action for a in env.agents}
        obs, rew, term, trunc, info = env.step(acts)
        out.append((obs, rew["controller_0"], info))
    return out


def test_zero_rates_reproduce_no_faults():
    """``faults={}`` and ``Faults()`` (the ideal exchange) reproduce ``faults=None``: the same observations
    (the common components; the faulted ones add ``received``, all ones here), rewards and infos to rounding.
    Not bitwise: the faulted kernel sums the consensus term link by link, ``sum_e a_e (xhat_i - r_e)``, the
    unfaulted one as the Laplacian row ``deg_i xhat_i - sum_j a_ij xhat_j`` (a few ulps per evaluation;
    measured: 1.6e-16 relative in the observations, rewards equal, over 30 steps; bounded by 1e-9 here)."""
    ref = _run(tracking_v0.parallel_env(obs_dtype="float64"), 4, 30)
    for faults in ({}, Faults()):
        env = tracking_v0.parallel_env(obs_dtype="float64", faults=faults)
        lay = env.observation_layout("controller_0")
        assert lay["received"] == slice(31, 34)
        got = _run(env, 4, 30)
        for (o1, r1, i1), (o2, r2, i2) in zip(ref, got):
            assert r2 == pytest.approx(r1, rel=1e-9, abs=1e-12)
            for a in o1:
                np.testing.assert_allclose(o2[a][:31], o1[a], rtol=1e-9, atol=1e-9)
                np.testing.assert_array_equal(o2[a][31:], 1.0)
                assert i2[a]["co_received"] is True and i2[a]["oo_received_fraction"] == 1.0
                assert i2[a]["estimation_error"] == pytest.approx(i1[a]["estimation_error"], rel=1e-9, abs=1e-12)


def test_faults_none_draws_nothing_more():
    """``faults=None`` leaves the generator where it was (the fault seed is drawn only with faults on), and
    the initial observations (every rate zero) do not depend on the option."""
    e1, e2 = tracking_v0.parallel_env(), tracking_v0.parallel_env(faults={})
    o1, _ = e1.reset(seed=9)
    o2, _ = e2.reset(seed=9)
    for a in o1:
        np.testing.assert_array_equal(o2[a][:31], o1[a])
    assert e1.np_random.bit_generator.state != e2.np_random.bit_generator.state


def test_determinism_per_seed():
    """The same seed gives the same episode (observations, rewards, infos) bit for bit; another seed other
    fault draws."""
    runs = [_run(tracking_lossy_v0.parallel_env(), s, 15) for s in (3, 3, 4)]
    for (o1, r1, i1), (o2, r2, i2) in zip(runs[0], runs[1]):
        assert r1 == r2 and i1 == i2
        for a in o1:
            np.testing.assert_array_equal(o1[a], o2[a])
    rec = lambda run: [[i[a]["co_received"] for a in i] for _, _, i in run]  # noqa: E731
    assert rec(runs[0]) != rec(runs[2]) or not np.array_equal(runs[0][-1][0]["controller_0"],
                                                              runs[2][-1][0]["controller_0"])


def test_co_loss_holds_the_first_estimate():
    """``co_loss=1``: every C-O packet after reset is lost, so each agent's ``xhat`` stays the ``t = 0``
    estimate its node sent while the node's own estimate (the privileged ``estimates``) moves on;
    ``co_received`` is False from the first step on and the ``received`` entry 0."""
    env = tracking_v0.parallel_env(faults={"co_loss": 1.0}, observation="full", obs_dtype="float64")
    obs0, info0 = env.reset(seed=2)
    assert all(info0[a]["co_received"] for a in info0)
    lay = env.observation_layout("controller_3")
    x0 = obs0["controller_3"][lay["xhat"]].copy()
    np.testing.assert_array_equal(x0, obs0["controller_3"][lay["estimates"]][27:36])  # node 3 at reset
    for k in range(5):
        obs, _, _, _, info = env.step({a: np.zeros(1, np.float32) for a in env.agents})
        o = obs["controller_3"]
        np.testing.assert_array_equal(o[lay["xhat"]], x0)
        assert np.abs(o[lay["estimates"]][27:36] - x0).max() > 1e-3
        assert not info["controller_3"]["co_received"] and o[lay["received"]][0] == 0.0
    # with co_delay the controllers read the estimate sent co_delay steps before (the t = 0 one until then)
    env = tracking_v0.parallel_env(faults={"co_delay": 2}, observation="full", obs_dtype="float64")
    obs, _ = env.reset(seed=2)
    sent = [obs["controller_1"][lay["estimates"]][9:18].copy()]
    for k in range(4):
        obs, *_ = env.step({a: np.zeros(1, np.float32) for a in env.agents})
        sent.append(obs["controller_1"][lay["estimates"]][9:18].copy())
        np.testing.assert_array_equal(obs["controller_1"][lay["xhat"]], sent[max(0, k + 1 - 2)])


def test_oo_loss_and_noise_in_the_observations():
    """``oo_loss``: the fraction of neighbour values received matches ``1 - oo_loss`` (the period's draw per
    link); a neighbour value not received is the one held before. ``measurement_noise``: the observed ``y_i``
    is ``C_i x`` plus noise of the configured standard deviation (the held draw the observer uses)."""
    p, sigma = 0.3, 0.05
    core = TrackingEnv.make_core(64, faults={"oo_loss": p, "measurement_noise": sigma}, observation="full",
                                 obs_dtype="float64")
    core.reset(None, list(range(64)))
    lay = core.layout.agent_layout[0]
    fr, noise = [], []
    C = ne2().C[0]  # node 0 measures x_1
    senders = core._fa.sender[core._fa.receiver == 0]  # node 0's neighbours (links 0 and 1)
    for k in range(20):
        core.advance(np.zeros((64, core.n_inputs)))
        o = core.observations
        rec = o[:, 0, lay["received"]][:, 1:] == 1.0
        nb = o[:, 0, lay["neighbors"]].reshape(64, 2, 9)
        est = o[:, 0, lay["estimates"]].reshape(64, 6, 9)[:, senders]
        held = core.fault_state.received[:, :2]
        np.testing.assert_array_equal(nb[rec], est[rec])  # received now: the sender's current estimate
        np.testing.assert_array_equal(nb[~rec], held[~rec])  # else the copy node 0 holds
        assert np.all(np.any(nb[~rec] != est[~rec], axis=-1))
        fr.append(rec.mean())
        noise.append(o[:, 0, lay["y"]][:, 0] - o[:, 0, lay["x"]] @ C[0])
    n = 64 * 2 * 20
    assert abs(np.mean(fr) - (1 - p)) < 5 * np.sqrt(p * (1 - p) / n)
    z = np.concatenate(noise) / sigma
    assert abs(z.std() - 1) < 5 * np.sqrt(1 / (2 * z.size)) and abs(z.mean()) < 5 / np.sqrt(z.size)
    frac = core.oo_received_fraction
    assert frac.shape == (64, 5) and np.all((frac >= 0) & (frac <= 1))


def test_batch_independence_and_threads():
    """A copy's faulted episode does not depend on the batch, its position or the threads advancing it."""
    f = SETTINGS["delays"]
    big = TrackingEnv.make_core(140, faults=f, threads=2)
    assert len(big.ranges) == 2
    serial = TrackingEnv.make_core(140, faults=f, threads=1)
    one = TrackingEnv.make_core(1, faults=f)
    seeds = list(range(100, 240))
    big.reset(None, seeds)
    serial.reset(None, seeds)
    one.reset(None, [seeds[130]])
    u = np.random.default_rng(1).normal(size=(140, big.n_inputs))
    for _ in range(4):
        big.advance(u)
        serial.advance(u)
        one.advance(u[130:131])
    np.testing.assert_array_equal(big.observations, serial.observations)
    np.testing.assert_array_equal(big.observations[130], one.observations[0])
    for a, b in zip(big.fault_state, one.fault_state):
        np.testing.assert_array_equal(a[130], b[0])


@pytest.mark.parametrize("faults, exc, match", [
    ({"oo_los": 0.1}, TypeError, r"faults: unexpected key 'oo_los'; valid keys are"),
    ({"oo_loss": 1.5}, ValueError, "faults: oo_loss must be"),
    ({"co_delay": -1}, ValueError, "faults: co_delay must be an integer >= 0"),
    (0.1, ValueError, "faults must be None, a dict"),
    ({"oo_period": 0.0015}, ValueError, "faults: oo_period must be a positive integer multiple of the Euler step"),
    ({"switching": {"graphs": [np.zeros((3, 3))]}}, ValueError, "faults: switching graphs have 3 nodes"),
])
def test_bad_faults_raise_named_errors(faults, exc, match):
    with pytest.raises(exc, match=match):
        tracking_v0.parallel_env(faults=faults)
    with pytest.raises(exc, match=match):
        gym.make("dobs_envs/Tracking-v0", faults=faults)
    with pytest.raises(exc, match=match):
        gym.make_vec("dobs_envs/TrackingLossy-v0", num_envs=2, faults=faults)


def test_the_received_component_needs_faults():
    with pytest.raises(ValueError, match="observation component 'received' needs communication faults"):
        tracking_v0.parallel_env(observation=("xhat", "received"))
    env = tracking_v0.parallel_env(observation=("xhat", "received"), faults={})
    assert env.observation_space("controller_0").shape == (12,)


def test_tracking_lossy_defaults():
    """The registered lossy environment: its default faults, ``faults=None`` gives tracking_v0 exactly."""
    e = registry.get("tracking_lossy")
    assert e.gym_id == "dobs_envs/TrackingLossy-v0" and e.max_episode_steps == 400
    env = tracking_lossy_v0.parallel_env()
    assert env.options.faults == Faults(**TRACKING_LOSSY_FAULTS)
    assert env.observation_space("controller_0").shape == (34,)
    a = _run(tracking_lossy_v0.parallel_env(faults=None), 5, 10)
    b = _run(tracking_v0.parallel_env(), 5, 10)
    for (o1, r1, i1), (o2, r2, i2) in zip(a, b):
        assert r1 == r2 and i1 == i2
        for k in o1:
            np.testing.assert_array_equal(o1[k], o2[k])
    genv = gym.make("dobs_envs/TrackingLossy-v0")
    obs, info = genv.reset(seed=0)
    assert obs.shape == (5 * 34,) and info["co_received"].shape == (5,)
    venv = gym.make_vec("dobs_envs/TrackingLossy-v0", num_envs=3, vectorization_mode="vector_entry_point")
    obs, info = venv.reset(seed=0)
    assert obs.shape == (3, 170) and info["oo_received_fraction"].shape == (3, 5)
    venv.close()


_SIGNATURES = r'''
import json
import numpy as np
from numba import types
from dobs_envs.envs import TrackingEnv
from dobs_envs.envs.step_kernel import advance_range
from dobs_envs.sim import period_kernel as pk
B = pk.TILE + pk.MIN_TILE + 1  # whole tiles, a remainder tile and one copy alone: every path of advance_rows
core = TrackingEnv.make_core(B, faults={"oo_loss": 0.2, "co_loss": 0.1})
core.reset(None, list(range(B)))
core.advance(np.zeros((B, core.n_inputs)))
# then the simulation on the same (faulted) network: a rollout of NE2 (tracking's network) with its controller
from dobs_envs.rollout import rollout
from dobs_envs.scenarios.paper import ne2
rollout(ne2(), batch=B, t_end=0.05, faults={"oo_loss": 0.2, "co_loss": 0.1})
# the position of the fault argument in each compiled function
where = {advance_range: -1, pk.advance_rows: -1, pk._advance_tiles: 4, pk.period_tile: 4, pk._scatter: 8,
         pk.period_copy: 4}
ideal = lambda t: isinstance(t, (types.NoneType, types.Omitted)) or (isinstance(t, types.BaseTuple) and t.count == 0)
print(json.dumps({d.py_func.__name__: [ideal(s[i]) for s in d.signatures] for d, i in where.items()}))
'''


def test_a_faulted_network_compiles_no_ideal_engine(tmp_path):
    """The engine's functions branch on ``len(fault)`` (``NO_FAULT = ()`` on the ideal network), which numba
    prunes per specialisation both ways: a process that steps and simulates only faulted copies compiles no
    ideal-network specialisation of any engine function (``if fault is None:`` was not pruned for a fault
    tuple, so a faulted environment compiled the whole ideal engine too: twice the cold compile). The
    environment's step and the simulation's rollout share every specialisation of the period kernel (a
    rollout's inputs in another memory layout compiled the whole period kernel a second time). (The other
    way, an ideal-only process compiles no fault code: also measured, 80 s of cold compile, left out of the
    suite.)
    Run in a fresh process (this one has compiled both) with an empty numba cache
    (a kernel loaded from the cache brings its callees inside it, not as specialisations of theirs) and
    without LLVM optimisation (``NUMBA_OPT=0``: pruning happens before typing, whatever the level)."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), NUMBA_OPT="0")
    out = subprocess.run([sys.executable, "-c", _SIGNATURES], capture_output=True, text=True, timeout=1200, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    ideal = json.loads(out.stdout.strip().splitlines()[-1])
    for name, flags in ideal.items():
        assert flags, f"{name} was not compiled: the test no longer reaches it"
        assert not any(flags), f"{name} has a specialisation for the ideal network: {flags}"
    # the step and the rollout share the period kernel: one specialisation each, two of period_tile (the tile
    # width TILE as a constant, the remainder's at run time)
    assert {name: len(flags) for name, flags in ideal.items()} == {
        "advance_range": 1, "advance_rows": 1, "_advance_tiles": 1, "period_tile": 2, "_scatter": 1, "period_copy": 1}
