"""The jitted shared-policy PPO (agents/training/jax/ippo.py, run_marl.py): each slot sees its own agent's observation
and nothing else, the (copy, agent) slot layout round-trips through the env, a vmapped pair of seeds is two single
runs, the exported numpy policy acts as the JAX policy, and ``train --trainer jax --multi-agent`` writes a run that
``evaluate --model`` scores on the compiled PettingZoo env."""
from __future__ import annotations

import json
import math
import os
from dataclasses import replace

import numpy as np
import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("optax")
import jax.numpy as jnp  # noqa: E402

from agents.training.jax.ippo import (agent_actions, ippo_config, jax_act_shared, make_marl_env,  # noqa: E402
                                      make_train, marl_slots, slot_layout, slot_observations)
from agents.training.jax.ppo import HPARAMS  # noqa: E402
from agents.training.recipes import resolve_recipe  # noqa: E402
from agents.vecenv.slots import SlotEncoder  # noqa: E402
from jax_run_records import MARL_CONFIG_KEYS  # noqa: E402

#: the shipped multi-agent tracking recipe at a tiny size: 2 updates of 2 copies x 5 agents x 16 steps, net [8, 8]
TINY = {"n_envs": 2, "n_steps": 16, "batch_size": 32, "n_epochs": 2,
        "policy_kwargs": {"net_arch": [8, 8], "activation_fn": "tanh", "log_std_init": -2.0}}


@pytest.fixture(scope="module")
def setup():
    hp = resolve_recipe("ppo", "tracking", multi_agent=True, overrides=TINY).hyperparams
    cfg, h = ippo_config(hp, "tracking", total_timesteps=64)
    env = make_marl_env(cfg)
    return cfg, h, env, slot_layout(env, cfg)


def _encoder(env, layout):
    """The SB3 shared path's encoder (CoreVecEnv / loading) over the PettingZoo spaces of ``env``."""
    from dobs_envs.envs.adapter import agent_spaces

    obs_sp, act_sp = agent_spaces(env.core)
    agents = list(env.agents)
    return SlotEncoder(agents, dict(zip(agents, obs_sp)), dict(zip(agents, act_sp)), agent_id=layout.agent_id,
                       rescale_actions=layout.rescale)


def test_slot_is_its_agents_own_observation(setup):
    """Slot k's input is agent k's observation of the env (the compiled PettingZoo env's, through the state copied
    into the JAX env), padded, plus its one-hot id: SlotEncoder's encoding; and it depends on no other agent's
    observation (its Jacobian with respect to them is exactly zero)."""
    from agents.config.envs import parallel_factory
    from baselines.references import base_env
    from dobs_envs.jax.parity import state_from_core

    cfg, _, env, layout = setup
    K = layout.n_agents
    assert layout.agent_id and layout.rescale and layout.width == layout.obs_dim + K  # the recipe's agent_id
    pz = parallel_factory("tracking", cfg.ppo.env_kwargs)()
    assert list(pz.possible_agents) == list(layout.agents)
    obs, _ = pz.reset(seed=20000)
    rng = np.random.default_rng(0)
    for _ in range(5):  # away from the reset: the observers disagree, the agents' observations differ
        obs, *_ = pz.step({a: rng.uniform(-5, 5, (1,)).astype(np.float32) for a in pz.possible_agents})
    state = state_from_core(base_env(pz).core, 0, jnp.float32)
    got = np.asarray(slot_observations(env.get_obs(state), layout))
    ref = _encoder(env, layout).encode_all(obs)
    scale = np.maximum(1.0, np.abs(ref))
    np.testing.assert_allclose(got / scale, ref / scale, rtol=0, atol=1e-4)  # float32 JAX features vs float64 core
    assert not np.allclose(ref[0, :layout.obs_dim], ref[1, :layout.obs_dim])
    pz.close()

    rows = {a: jnp.asarray(obs[a]) for a in layout.agents}
    jac = jax.jacobian(lambda o: slot_observations(o, layout))(rows)  # {agent j: (K, width, w_j)}
    for j, a in enumerate(layout.agents):
        J = np.asarray(jac[a])
        for k in range(K):
            if k == j:
                np.testing.assert_array_equal(J[k, :layout.obs_widths[j]], np.eye(layout.obs_widths[j]))
                assert not J[k, layout.obs_widths[j]:].any()
            else:
                assert not J[k].any(), (k, a)


