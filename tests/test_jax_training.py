"""The jitted PPO trainer (agents/training/jax): a tiny run on tracking vmapped over seeds and a learning
rate, VecNormalize's normalisation against SB3's own code, and the numpy export against the JAX policy
and in the compiled Gymnasium environment."""
import json

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("optax")
import jax.numpy as jnp  # noqa: E402

from agents.training.jax import normalize as nz  # noqa: E402
from agents.training.jax.export import jax_act, save_policy, select_run  # noqa: E402
from agents.training.jax.numpy_policy import NumpyPolicy  # noqa: E402
from agents.training.jax.ppo import HPARAMS, make_env, make_train, ppo_config  # noqa: E402

# the shipped tracking recipe's keys (agents/hyperparams/ppo.yaml) at a tiny size: 2 updates of 4 x 32 steps
TINY = {"policy": "MlpPolicy", "n_envs": 4, "n_steps": 32, "batch_size": 64, "n_epochs": 2, "gamma": 0.99,
        "gae_lambda": 0.95, "learning_rate": "lin_3.0e-4", "clip_range": 0.2, "ent_coef": 0.0, "max_grad_norm": 0.5,
        "normalize": {"norm_obs": True, "norm_reward": True}, "normalize_actions": True,
        "policy_kwargs": {"net_arch": [16, 16], "activation_fn": "tanh", "log_std_init": -2.0},
        "env_kwargs": {"state_bound": 30}}
ENV_ID = "dobs_envs/Tracking-v0"


@pytest.fixture(scope="module")
def tiny():
    """One compiled function (vmapped over the key and every float hyperparameter), two calls."""
    cfg, hp = ppo_config(TINY, ENV_ID, total_timesteps=256)
    env, env_params = make_env(cfg)
    train = jax.jit(jax.vmap(make_train(cfg, env, env_params)))
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    batch = {k: jnp.full((2,), hp[k], jnp.float32) for k in HPARAMS}
    out_a = jax.device_get(train(keys[:2], batch))                       # seeds k0, k1
    lrs = dict(batch, learning_rate=jnp.asarray([hp["learning_rate"], 3e-3], jnp.float32))
    out_b = jax.device_get(train(jnp.stack([keys[0], keys[0]]), lrs))    # seed k0 twice, two learning rates
    return cfg, hp, env, env_params, out_a, out_b


