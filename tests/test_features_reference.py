"""The compiled observation/reward kernel against its numpy reference over a closed-loop run."""
import numpy as np
import pytest

from baselines.policies import SeparationPolicy
from dobs_envs import tracking_v0
from dobs_envs.envs.numpy_features import write_features_reference
from dobs_envs.envs.observation import write_features_packed

STEPS = 300  # 15 s of NE2 at the default control period 0.05 s


def _both(env, u):
    """Compiled and reference kernels on the env's current state; fresh buffers each."""
    s, L = env.sim_state, env.layout
    W = np.zeros(L.size + env.n_nodes + env.n_inputs)
    W[L.one] = 1.0
    W[L.size + env.n_nodes:] = u
    res = []
    for fn in (write_features_packed, write_features_reference):
        Wk, out = W.copy(), np.empty(L.all_index.size)
        scalars = fn(s.x, s.z, s.x_r, s.gamma, s.gamma_s, s.v, float(s.t[0]), Wk, env._SF, env._SI,
                     env.has_reference, out)
        res.append((Wk, out, np.array(scalars, dtype=float)))
    return res


@pytest.mark.parametrize("observation", ["full", "local"])
def test_features_match_reference_over_a_converging_run(observation):
    env = tracking_v0.parallel_env(observation=observation, obs_dtype="float64", max_cycles=STEPS)
    policy = SeparationPolicy(env)
    obs, _ = env.reset(seed=7)
    agents = env.possible_agents
    est0 = None
    for k in range(STEPS):
        acts = policy(obs)
        u = np.clip(np.concatenate([acts[a] for a in agents]), -env.action_bound, env.action_bound)
        obs, rew, term, trunc, info = env.step(acts)
        assert not term[agents[0]]
        (Wc, oc, sc), (Wr, orf, sr) = _both(env, u)
        # features f, estimation errors and u (the whole work buffer); observations; cost, ||e||, ||x||
        np.testing.assert_allclose(Wr, Wc, rtol=1e-12, atol=1e-12, err_msg=f"features, step {k}")
        np.testing.assert_allclose(orf, oc, rtol=1e-12, atol=1e-12, err_msg=f"observations, step {k}")
        np.testing.assert_allclose(sr, sc, rtol=1e-12, atol=0.0, err_msg=f"cost/||e||/||x||, step {k}")
        # the environment's outputs are the compiled kernel's
        np.testing.assert_array_equal(np.concatenate([obs[a] for a in agents]), oc)
        assert info[agents[0]]["tracking_error"] == sc[1]
        est = np.array([info[a]["estimation_error"] for a in agents])
        if est0 is None:
            est0 = est
    assert trunc[agents[0]]
    # the distributed observer converges over the run (the comparison covers transient and steady state)
    assert est.max() < 1e-2 * est0.max()