def _reset_and_step(env, layout, B):
    """One compiled program: marl_slots' reset and step of ``B`` copies, beside env.reset / env.step vmapped (the
    JaxMARL interface) on the same keys and the slots' actions decoded by agent_actions."""
    K = layout.n_agents
    slots = marl_slots(env, layout, B)
    assert slots.n_slots == B * K and slots.copies == B and slots.obs_dim == layout.width

    @jax.jit
    def run(key, k_step, action):
        obs, state = slots.reset(key)
        ref_obs, ref_state = jax.vmap(env.reset)(jax.random.split(key, B))
        out = slots.step(k_step, state, action)
        acts = jax.vmap(lambda a: agent_actions(a, layout))(action.reshape(B, K, -1))
        ref = jax.vmap(env.step)(jax.random.split(k_step, B), ref_state, acts)
        return obs, ref_obs, out, ref

    return run


def test_slot_layout_round_trips_through_the_env(setup):
    """Slot c*K + k of marl_slots is agent k of copy c: its observation at reset, the input the env applies for its
    action (SlotEncoder.decode_batch's, the SB3 shared path's), its reward (the copy's team reward), its end
    (terminated / truncated) and its final observation."""
    cfg, _, env, layout = setup
    K, B = layout.n_agents, 3
    enc = _encoder(env, layout)
    key, k_step = jax.random.PRNGKey(7), jax.random.PRNGKey(8)
    action = np.linspace(-1.2, 1.2, B * K, dtype=np.float32).reshape(B * K, 1)  # distinct per slot, some clipped
    run_long = _reset_and_step(env, layout, B)
    obs, ref_obs, (nxt, state, reward, term, trunc, final), ref = jax.device_get(
        run_long(key, k_step, jnp.asarray(action)))
    per_copy = np.stack([np.stack([ref_obs[a][c] for a in layout.agents]) for c in range(B)])
    np.testing.assert_array_equal(obs, enc.encode_batch(per_copy))
    np.testing.assert_allclose(state.u, enc.decode_batch(action), rtol=1e-6)  # the inputs applied (B, m)
    r = reward.reshape(B, K)
    np.testing.assert_array_equal(r, np.repeat(r[:, :1], K, axis=1))  # one team reward per copy, in each slot
    # the slots' step and env.step are two computations: float32 round-off (a few ulps) between them
    np.testing.assert_allclose(r[:, 0], ref[2][layout.agents[0]], rtol=1e-6)
    for c in range(B):
        for k, a in enumerate(layout.agents):
            want = enc.encode(k, ref[0][a][c])
            np.testing.assert_allclose(nxt[c * K + k], want, rtol=1e-5, atol=1e-5 * np.abs(want).max())
    assert not term.any() and not trunc.any()
    np.testing.assert_array_equal(final, nxt)  # no episode ended: the final observation is the next one
    nxt_long = nxt

    # episodes of one step and a state bound between the copies' ||x|| after it: the copy above it terminates, the
    # others are truncated; all their slots end together, with the step's observation as the final one and the
    # next episode's first observation as the next one
    xn = np.linalg.norm(state.x, axis=1)
    short = replace(cfg, ppo=replace(cfg.ppo, env_kwargs={"state_bound": float(np.sort(xn)[1]) * 1.0001,
                                                          "max_episode_steps": 1}))
    _, _, (nxt, state2, _, term, trunc, final), ref = jax.device_get(
        _reset_and_step(make_marl_env(short), layout, B)(key, k_step, jnp.asarray(action)))
    np.testing.assert_allclose(state2.t, 0.0)  # every copy reset
    copy_term = xn > np.sort(xn)[1] * 1.0001
    assert copy_term.sum() == 1
    np.testing.assert_array_equal(term, np.repeat(copy_term, K))
    np.testing.assert_array_equal(trunc, np.repeat(~copy_term, K))
    for c in range(B):
        for k, a in enumerate(layout.agents):
            np.testing.assert_allclose(nxt[c * K + k], enc.encode(k, ref[0][a][c]), rtol=1e-6)  # env.step's reset
    assert not np.allclose(final, nxt)
    # the final observation: the one the step produced (the long-episode env's after its first step, same keys)
    np.testing.assert_allclose(final, nxt_long, rtol=1e-5, atol=1e-5 * np.abs(nxt_long).max())


