"""The jitted SAC and TD3 trainers (agents/training/jax/sac.py, td3.py): gradient steps against SBX's own SAC and
TD3 updates and an independent float64 numpy computation, the replay ring buffer, truncation handling, vmap over
seeds, the numpy export and the CLI (``train --trainer jax --algo sac|td3``, ``evaluate --model``)."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("optax")
import jax.numpy as jnp  # noqa: E402

from agents.training.jax import sac  # noqa: E402
from agents.training.jax.export import jax_act, save_policy  # noqa: E402
from agents.training.jax.numpy_policy import NumpyPolicy  # noqa: E402

ENV_ID = "dobs_envs/Tracking-v0"
#: a tiny run: 2 copies, 5-step episodes (truncation only: the state bound is far), 20 vector steps, a ring
#: of 10 rows (it wraps), learning after 16 env steps, 2 gradient steps of 8 samples per collect of 2 steps
TINY = {"policy": "MlpPolicy", "n_envs": 2, "learning_rate": "lin_1.0e-3", "buffer_size": 20, "learning_starts": 16,
        "batch_size": 8, "tau": 0.02, "gamma": 0.99, "train_freq": 2, "gradient_steps": 2, "ent_coef": "auto",
        "use_sde": True, "normalize": {"norm_obs": True, "norm_reward": True}, "normalize_actions": True,
        "policy_kwargs": {"net_arch": [8], "activation_fn": "relu"},
        "env_kwargs": {"state_bound": 1e5, "max_episode_steps": 5}}


# ---- one gradient step against SBX and against numpy ------------------------------------------------------------

def _batch(rng, n, D, m):
    return (rng.normal(0, 1, (n, D)).astype(np.float32), rng.uniform(-1, 1, (n, m)).astype(np.float32),
            rng.normal(0, 1, (n, D)).astype(np.float32), rng.normal(0, 1, (n,)).astype(np.float32),
            (rng.random(n) < 0.3).astype(np.float32))


def _sbx_trees(params, target):
    actor = {f"Dense_{i}": {"kernel": params[f"pi_w{i}"], "bias": params[f"pi_b{i}"]}
             for i in range(sum(k.startswith("pi_w") for k in params))}
    actor[f"Dense_{len(actor)}"] = {"kernel": params["ls_w"], "bias": params["ls_b"]}

    def critic(p):
        return {"params": {"VmapContinuousCritic_0": {
            f"Dense_{i}": {"kernel": p[f"qf_w{i}"], "bias": p[f"qf_b{i}"]}
            for i in range(sum(k.startswith("qf_w") for k in p))}}}

    return {"params": actor}, critic(params), critic(target)


def test_gradient_steps_equal_sbx_sac():
    """Three gradient steps from the same networks, batches and keys: SBX's SAC._train (update_critic,
    soft_update, update_actor, update_temperature; its TFP distribution, flax networks, optax Adam) against
    sac.update_step, float32 both: parameters, target critics, log alpha and losses agree to float32 rounding
    (different operation orders; Adam's first steps are sign-like, so relative tolerance 1e-5 on O(1e-3) moves)."""
    import flax.linen as nn
    import optax
    from flax.training.train_state import TrainState
    from sbx.common.policies import SquashedGaussianActor, VectorCritic
    from sbx.common.type_aliases import RLTrainState, ReplayBufferSamplesNp
    from sbx.sac.sac import SAC, EntropyCoef

    D, m, n, G, lr, lr_alpha, tau, gamma, H = 4, 2, 16, 3, 3e-3, 1e-3, 0.05, 0.97, -float(2)
    params = sac.init_params(jax.random.PRNGKey(0), D, m, (8, 8))
    params["ls_b"] = params["ls_b"] + 0.3  # not at the initial zero bias: a sigma of its own
    target = {k: v for k, v in sac.init_params(jax.random.PRNGKey(1), D, m, (8, 8)).items() if k.startswith("qf_")}
    log_alpha = jnp.asarray(np.log(0.3), jnp.float32)
    rng = np.random.default_rng(0)
    data = [np.concatenate(x) for x in zip(*[_batch(rng, n, D, m) for _ in range(G)])]

    actor_tree, qf_tree, target_tree = _sbx_trees(params, target)
    actor = SquashedGaussianActor(net_arch=[8, 8], action_dim=m, activation_fn=nn.relu)
    qf = VectorCritic(net_arch=[8, 8], n_critics=2, activation_fn=nn.relu)
    adam = optax.inject_hyperparams(optax.adam)(learning_rate=lr)
    actor_state = TrainState.create(apply_fn=actor.apply, params=actor_tree, tx=adam)
    qf_state = RLTrainState.create(apply_fn=qf.apply, params=qf_tree, target_params=target_tree, tx=adam)
    ent_state = TrainState.create(apply_fn=EntropyCoef(0.3).apply, params={"log_ent_coef": log_alpha},
                                  tx=optax.adam(learning_rate=lr_alpha))
    obs, act, nxt, rew, done = (jnp.asarray(x) for x in data)
    key = jax.random.PRNGKey(42)
    samples = ReplayBufferSamplesNp(obs, act, nxt, done, rew, jnp.full((G * n,), gamma, jnp.float32))
    qf_state, actor_state, ent_state, _, (pi_loss, q_loss, _, alpha_used) = SAC._train(
        tau, H, G, samples, 1, 0, qf_state, actor_state, ent_state, key)

    state = (params, target, log_alpha, sac.init_opts(params, log_alpha))
    step = jax.jit(lambda s, b, ks: sac.update_step(s, b, ks, lr=lr, lr_alpha=lr_alpha, gamma=gamma, tau=tau,
                                                     target_entropy=H, activation="relu"))
    k = key
    for g in range(G):  # SBX's key chain: update_critic splits 4 (noise: [1]), update_actor splits 3 (noise: [2])
        k_critic = jax.random.split(k, 4)
        k_actor = jax.random.split(k_critic[0], 3)
        sl = slice(g * n, (g + 1) * n)
        state, (q_mine, pi_mine, alpha_mine) = step(state, tuple(x[sl] for x in (obs, act, nxt, rew, done)),
                                                    (k_critic[1], k_actor[2]))
        k = k_actor[0]
    p, t, la, _ = state
    mine_actor, mine_qf, mine_target = _sbx_trees(p, t)
    moved = 0.0
    for ours, theirs in ((mine_actor, actor_state.params), (mine_qf, qf_state.params),
                         (mine_target, qf_state.target_params)):
        for a, b in zip(jax.tree.leaves(ours), jax.tree.leaves(theirs)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=2e-6)
    for a, b in zip(jax.tree.leaves(mine_actor), jax.tree.leaves(_sbx_trees(params, target)[0])):
        moved = max(moved, float(np.max(np.abs(np.asarray(a) - np.asarray(b)))))
    assert moved > 5e-3  # G Adam steps of ~lr each: the comparison is not of unchanged networks
    np.testing.assert_allclose(float(la), float(ent_state.params["log_ent_coef"]), rtol=1e-5)
    assert float(la) != float(log_alpha)
    # the actor loss is a mean of differences of O(1) terms (alpha log pi - min Q; ~0.06 here), so its float32
    # rounding is absolute, of the order of the parameters' (atol 2e-6 above), not relative to the small result
    np.testing.assert_allclose([float(q_mine), float(pi_mine), float(alpha_mine)],
                               [float(q_loss), float(pi_loss), float(alpha_used)], rtol=1e-5, atol=2e-6)


def _np_mlp(ws, bs, x, last_act=False):
    for i, (w, b) in enumerate(zip(ws, bs)):
        x = x @ w + b
        if i < len(ws) - 1 or last_act:
            x = np.maximum(x, 0.0)
    return x


def test_losses_polyak_and_alpha_against_numpy():
    """The losses of one step in float64 numpy, written from the SAC equations (Haarnoja et al. 2018, the
    tanh change of variables as log(1 - tanh(x)^2), not the softplus form the trainer uses), on a batch with
    terminations (no bootstrap) and non-terminal transitions (bootstrap with the entropy term)."""
    D, m, n = 3, 2, 6
    params = {k: np.asarray(v, np.float64) for k, v in sac.init_params(jax.random.PRNGKey(3), D, m, (5,)).items()}
    target = {k: v * 0.5 for k, v in params.items() if k.startswith("qf_")}
    obs, act, nxt, rew, done = _batch(np.random.default_rng(1), n, D, m)
    done[:2] = 1.0
    alpha, gamma, k = 0.2, 0.9, jax.random.PRNGKey(5)
    eps = np.asarray(sac.standard_normal(k, (n, m)), np.float64)

    def pi(o):
        h = _np_mlp([params["pi_w0"]], [params["pi_b0"]], o, last_act=True)
        mu = h @ params["pi_w1"] + params["pi_b1"]
        log_std = np.clip(h @ params["ls_w"] + params["ls_b"], -20, 2)
        x = mu + np.exp(log_std) * eps
        logp = np.sum(-0.5 * eps ** 2 - log_std - 0.5 * np.log(2 * np.pi) - np.log(1 - np.tanh(x) ** 2), axis=-1)
        return np.tanh(x), logp

    def q(p, o, a):
        x = np.concatenate([o, a], axis=-1)
        return np.stack([_np_mlp([p["qf_w0"][c], p["qf_w1"][c]], [p["qf_b0"][c], p["qf_b1"][c]], x)[:, 0]
                         for c in range(2)])

    a_next, logp_next = pi(nxt)
    y = rew + (1 - done) * gamma * (q(target, nxt, a_next).min(axis=0) - alpha * logp_next)
    ref_q = 0.5 * np.sum(np.mean((y - q(params, obs, act)) ** 2, axis=1))
    a_pi, logp_pi = pi(obs)
    ref_pi = np.mean(alpha * logp_pi - q(params, obs, a_pi).min(axis=0))
    f32 = {k_: jnp.asarray(v, jnp.float32) for k_, v in params.items()}
    qf = {k_: v for k_, v in f32.items() if k_.startswith("qf_")}
    actor = {k_: v for k_, v in f32.items() if not k_.startswith("qf_")}
    tgt = {k_: jnp.asarray(v, jnp.float32) for k_, v in target.items()}
    got_q = sac.critic_loss(qf, tgt, actor, alpha, (obs, act, nxt, rew, done), gamma, k, "relu")
    got_pi, entropy = sac.actor_loss(actor, qf, alpha, obs, k, "relu")
    np.testing.assert_allclose(float(got_q), ref_q, rtol=2e-5)
    np.testing.assert_allclose(float(got_pi), ref_pi, rtol=2e-5, atol=1e-6)
    np.testing.assert_allclose(float(entropy), -np.mean(logp_pi), rtol=2e-5)
    # temperature: L = log(alpha) (H - H_target); its gradient in log alpha is H - H_target
    la = jnp.asarray(np.log(alpha), jnp.float32)
    np.testing.assert_allclose(float(sac.alpha_loss(la, entropy, -2.0)), np.log(alpha) * (-np.mean(logp_pi) + 2),
                               rtol=2e-5)
    np.testing.assert_allclose(float(jax.grad(sac.alpha_loss)(la, entropy, -2.0)), -np.mean(logp_pi) + 2, rtol=2e-5)
    # polyak: tau theta + (1 - tau) theta'
    new = sac.polyak(qf, tgt, 0.02)
    for kk in qf:
        np.testing.assert_allclose(np.asarray(new[kk]), 0.02 * params[kk] + 0.98 * target[kk], rtol=1e-6, atol=1e-7)
    # the deterministic policy is tanh of the mean (SBX's mode())
    h = np.maximum(obs @ params["pi_w0"] + params["pi_b0"], 0)
    mu, _ = sac.actor_dist(actor, jnp.asarray(obs), "relu")
    np.testing.assert_allclose(np.asarray(mu), h @ params["pi_w1"] + params["pi_b1"], rtol=1e-5, atol=1e-6)


# ---- replay ring buffer -------------------------------------------------------------------------------------------

def test_ring_buffer_wraps_and_samples_the_filled_rows():
    rows, B = 3, 2
    ring = sac.ring_init(rows, B, 2, 1)
    write = jax.jit(sac.ring_write)
    seen = []
    for t in range(7):
        row = {"obs": np.full((B, 2), t), "action": np.full((B, 1), -t), "next_obs": np.full((B, 2), t + 0.5),
               "reward": np.arange(B) + 10 * t, "done": np.full(B, t % 2)}
        ring = write(ring, row)
        seen.append((int(ring[1]), bool(ring[2])))
    # position advances modulo 3; full once it wrapped (after the third write)
    assert seen == [(1, False), (2, False), (0, True), (1, True), (2, True), (0, True), (1, True)]
    buf = ring[0]
    # row r holds the last write t with t % 3 == r: rows 0, 1, 2 <- t = 6, 4, 5
    np.testing.assert_array_equal(buf["obs"][:, 0, 0], [6, 4, 5])
    np.testing.assert_array_equal(buf["action"][:, 1, 0], [-6, -4, -5])
    np.testing.assert_array_equal(buf["reward"], [[60, 61], [40, 41], [50, 51]])
    np.testing.assert_array_equal(buf["done"][:, 0], [0, 0, 1])
    # sampling: only the rows written so far (SB3: randint(0, pos) until full), every copy
    r, e = sac.sample_indices(jax.random.PRNGKey(0), 4000, jnp.asarray(2), jnp.asarray(False), rows, B)
    assert set(np.unique(r)) == {0, 1} and set(np.unique(e)) == {0, 1}
    r, _ = sac.sample_indices(jax.random.PRNGKey(0), 4000, jnp.asarray(1), jnp.asarray(True), rows, B)
    assert set(np.unique(r)) == {0, 1, 2}


# ---- a tiny run: truncation, vmap over seeds ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def tiny():
    cfg, hp = sac.sac_config(TINY, ENV_ID, total_timesteps=40)
    env, env_params = sac.make_env(cfg)
    fn = sac.make_train(cfg, env, env_params, return_buffer=True)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    single = jax.jit(fn)
    runs = [jax.device_get(single(k, hp)) for k in keys]
    batch = {k: jnp.full((2,), hp[k], jnp.float32) for k in sac.HPARAMS}
    both = jax.device_get(jax.jit(jax.vmap(fn))(keys, batch))
    return cfg, hp, env, env_params, runs, both


def test_truncated_episodes_bootstrap_from_their_final_observation(tiny):
    cfg, _, _, _, runs, _ = tiny
    assert cfg.buffer_rows == 10 and cfg.n_updates == 10 and cfg.steps_done == 40
    for out in runs:
        c = out["curve"]
        # 5-step episodes of 2 copies over 20 vector steps, every one truncated (the state bound is 1e5)
        assert int(c["episodes"].sum()) == 8 and np.all(c["episode_length"][c["episodes"] > 0] == 5)
        # learning once the step count after a collect exceeds 16: not after collects 1-4 (4, 8, 12, 16 steps)
        assert np.all(np.isnan(c["critic_loss"][:4])) and np.all(np.isfinite(c["critic_loss"][4:]))
        assert int(out["buffer_pos"]) == 0 and bool(out["buffer_full"])  # 20 rows written into 10: wrapped twice
        buf = out["buffer"]  # rows 0..9 hold vector steps 10..19, in order (the position is back at 0)
        assert np.all(buf["done"] == 0)  # truncation is not termination: these transitions bootstrap
        for r in range(9):
            same = np.array_equal(buf["next_obs"][r], buf["obs"][r + 1])
            # an episode ends after vector steps 14 and 19: there the next observation is the final one,
            # not the next episode's first observation (which the following row starts from)
            assert same == ((10 + r + 1) % 5 != 0), r
        assert np.all(np.isfinite(buf["next_obs"])) and not np.array_equal(buf["next_obs"][4], buf["obs"][5])


def test_vmap_over_two_seeds_equals_two_single_runs(tiny):
    _, _, _, _, runs, both = tiny
    for i, single in enumerate(runs):
        for name in ("params", "target", "log_alpha", "obs_mean", "obs_var", "ret_var"):
            for a, b in zip(jax.tree.leaves(single[name]), jax.tree.leaves(both[name])):
                np.testing.assert_allclose(a, b[i], rtol=1e-5, atol=1e-6, err_msg=name)
        np.testing.assert_array_equal(single["buffer"]["action"], both["buffer"]["action"][i])
    assert not np.array_equal(runs[0]["params"]["pi_w0"], runs[1]["params"]["pi_w0"])


def test_export_tanh_policy_matches_jax_and_old_ppo_files_load(tiny, tmp_path):
    cfg, hp, env, env_params, runs, _ = tiny
    d = save_policy(str(tmp_path / "p"), runs[0], cfg, hp, env, env_params)
    pol = NumpyPolicy(d)
    assert pol.meta["kind"] == "tanh" and pol.meta["format"] == "dobs_envs.jax_policy/2"
    assert not any(k.startswith(("ls_", "qf_")) for k in pol.arrays)  # the deterministic actor only
    rng = np.random.default_rng(0)
    obs = (runs[0]["obs_mean"] + np.sqrt(runs[0]["obs_var"]) * rng.normal(0, 3, (64, pol.obs_dim))).astype(np.float32)
    u = pol(obs)
    np.testing.assert_allclose(u, np.asarray(jax_act(runs[0], cfg, hp, env, env_params)(jnp.asarray(obs))),
                               rtol=1e-4, atol=1e-5 * float(np.max(pol.arrays["action_scale"])))
    scale = pol.arrays["action_scale"]
    assert np.all(np.abs(u) <= scale) and np.any(np.abs(u) < 0.99 * scale)  # tanh onto the bounds
    # a file of the first format (PPO's, no kind) is still read, as the clipped mean
    meta = json.load(open(os.path.join(d, "policy.json")))
    meta.pop("kind")
    meta["format"] = "dobs_envs.jax_ppo_policy/1"
    old = NumpyPolicy.from_arrays(pol.arrays, meta)
    assert old.meta["kind"] == "clip"
    from agents.training.jax.numpy_policy import numpy_actor_mean
    o = np.clip((obs - pol.arrays["obs_mean"]) / np.sqrt(pol.arrays["obs_var"] + 1e-8), -10, 10)
    np.testing.assert_allclose(old(obs), np.clip(numpy_actor_mean(pol.arrays, o, "relu"), -1, 1) * scale)
    with pytest.raises(ValueError, match="kind"):
        NumpyPolicy.from_arrays(pol.arrays, dict(pol.meta, kind="softmax"))


@pytest.mark.parametrize("bad, name", [({"policy_delay": 2}, "policy_delay"),
                                       ({"sde_sample_freq": 4}, "sde_sample_freq"),
                                       ({"policy_kwargs": {"log_std_init": -3}}, "log_std_init"),
                                       ({"train_freq": [1, "episode"]}, "train_freq"),
                                       ({"ent_coef": "auto_-1"}, "ent_coef")])
def test_unimplemented_or_bad_recipe_keys_are_refused_by_name(bad, name):
    with pytest.raises(ValueError, match=name):
        sac.sac_config({**TINY, **bad}, ENV_ID)


# ---- the CLI ------------------------------------------------------------------------------------------------------

#: the tracking recipe (SAC's or TD3's) with tiny networks and 4 collects of 8 x 32 steps (a curve of 5 points)
CLI_HP = {"policy_kwargs": {"net_arch": [16, 16], "activation_fn": "relu"}, "learning_starts": 256, "batch_size": 64,
          "buffer_size": 2048, "train_freq": 32, "gradient_steps": 4}


@pytest.mark.parametrize("algo, refused", [("sac", "policy_delay"), ("td3", "use_sde")])
def test_cli_run_directory_and_evaluate(algo, refused, tmp_path, capsys):
    """``train --trainer jax --algo sac|td3``: the run directory (the records, the exported tanh policy, the curve
    in the benchmark's format), ``evaluate --model`` scoring it as the "SAC (JAX)" / "TD3 (JAX)" row with the
    harness's figures, and a recipe key the trainer lacks refused in one line."""
    from importlib import metadata

    from agents.config.envs import gym_factory
    from agents.evaluate import evaluate_policy, summarise
    from agents.training.recipes import resolve_recipe
    from dobs_envs.cli import main

    out = str(tmp_path / "run")
    assert main(["train", "--trainer", "jax", "--algo", algo, "--env", "tracking", "--timesteps", "1024", "--seed",
                 "2", "--out", out, "--no-progress", "--hyperparams", json.dumps(CLI_HP)]) == 0
    assert f"trained {algo} (jax) on tracking: 1024 env steps" in capsys.readouterr().out
    assert sorted(os.listdir(out)) == ["config.json", "curve.json", "policy.json", "policy.npz", "train_curve.json"]
    cfg = json.load(open(os.path.join(out, "config.json")))
    assert cfg["trainer"] == "jax" and cfg["library"] == "agents.training.jax" and cfg["algo"] == algo
    assert cfg["jax_version"] == jax.__version__ and cfg["optax_version"] == metadata.version("optax")
    assert cfg["status"] == "complete" and cfg["seed"] == 2 and cfg["timesteps_done"] == 1024
    assert cfg["n_updates"] == 4 and cfg["rollout"] == 256
    assert cfg["hyperparams"] == json.loads(json.dumps(resolve_recipe(algo, "tracking", overrides=CLI_HP).hyperparams))
    for k in ("compile_seconds", "train_seconds", "train_cpu_seconds", "curve_seconds"):
        assert math.isfinite(cfg[k]) and cfg[k] > 0, k
    meta = json.load(open(os.path.join(out, "policy.json")))
    assert meta["kind"] == "tanh" and meta["trainer"] == f"agents.training.jax.{algo}"
    curve = json.load(open(os.path.join(out, "curve.json")))
    assert [p["env_steps"] for p in curve["points"]] == [0, 256, 512, 768, 1024]
    tc = json.load(open(os.path.join(out, "train_curve.json")))
    assert tc["steps"] == [256, 512, 768, 1024] and tc["critic_loss"][0] is None and tc["critic_loss"][1] is not None
    # evaluate --model: the "SAC (JAX)" / "TD3 (JAX)" row, the harness's figures on the compiled env
    js = str(tmp_path / "eval.json")
    assert main(["evaluate", "--model", out, "--episodes", "2", "--seed", "10000", "--json", js]) == 0
    summ = json.load(open(js))
    assert summ["policy"] == f"{algo.upper()} (JAX)" and summ["seeds"] == [10000, 10001]
    env = gym_factory("tracking", {})()
    ref = summarise(evaluate_policy(env, NumpyPolicy(out), 2, 10000, parallel=False))
    env.close()
    assert {k: v for k, v in summ.items() if k not in ("policy", "model")} == json.loads(json.dumps(ref))
    # a recipe key the trainer lacks: one usage line naming it, the run directory untouched
    before = {f: open(os.path.join(out, f), "rb").read() for f in os.listdir(out)}
    with pytest.raises(SystemExit) as exc:
        main(["train", "--trainer", "jax", "--algo", algo, "--timesteps", "64", "--no-progress", "--out", out,
              "--overwrite", "--hyperparams", json.dumps({refused: 2})])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and refused in err and err.count("\n") == 0
    assert {f: open(os.path.join(out, f), "rb").read() for f in os.listdir(out)} == before


# ---- TD3 (the same loop, SBX's TD3 learner) --------------------------------------------------------------------------

def test_td3_gradient_steps_equal_sbx_td3():
    """Four gradient steps (policy_delay 2: two actor steps) from the same networks, batches and keys: SBX's
    TD3._train (update_critic with target policy smoothing, soft_update of both targets, delayed update_actor)
    against td3.update_step; tolerances as for SAC."""
    import flax.linen as nn
    import optax
    from sbx.common.policies import VectorCritic
    from sbx.common.type_aliases import ReplayBufferSamplesNp, RLTrainState
    from sbx.td3.policies import Actor
    from sbx.td3.td3 import TD3

    from agents.training.jax import td3

    D, m, n, G, lr, tau, gamma, sigma, clip = 4, 2, 16, 4, 3e-3, 0.05, 0.97, 0.2, 0.3
    params = td3.init_td3(jax.random.PRNGKey(0), D, m, (8, 8))
    target = td3.init_td3(jax.random.PRNGKey(1), D, m, (8, 8))
    rng = np.random.default_rng(2)
    obs, act, nxt, rew, done = (jnp.asarray(np.concatenate(x)) for x in zip(*[_batch(rng, n, D, m)
                                                                              for _ in range(G)]))
    a_tree, q_tree, qt_tree = _sbx_trees(dict(params, ls_w=None, ls_b=None), target)
    del a_tree["params"]["Dense_3"]  # the SAC helper's log-sigma head
    at_tree = {"params": {f"Dense_{i}": {"kernel": target[f"pi_w{i}"], "bias": target[f"pi_b{i}"]} for i in range(3)}}
    actor = Actor(net_arch=[8, 8], action_dim=m, activation_fn=nn.relu)
    qf = VectorCritic(net_arch=[8, 8], n_critics=2, activation_fn=nn.relu)
    adam = optax.inject_hyperparams(optax.adam)(learning_rate=lr)
    actor_state = RLTrainState.create(apply_fn=actor.apply, params=a_tree, target_params=at_tree, tx=adam)
    qf_state = RLTrainState.create(apply_fn=qf.apply, params=q_tree, target_params=qt_tree, tx=adam)
    key = jax.random.PRNGKey(7)
    samples = ReplayBufferSamplesNp(obs, act, nxt, done, rew, jnp.full((G * n,), gamma, jnp.float32))
    qf_state, actor_state, _, (pi_loss, q_loss) = TD3._train(tau, G, samples, 2, 1, sigma, clip, qf_state, actor_state,
                                                             key)

    state = (params, target, td3.init_opts(params), jnp.asarray(0, jnp.int32))
    step = jax.jit(lambda s, b, k: td3.update_step(s, b, k, lr=lr, gamma=gamma, tau=tau, noise_std=sigma,
                                                   noise_clip=clip, activation="relu", policy_delay=2))
    k = key
    for g in range(G):  # SBX's key chain: update_critic splits 4 (noise: [1]); update_actor splits 2
        ks = jax.random.split(k, 4)
        sl = slice(g * n, (g + 1) * n)
        state, (q_mine, pi_mine) = step(state, tuple(x[sl] for x in (obs, act, nxt, rew, done)), ks[1])
        k = jax.random.split(ks[0], 2)[0] if g % 2 == 1 else ks[0]
        assert np.isnan(float(pi_mine)) == (g % 2 == 0)  # the actor moves on every second step
    p, t, _, count = state
    assert int(count) == G
    pairs = [(p[f"pi_{w}{i}"], actor_state.params["params"][f"Dense_{i}"][name])
             for i in range(3) for w, name in (("w", "kernel"), ("b", "bias"))]
    pairs += [(t[f"pi_{w}{i}"], actor_state.target_params["params"][f"Dense_{i}"][name])
              for i in range(3) for w, name in (("w", "kernel"), ("b", "bias"))]
    crit = qf_state.params["params"]["VmapContinuousCritic_0"]
    crit_t = qf_state.target_params["params"]["VmapContinuousCritic_0"]
    pairs += [(src[f"qf_{w}{i}"], tree[f"Dense_{i}"][name]) for src, tree in ((p, crit), (t, crit_t))
              for i in range(3) for w, name in (("w", "kernel"), ("b", "bias"))]
    for a, b in pairs:
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=2e-6)
    assert float(np.max(np.abs(np.asarray(p["pi_w2"]) - np.asarray(params["pi_w2"])))) > 5e-3  # the actor moved
    np.testing.assert_allclose([float(q_mine), float(pi_mine)], [float(q_loss), float(pi_loss)], rtol=1e-5)