def test_tiny_run_shapes_and_finite(tiny):
    cfg, hp, env, env_params, out, _ = tiny
    assert cfg.n_updates == 2 and cfg.steps_done == 256
    D, m = env.observation_space(env_params).shape[0], env.num_actions
    p = out["params"]
    assert p["pi_w0"].shape == (2, D, 16) and p["pi_w2"].shape == (2, 16, m) and p["vf_w2"].shape == (2, 16, 1)
    assert p["log_std"].shape == (2, m)
    assert out["obs_mean"].shape == out["obs_var"].shape == (2, D)
    for leaf in jax.tree.leaves(p) + [out["obs_mean"], out["obs_var"], out["ret_var"]]:
        assert np.all(np.isfinite(leaf))
    # every reset and step observation counted once: 1e-4 + n_envs (reset) + n_envs per step
    np.testing.assert_allclose(out["obs_count"], 1e-4 + 4 * (1 + 256 // 4), rtol=1e-6)
    c = out["curve"]
    np.testing.assert_array_equal(c["steps"], [[128, 256]] * 2)
    # the untrained policy leaves the training state bound (30) within a rollout: episodes end
    assert np.all(c["episodes"].sum(axis=1) > 0)
    ended = c["episodes"] > 0
    assert np.all(np.isfinite(c["episode_return"][ended])) and np.all(np.isnan(c["episode_return"][~ended]))
    assert np.all(c["episode_return"][ended] < 0)  # the rewards are costs
    assert np.all((c["episode_length"][ended] >= 1) & (c["episode_length"][ended] <= 400))


def test_seeds_differ_and_runs_are_reproducible_and_independent(tiny):
    _, _, _, _, a, b = tiny
    pa, pb = a["params"], b["params"]
    assert not np.array_equal(pa["pi_w0"][0], pa["pi_w0"][1])        # seeds k0, k1: different initialisations
    for k in pa:                                                        # seed k0 again (beside another run): bitwise
        np.testing.assert_array_equal(pa[k][0], pb[k][0])
    np.testing.assert_array_equal(a["obs_mean"][0], b["obs_mean"][0])
    # the vmapped learning rate acts: same seed and data at the first rollout, different parameters after
    assert not np.array_equal(pb["pi_w0"][0], pb["pi_w0"][1])


def test_normaliser_matches_sb3_vecnormalize():
    """norm_step against SB3's VecNormalize (its RunningMeanStd and reward methods, called in step_wait's
    order) on a known stream with episode ends and with clipping active; float32 vs SB3's float64:
    about 50 running-mean updates of values O(10) keep relative errors near 1e-6."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    B, T, gamma, clip_obs, clip_rew = 3, 50, 0.9, 2.0, 1.5
    sb3 = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")] * B), gamma=gamma, clip_obs=clip_obs,
                       clip_reward=clip_rew)
    rng = np.random.default_rng(0)
    obs = rng.normal(2.0, 5.0, size=(T, B, 3))
    rew = rng.normal(-1.0, 3.0, size=(T, B))
    done = rng.random((T, B)) < 0.1
    state = nz.norm_init((3,), B, jnp.float32)
    step = jax.jit(lambda s, o, r, d: nz.norm_step(s, o, r, d, gamma=gamma, clip_obs=clip_obs, clip_reward=clip_rew,
                                                   epsilon=1e-8))
    clipped = 0
    for t in range(T):
        sb3.obs_rms.update(obs[t])                     # VecNormalize.step_wait, training mode
        ref_obs = sb3.normalize_obs(obs[t])
        sb3._update_reward(rew[t])
        ref_rew = sb3.normalize_reward(rew[t])
        sb3.returns[done[t]] = 0
        state, o_n, r_n = step(state, jnp.asarray(obs[t], jnp.float32), jnp.asarray(rew[t], jnp.float32),
                               jnp.asarray(done[t]))
        np.testing.assert_allclose(np.asarray(o_n), ref_obs, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(np.asarray(r_n), ref_rew, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(np.asarray(state.returns), sb3.returns, rtol=1e-5, atol=1e-5)
        clipped += int(np.sum(np.abs(ref_obs) == clip_obs) + np.sum(np.abs(ref_rew) == clip_rew))
    np.testing.assert_allclose(np.asarray(state.obs_rms.mean), sb3.obs_rms.mean, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(state.obs_rms.var), sb3.obs_rms.var, rtol=1e-5)
    np.testing.assert_allclose(float(state.ret_rms.var), sb3.ret_rms.var, rtol=1e-5)
    assert clipped > 0  # the clips were exercised
    sb3.close()


def _check_export(tmp_path, run, cfg, hp, env, env_params, name, gain=1.0):
    d = save_policy(str(tmp_path / name), run, cfg, hp, env, env_params, extra={"seed": 0})
    numpy_policy = NumpyPolicy(d)
    act = jax_act(run, cfg, hp, env, env_params)
    rng = np.random.default_rng(1)
    D = numpy_policy.obs_dim
    # around the training statistics (some beyond the clip of 10 standard deviations) and raw draws
    obs = np.concatenate([run["obs_mean"] + np.sqrt(run["obs_var"]) * rng.normal(0, 4, (200, D)),
                          rng.normal(0, 1, (56, D))]).astype(np.float32)
    u_np, u_jax = numpy_policy(obs), np.asarray(act(jnp.asarray(obs)))
    scale = numpy_policy.arrays["action_scale"]
    # float32 network against float64: ~1e-6 of the action units over three layers of fan-in <= 155,
    # times the gain put on the output layer
    np.testing.assert_allclose(u_np / scale, u_jax / scale, rtol=0, atol=2e-5 * gain)
    np.testing.assert_allclose(numpy_policy(obs[0]), u_np[0])  # one observation as a batch of one
    return numpy_policy, u_np / scale


def test_numpy_export_matches_jax_and_acts_in_gymnasium(tiny, tmp_path):
    import gymnasium as gym

    import dobs_envs  # noqa: F401  (registers the ids)

    cfg, hp, env, env_params, out, _ = tiny
    run = select_run(out, 0)
    policy, _ = _check_export(tmp_path, run, cfg, hp, env, env_params, "trained")
    # a saturating actor (output layer x 300): the clipping to [-1, 1] is part of the map
    loud = dict(run, params=dict(run["params"], pi_w2=run["params"]["pi_w2"] * 300))
    _, a = _check_export(tmp_path, loud, cfg, hp, env, env_params, "saturating", gain=300)
    assert 0.2 < np.mean(np.abs(a) == 1.0) < 0.95  # clipped and unclipped entries

    meta = json.loads((tmp_path / "trained" / "policy.json").read_text())
    assert meta["env_id"] == ENV_ID and meta["net_arch"] == [16, 16]
    g = gym.make(ENV_ID)
    # the policy's [-1, 1] mapped onto the env's bounds (RescaleAction of the SB3 recipe)
    np.testing.assert_allclose(policy.arrays["action_scale"], g.action_space.high, rtol=1e-6)
    obs, _ = g.reset(seed=10000)
    steps, total, done = 0, 0.0, False
    while not done:
        u = policy(obs).astype(np.float32)
        assert g.action_space.contains(u)
        obs, r, term, trunc, _ = g.step(u)
        steps, total, done = steps + 1, total + r, term or trunc
    assert np.isfinite(total) and 1 <= steps <= g.spec.max_episode_steps
    g.close()

    with pytest.raises(FileExistsError, match="overwrite"):
        save_policy(str(tmp_path / "trained"), run, cfg, hp, env, env_params)
    with pytest.raises(ValueError, match="select_run"):
        save_policy(str(tmp_path / "both"), out, cfg, hp, env, env_params)
    with pytest.raises(ValueError, match=r"obs must have shape \(155,\)"):
        policy(np.zeros(154))


@pytest.mark.parametrize("change, message", [
    ({"target_kl": 0.02}, r"\['target_kl'\] are not implemented"),
    ({"batch_size": 48}, "batch_size 48 must divide"),
    ({"learning_rate": "exp_1e-3"}, "learning_rate must be a number or 'lin_<number>'"),
    ({"policy_kwargs": {"net_arch": {"pi": [8], "vf": [8]}}}, "net_arch must be a non-empty list"),
    ({"normalize": {"norm_obs": True, "clip_obs": 5, "bogus": 1}}, r"normalize keys \['bogus'\]"),
    ({"env_kwargs": {"dtype": "float64"}}, "may not set 'dtype'"),
])
def test_config_errors_name_the_key(change, message):
    with pytest.raises(ValueError, match=message):
        ppo_config({**TINY, **change}, ENV_ID, total_timesteps=256)


def test_snapshots_keep_the_initial_and_final_actor(tiny):
    """make_train(snapshots=...): update count 0 is the initialisation (init_params of the run's first key),
    the last the run's final actor and statistics (bitwise: the same values written into the buffer); the
    run with snapshots is the vmapped run without them (float32 round-off between batched and single code)."""
    from agents.training.jax import policy as pol

    cfg, hp, env, env_params, out_a, _ = tiny
    with pytest.raises(ValueError, match=r"update counts in 0\.\.2"):
        make_train(cfg, env, env_params, snapshots=[0, 3])
    key = jax.random.split(jax.random.PRNGKey(0), 3)[0]
    out = jax.device_get(jax.jit(make_train(cfg, env, env_params, snapshots=[2, 0, 1]))(key, hp))
    snap = out["snapshots"]
    assert snap["pi_w0"].shape[0] == 3 and "vf_w0" not in snap and "log_std" not in snap
    D, m = env.observation_space(env_params).shape[0], env.num_actions
    init = pol.init_params(jax.random.split(key, 3)[0], D, m, cfg.net_arch, hp["log_std_init"])
    for k in ("pi_w0", "pi_b0", "pi_w2"):
        np.testing.assert_array_equal(snap[k][0], np.asarray(init[k]))
        np.testing.assert_array_equal(snap[k][2], out["params"][k])
    # the first update moved the weights (the last one has learning rate 0: lin_ reaches 0 at the budget, as SB3's)
    assert not np.array_equal(snap["pi_w0"][1], snap["pi_w0"][0])
    np.testing.assert_array_equal(snap["obs_mean"][2], out["obs_mean"])
    np.testing.assert_array_equal(snap["obs_var"][2], out["obs_var"])
    np.testing.assert_allclose(out["params"]["pi_w0"], out_a["params"]["pi_w0"][0], rtol=1e-4, atol=1e-6)