@pytest.fixture(scope="module")
def runs(setup):
    """One compiled vmapped run over two seeds and one compiled single run called with each seed."""
    cfg, h, env, _ = setup
    train = make_train(cfg, env)
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    batch = {k: jnp.full((2,), h[k], jnp.float32) for k in HPARAMS}
    both = jax.device_get(jax.jit(jax.vmap(train))(keys, batch))
    single = jax.jit(train)
    return both, [jax.device_get(single(k, h)) for k in keys]


def test_vmap_over_two_seeds_is_two_single_runs(runs, setup):
    cfg, _, _, layout = setup
    both, singles = runs
    assert cfg.ppo.n_updates == 2
    assert both["params"]["pi_w0"].shape == (2, layout.width, 8)
    np.testing.assert_array_equal(both["curve"]["steps"], [[32, 64]] * 2)  # env steps: 2 copies x 16 steps
    # every slot's reset and step observation counted once: 1e-4 + B K (reset) + B K per step
    np.testing.assert_allclose(both["obs_count"], 1e-4 + 10 * (1 + 32), rtol=1e-6)
    assert not np.array_equal(both["params"]["pi_w0"][0], both["params"]["pi_w0"][1])
    for i, one in enumerate(singles):
        # float32 round-off between the batched and the single program (as test_jax_training's snapshot test)
        for k in one["params"]:
            np.testing.assert_allclose(both["params"][k][i], one["params"][k], rtol=1e-4, atol=1e-6, err_msg=k)
        np.testing.assert_allclose(both["obs_mean"][i], one["obs_mean"], rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(both["curve"]["episodes"][i], one["curve"]["episodes"])


def test_exported_numpy_policy_acts_as_the_jax_policy(runs, setup, tmp_path):
    """The shared actor written by the run directory's writer, acted by NumpyPolicy through the SlotEncoder (what
    evaluate does), gives every agent the JAX policy's input on the same observations."""
    from agents.training.jax.export import save_policy
    from agents.training.jax.numpy_policy import NumpyPolicy
    from agents.training.jax.run_marl import shared_export
    from agents.training.loading import slot_policy

    cfg, h, env, layout = setup
    one = runs[1][0]
    cfg_p, space, extra = shared_export(cfg, layout)
    d = save_policy(str(tmp_path / "shared"), one, cfg_p, h, space, None, extra=extra)
    numpy_act = NumpyPolicy(d)
    assert numpy_act.obs_dim == layout.width and np.all(numpy_act.arrays["action_scale"] == 1.0)
    policy = slot_policy(_encoder(env, layout), numpy_act)
    loud = dict(one, params=dict(one["params"], pi_w2=one["params"]["pi_w2"] * 300))  # saturating: the clips act
    rng = np.random.default_rng(1)
    sd = np.sqrt(one["obs_var"][:layout.obs_dim])
    clipped = 0
    for run, gain in ((one, 1.0), (loud, 300.0)):
        if run is loud:
            d = save_policy(str(tmp_path / "loud"), run, cfg_p, h, space, None, extra=extra)
            policy = slot_policy(_encoder(env, layout), NumpyPolicy(d))
        act = jax_act_shared(run, cfg, h, layout)
        for _ in range(20):
            obs = {a: (one["obs_mean"][:w] + sd[:w] * rng.normal(0, 4, w)).astype(np.float32)
                   for a, w in zip(layout.agents, layout.obs_widths)}
            u_np, u_jax = policy(obs), jax.device_get(act(obs))
            for k, a in enumerate(layout.agents):
                bound = layout.act_hi[k, 0]
                # float32 network against float64 over three layers, times the output layer's gain
                np.testing.assert_allclose(u_np[a] / bound, u_jax[a] / bound, rtol=0, atol=2e-5 * gain)
                clipped += int(np.abs(u_np[a][0]) == bound)
    assert clipped > 0


def test_cli_run_is_scored_by_evaluate_on_the_pettingzoo_env(tmp_path, capsys):
    from agents.config.envs import parallel_factory
    from agents.evaluate import evaluate_policy, summarise
    from agents.training.loading import JaxTrainedAgent, load_agent
    from dobs_envs.cli import main

    out = str(tmp_path / "run")
    hp = {"n_steps": 64, "n_epochs": 1, "policy_kwargs": {"net_arch": [8, 8], "activation_fn": "tanh",
                                                          "log_std_init": -2.0}}
    assert main(["train", "--trainer", "jax", "--multi-agent", "--env", "tracking", "--timesteps", "512", "--seed",
                 "2", "--out", out, "--no-progress", "--hyperparams", json.dumps(hp)]) == 0
    assert "(jax, shared)" in capsys.readouterr().out
    assert sorted(os.listdir(out)) == ["config.json", "curve.json", "policy.json", "policy.npz", "train_curve.json"]
    cfg = json.load(open(os.path.join(out, "config.json")))
    assert cfg["trainer"] == "jax" and cfg["multi_agent"] is True and cfg["status"] == "complete"
    assert set(cfg) == MARL_CONFIG_KEYS
    assert cfg["n_agents"] == 5 and cfg["agent_id"] is True and cfg["normalize_actions"] is True
    assert cfg["timesteps_done"] == 512 and cfg["n_updates"] == 2 and cfg["samples_per_update"] == 5 * 256
    assert cfg["hyperparams"] == json.loads(json.dumps(
        resolve_recipe("ppo", "tracking", multi_agent=True, overrides=hp).hyperparams))  # SB3's shared recipe
    for k in ("compile_seconds", "compile_cpu_seconds", "train_seconds", "train_cpu_seconds", "curve_seconds"):
        assert math.isfinite(cfg[k]) and cfg[k] > 0, k
    curve = json.load(open(os.path.join(out, "curve.json")))
    assert curve["seeds"] == [20000, 20001, 20002] and [p["env_steps"] for p in curve["points"]] == [0, 256, 512]
    assert json.load(open(os.path.join(out, "train_curve.json")))["steps"] == [256, 512]

    agent = load_agent(out)
    assert isinstance(agent, JaxTrainedAgent) and agent.multi_agent and agent.name == "PPO (JAX, shared)"
    summ_path = str(tmp_path / "eval.json")
    assert main(["evaluate", "--model", out, "--episodes", "2", "--seed", "10000", "--json", summ_path]) == 0
    summ = json.load(open(summ_path))
    assert summ["policy"] == "PPO (JAX, shared)" and summ["seeds"] == [10000, 10001]
    env = parallel_factory("tracking", {})()  # the same harness by hand on the PettingZoo env: the same figures
    res = evaluate_policy(env, agent.policy_for(env), 2, 10000, parallel=True)
    env.close()
    assert {k: v for k, v in summ.items() if k not in ("policy", "model")} == json.loads(json.dumps(summarise(res)))
    # the last curve point is the exported policy on the curve episodes
    from agents.training.curves import paper_costs

    env = parallel_factory("tracking", {})()
    costs = [r.cost for r in evaluate_policy(env, agent.policy_for(env), 3, 20000, parallel=True)]
    env.close()
    np.testing.assert_allclose(curve["points"][-1]["cost_ratio"], np.array(costs) / paper_costs("tracking", {},
                                                                                                 curve["seeds"]),
                               rtol=1e-12)


@pytest.mark.parametrize("extra, names", [
    (["--hyperparams", '{"target_kl": 0.02}'], ["target_kl", "multi-agent"]),
    (["--hyperparams", '{"agent_id": 1}'], ["agent_id"]),
    (["--hybrid", "residual"], ["--hybrid"]),
])
def test_multi_agent_usage_errors_exit_2_before_out_is_touched(extra, names, tmp_path, capsys):
    from dobs_envs.cli import main

    out = tmp_path / "never"
    with pytest.raises(SystemExit) as exc:
        main(["train", "--trainer", "jax", "--multi-agent", "--timesteps", "64", "--no-progress", "--out", str(out),
              *extra])
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2 and err.count("\n") == 0 and "Traceback" not in err, err
    for n in names:
        assert n in err, err
    assert not out.exists()
