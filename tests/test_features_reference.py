"""The compiled (batched) observation/reward kernel against its numpy reference over a closed-loop run."""
import numpy as np
import pytest

from baselines.policies import SeparationPolicy
from dobs_envs import tracking_v0
from dobs_envs.envs import DObsVectorEnv, TrackingEnv
from dobs_envs.envs.features import pack_static, write_features
from dobs_envs.envs.numpy_features import write_features_reference

STEPS = 300  # 15 s of NE2 at the default control period 0.05 s


def _static(core):
    """The kernel's static arrays, rebuilt from the core's public attributes."""
    p, L, sc = core.params, core.layout, core.scenario
    ref = np.array([sc.reference.amplitude, sc.reference.frequency, sc.reference.phase])
    return pack_static(p.C, p.G_bar, ref, core.Q, core.R, L.offsets([c.shape[0] for c in sc.C]), L.padded_index,
                       L.size)


def _both(core, SF, SI, rows):
    """Compiled and reference kernels on the core's current state; fresh buffers each."""
    s = core.sim_state
    B, L = core.num_envs, core.layout
    W = np.zeros((B, L.size + core.n_nodes + core.n_inputs))
    W[:, L.one] = 1.0
    W[:, L.size + core.n_nodes:] = core.applied_inputs
    res = []
    for fn in (write_features, write_features_reference):
        Wk, obs = W.copy(), np.zeros((B, core.n_agents, core.obs_dim))
        scal = np.zeros((3, B)), np.zeros(B, bool)
        fn(rows, (s.t, s.x, s.z, s.gamma, s.gamma_s, s.v, s.x_r), Wk, obs, SF, SI, True,
           (scal[0][0], scal[0][1], scal[0][2], scal[1]))
        res.append((Wk, obs, scal[0], scal[1]))
    return res


@pytest.mark.parametrize("observation,padded", [("full", False), ("local", False), ("local", True)])
def test_features_match_reference_over_a_converging_run(observation, padded):
    env = tracking_v0.parallel_env(observation=observation, obs_dtype="float64", max_cycles=STEPS,
                                   padded_observations=padded)
    core = env.core
    SF, SI = _static(core)
    rows = np.array([0])
    policy = SeparationPolicy(env)
    obs, _ = env.reset(seed=7)
    agents = env.possible_agents
    est0 = None
    for k in range(STEPS):
        obs, rew, term, trunc, info = env.step(policy(obs))
        assert not term[agents[0]]
        (Wc, oc, sc, fc), (Wr, orf, sr, fr) = _both(core, SF, SI, rows)
        # features f, estimation errors and u (the whole work row); observations; cost, ||e||, ||x||
        np.testing.assert_allclose(Wr, Wc, rtol=1e-12, atol=1e-12, err_msg=f"features, step {k}")
        np.testing.assert_allclose(orf, oc, rtol=1e-12, atol=1e-12, err_msg=f"observations, step {k}")
        np.testing.assert_allclose(sr, sc, rtol=1e-12, atol=0.0, err_msg=f"cost/||e||/||x||, step {k}")
        assert fc.all() and fr.all()
        # the environment's outputs are the compiled kernel's
        np.testing.assert_array_equal(core.features, Wc[:, :core.layout.size])
        np.testing.assert_array_equal(np.concatenate([obs[a] for a in agents]), oc[0].ravel())
        assert info[agents[0]]["tracking_error"] == sc[1, 0]
        est = np.array([info[a]["estimation_error"] for a in agents])
        if est0 is None:
            est0 = est
    assert trunc[agents[0]]
    # the distributed observer converges over the run (the comparison covers transient and steady state)
    assert est.max() < 1e-2 * est0.max()


def test_batched_features_match_reference_on_a_subset_of_copies():
    venv = DObsVectorEnv(TrackingEnv, 6, observation="full", obs_dtype="float64")
    core = venv.core
    SF, SI = _static(core)
    venv.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(20):
        venv.step(rng.uniform(-5, 5, size=(6, 5)))
    rows = np.array([1, 4, 5])
    (Wc, oc, sc, fc), (Wr, orf, sr, fr) = _both(core, SF, SI, rows)
    np.testing.assert_allclose(Wr, Wc, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(orf, oc, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sr, sc, rtol=1e-12, atol=0.0)
    np.testing.assert_array_equal(fc, fr)
    # copies outside ``rows`` are left alone
    assert np.all(oc[[0, 2, 3]] == 0) and np.all(sc[:, [0, 2, 3]] == 0)
