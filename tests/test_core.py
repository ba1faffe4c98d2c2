"""The batched environment core (dobs_envs.envs.env_core.EnvCore): API, batch independence,
the compiled step against its numpy reference, reason codes, padded observations."""
import numpy as np
import pytest

from baselines.policies import SeparationPolicy
from dobs_envs import tracking_v0
from dobs_envs.envs import DisturbanceRejectionEnv, RandomNetworkEnv, TrackingEnv
from dobs_envs.envs.numpy_advance import advance_reference
from dobs_envs.envs.step_kernel import advance_batch
from dobs_envs.scenarios.paper import ne2, ne3
from dobs_envs.sim.period_kernel import MIN_TILE, TILE


def _episode_arrays(core, seeds, steps, rng_seed=0):
    """Reset with ``seeds`` and run ``steps`` random (out-of-range included) inputs; stack everything."""
    core.reset(None, seeds)
    rng = np.random.default_rng(rng_seed)
    out = [core.observations.copy()]
    for _ in range(steps):
        u = rng.uniform(-1.5, 1.5, size=(core.num_envs, core.n_inputs)) * core.action_bound
        res = core.advance(u)
        out += [core.observations.copy(), res.reward.copy(), res.terminated.copy(), core.estimation_errors.copy()]
    return out


def test_copies_do_not_depend_on_the_batch():
    """Copy c of a batch (a SIMD tile of TILE copies, a run-time-width tile of the remainder, or the
    per-copy path) equals a batch-1 core (per-copy path) with the same seed and inputs, bit for bit;
    so do the copies of batches whose remainder is the narrowest tile (MIN_TILE) or just too narrow
    for one (a tile + copy by copy); two threads give the serial results."""
    B = TILE + 77  # a tile, then a 77-copy run-time-width tile
    seeds = list(range(100, 100 + B))
    big = TrackingEnv.make_core(B, max_cycles=1000)
    big.reset(None, seeds)
    others = {n: TrackingEnv.make_core(n, max_cycles=1000) for n in (MIN_TILE - 1, MIN_TILE, TILE + MIN_TILE - 1)}
    for n, core in others.items():
        core.reset(None, seeds[:n])
    rng = np.random.default_rng(0)
    U = [rng.uniform(-20, 20, size=(B, 5)) for _ in range(6)]
    small = {c: TrackingEnv.make_core(1, max_cycles=1000) for c in (0, 5, TILE - 1, TILE, TILE + 40, B - 1)}
    for c, core in small.items():
        core.reset(None, [seeds[c]])
    par = TrackingEnv.make_core(B, threads=2, max_cycles=1000)
    assert par.ranges == ((0, TILE), (TILE, B))
    par.reset(None, seeds)
    for u in U:
        big.advance(u)
        par.advance(u)
        for n, core in others.items():
            core.advance(u[:n])
            np.testing.assert_array_equal(core.observations, big.observations[:n])
            np.testing.assert_array_equal(core.sim_state.z, big.sim_state.z[:n])
        for c, core in small.items():
            core.advance(u[c:c + 1])
            np.testing.assert_array_equal(core.observations[0], big.observations[c])
            np.testing.assert_array_equal(core.sim_state.z[0], big.sim_state.z[c])
    np.testing.assert_array_equal(par.observations, big.observations)
    np.testing.assert_array_equal(par.sim_state.gamma, big.sim_state.gamma)


def _smooth(sc):
    """The scenario without the discontinuous consensus term (gamma_is = 0, as the NE2 ablation)."""
    return sc.replace(gamma_s0=0.0, phi_s=0.0)


@pytest.mark.parametrize("cls,kw", [(TrackingEnv, {"scenario": _smooth(ne2())}),
                                    (DisturbanceRejectionEnv, {"scenario": _smooth(ne3()), "disturbance": "random"}),
                                    (DisturbanceRejectionEnv, {"scenario": _smooth(ne3())})])
def test_compiled_step_matches_numpy_reference_over_a_run(cls, kw):
    """advance_batch vs advance_reference from the same state at every step of a 300-step run of 4
    copies with random (partly clipped) inputs, terminations, truncations and resets: codes exactly,
    rewards, states and features to 1e-9. The systems drop the discontinuous consensus term
    h(eps) = eps / ||eps||, which turns round-off differences of the two simulations (summation
    order) into O(dt gamma_is) differences once eps is at round-off level (chattering)."""
    core = cls.make_core(4, max_cycles=40, state_bound=60.0, **kw)
    gain = np.array([[0.05], [0.05], [1.2], [1.2]])  # copies 0-1 gentle (truncated), 2-3 aggressive
    core.reset(None, [1, 2, 3, 4])
    rng = np.random.default_rng(5)
    names = ("t", "x", "z", "gamma", "gamma_s", "v", "x_r", "W", "obs", "reward", "cost", "err", "xnorm", "finite",
             "term", "trunc", "reason", "cycles")
    steps, seen = 0, set()
    for k in range(300):
        u = rng.uniform(-1.0, 1.0, size=(4, core.n_inputs)) * gain * core.action_bound
        a, b = core.kernel_arguments(), core.kernel_arguments()
        assert advance_batch(u=u, **a) == -1
        assert advance_reference(u=u, **b) == -1
        for x, y, name in zip(a["state"] + (a["W"], a["obs"]) + a["outs"], b["state"] + (b["W"], b["obs"]) + b["outs"],
                              names):
            if x.dtype.kind in "bi":
                np.testing.assert_array_equal(x, y, err_msg=f"{name}, step {k}")
            else:
                scale = max(1.0, float(np.max(np.abs(np.where(np.isfinite(y), y, 0.0)), initial=0.0)))
                np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9 * scale, err_msg=f"{name}, step {k}")
        res = core.advance(u)
        ended = res.terminated | res.truncated
        seen.update(res.reason.tolist())
        steps += 1
        if ended.any():
            core.reset(np.flatnonzero(ended))
    assert steps == 300 and {0, 1, 3} <= seen  # ongoing, state bound exceeded, truncated


def test_reset_subsets_seeds_and_options():
    core = DisturbanceRejectionEnv.make_core(3)
    core.reset(None, [7, 8, 9])
    x_before = core.sim_state.x.copy()
    obs1 = core.observations.copy()
    core.advance(np.zeros((3, 5)))
    core.reset([1], [8])  # copy 1 back to its seeded start; copies 0 and 2 untouched
    s = core.sim_state
    np.testing.assert_array_equal(s.x[1], x_before[1])
    np.testing.assert_array_equal(core.observations[1], obs1[1])
    assert s.t.tolist() == [core.control_period, 0.0, core.control_period]
    assert core.cycles.tolist() == [1, 0, 1]
    x0 = np.arange(9.0)
    core.reset(np.array([False, True, True]), options={"x0": x0, "v0": [[-2.0, 2.0], [1.0, 0.5]]})
    s = core.sim_state
    np.testing.assert_array_equal(s.x[1:], [x0, x0])
    np.testing.assert_array_equal(s.v[1:], [[-2.0, 2.0], [1.0, 0.5]])
    with pytest.raises(ValueError, match=r"options\['x0'\]"):
        core.reset(None, options={"x0": np.zeros((2, 9))})
    with pytest.raises(ValueError, match="seeds"):
        core.reset([0, 1], [1])
    with pytest.raises(ValueError, match="indices"):
        core.reset([3])


def test_advance_validates_inputs_and_reports_reasons():
    core = TrackingEnv.make_core(2, state_bound=15.0, max_cycles=3)
    core.reset(None, [0, 1])
    bad = np.zeros((2, 5))
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"copy 1 .*controller_3"):
        core.advance(bad)
    assert core.cycles.tolist() == [0, 0]  # nothing simulated
    with pytest.raises(ValueError, match="shape"):
        core.advance(np.zeros((1, 5)))
    u = np.zeros((2, 5))
    u[0] = 1e6  # clipped to the bound, drives copy 0 out of the state bound
    reasons = []
    for _ in range(3):
        res = core.advance(u)
        reasons.append(res.reason.tolist())
        np.testing.assert_array_equal(core.applied_inputs[0], core.action_bound)
        if res.terminated[0]:
            break
    assert reasons[-1][0] == 1 and res.terminated[0]
    core.reset([0])
    while not res.truncated[1]:
        res = core.advance(np.zeros((2, 5)))
    assert res.reason[1] == 3 and core.cycles[1] == 3
    with pytest.raises(ValueError, match="writeable|read-only"):
        core.observations[0, 0, 0] = 1.0


def test_padded_observations_and_true_widths():
    core = RandomNetworkEnv.make_core(2, observation=("y", "xhat"))
    w = core.obs_widths
    assert len(set(w.tolist())) > 1  # the generator's nodes measure different numbers of outputs
    assert core.observations.shape == (2, core.n_agents, w.max())
    core.reset(None, [0, 1])
    for k in range(core.n_agents):
        assert np.all(core.observations[:, k, w[k]:] == 0)
        lay = core.layout.agent_layout[k]
        assert lay["xhat"].stop == w[k]
    # the concatenation used by the centralised views
    flat = core.observations.reshape(2, -1)[:, core.layout.concat_index]
    assert flat.shape == (2, int(w.sum()))


def test_states_task_errors_and_policy_run_through_the_public_api():
    env = tracking_v0.parallel_env()
    pol = SeparationPolicy(env)
    obs, _ = env.reset(seed=0)
    while env.agents:
        obs, *_ = env.step(pol(obs))
    core = env.core
    assert core.task_errors()[0] == core.tracking_errors[0] == env.tracking_error < 0.1
    st = core.states()
    assert st.shape == (1, core.state_dim) and np.array_equal(st[0], env.state())
    np.testing.assert_allclose(st[0, core.state_layout["x"]], env.sim_state.x[0], rtol=1e-6)


def test_pickled_core_and_env_keep_running():
    """copy.deepcopy / cloudpickle (SuperSuit copies environments so) rebuild the buffer views: a
    copy continues exactly as the original (pickle does not keep views sharing memory)."""
    import copy
    import pickle

    from dobs_envs import tracking_v0

    env = tracking_v0.parallel_env(max_cycles=4)
    env.reset(seed=3)
    env.step({a: np.ones(1) for a in env.agents})
    copies = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    acts = {a: np.full(1, 2.0) for a in env.possible_agents}
    outs = [[], [], []]
    for e, out in zip([env] + copies, outs):
        while e.agents:
            out.append(e.step(acts))
        out.append(e.reset(seed=5))
        out.append(e.step(acts))
    for out in outs[1:]:
        assert len(out) == len(outs[0]) == 5  # steps 2..4 (truncated at 4), reset, step
        for a, b in zip(out, outs[0]):
            assert repr(a) == repr(b)
    assert copies[0].core._rew.base is copies[0].core._outs[0]
    # the same argument types as the original's: the compiled step is not specialised again
    assert [a.flags.writeable for a in copies[1].core._ka] == [a.flags.writeable for a in env.core._ka]
