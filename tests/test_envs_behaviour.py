"""Behaviour of the environments: determinism, action validation/clipping, reset options,
observation layout, disturbances, design errors through the constructor, rendering."""
import math

import gymnasium as gym
import numpy as np
import pytest

import dobs_envs  # noqa: F401
from dobs_envs import disturbance_rejection_v0, hetero_mas_v0, random_network_v0, tracking_v0
from dobs_envs.assumptions import AssumptionError, CollectiveDetectabilityError, GraphNotConnectedError
from dobs_envs.envs import make_gym_env, make_parallel_env
from dobs_envs.graphs import Graph
from dobs_envs.scenarios.paper import ne2, ne3
from dobs_envs.sim import estimates, outputs

FACTORIES = {
    "tracking": lambda **k: tracking_v0.parallel_env(**k),
    "disturbance_exo": lambda **k: disturbance_rejection_v0.parallel_env(**k),
    "disturbance_random": lambda **k: disturbance_rejection_v0.parallel_env(disturbance="random", **k),
    "hetero_mas": lambda **k: hetero_mas_v0.parallel_env(**k),
    "random_plant": lambda **k: random_network_v0.parallel_env(**k),
    "random_mas": lambda **k: random_network_v0.parallel_env(kind="mas", n_agents=3, system_seed=2, **k),
}


def _episode(env, seed):
    obs, infos = env.reset(seed=seed)
    traj = [(obs, infos)]
    while env.agents:
        acts = {a: env.action_space(a).sample() for a in env.agents}  # spaces are seeded by reset(seed)
        traj.append(env.step(acts))
    return traj


def _same(t1, t2):
    if isinstance(t1, dict):
        return t1.keys() == t2.keys() and all(_same(t1[k], t2[k]) for k in t1)
    if isinstance(t1, (tuple, list)):
        return len(t1) == len(t2) and all(_same(a, b) for a, b in zip(t1, t2))
    if isinstance(t1, np.ndarray):
        return t1.dtype == t2.dtype and np.array_equal(t1, t2)
    return t1 == t2


@pytest.mark.parametrize("name", list(FACTORIES))
def test_whole_episode_determinism(name):
    env1, env2 = FACTORIES[name](max_cycles=25), FACTORIES[name](max_cycles=25)
    a, b = _episode(env1, 7), _episode(env2, 7)
    assert len(a) == 26 and _same(a, b)
    # the same env object re-seeded reproduces its own episode too
    assert _same(_episode(env1, 7), a)
    c = _episode(env1, 8)
    assert not np.array_equal(c[0][0]["controller_0"], a[0][0]["controller_0"])
    assert not _same(c[-1][1], a[-1][1])  # rewards differ


def test_gym_determinism_whole_episode():
    def run(seed):
        env = gym.make("dobs_envs/DisturbanceRejection-v0", disturbance="random", max_episode_steps=20)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        done = False
        while not done:
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            out += [obs, r, info["tracking_error"]]
            done = term or trunc
        return out

    a, b, c = run(3), run(3), run(4)
    assert len(a) == 61 and _same(a, b)
    assert not np.array_equal(a[-3], c[-3])


def _zero(env):
    return {a: np.zeros(env.action_space(a).shape, np.float32) for a in env.agents}


def test_bad_actions_raise_naming_the_agent():
    env = tracking_v0.parallel_env()
    env.reset(seed=0)
    acts = _zero(env)
    for bad, match in [(np.array([np.nan], np.float32), "controller_3"), (np.array([np.inf]), "controller_3"),
                       (np.zeros(2), "controller_3"), (np.zeros((1, 1)), "controller_3"), ("a", "controller_3")]:
        with pytest.raises(ValueError, match=match):
            env.step({**acts, "controller_3": bad})
    with pytest.raises(ValueError, match="controller_9"):
        env.step({**acts, "controller_9": np.zeros(1)})
    missing = dict(acts)
    del missing["controller_2"]
    with pytest.raises(ValueError, match="controller_2"):
        env.step(missing)
    # nothing was simulated by the rejected calls
    assert env.sim_state.t[0] == 0.0
    env.step(acts)
    assert env.sim_state.t[0] == pytest.approx(env.control_period)
    genv = gym.make("dobs_envs/Tracking-v0")
    genv.reset(seed=0)
    a = np.zeros(5, np.float32)
    a[4] = np.nan
    with pytest.raises(ValueError, match="controller_4"):
        genv.step(a)
    with pytest.raises(ValueError, match="shape"):
        genv.step(np.zeros(4))


def test_out_of_range_actions_are_clipped():
    env1, env2 = tracking_v0.parallel_env(), tracking_v0.parallel_env()
    env1.reset(seed=5)
    env2.reset(seed=5)
    hi = {a: env1.action_space(a).high for a in env1.agents}
    big = {a: hi[a] * 1e3 + 7.0 for a in env1.agents}
    big["controller_1"] = -big["controller_1"]
    exact = {a: (-hi[a] if a == "controller_1" else hi[a]).astype(np.float64) for a in env1.agents}
    for _ in range(3):
        o1, r1, *_ = env1.step(big)
        o2, r2, *_ = env2.step(exact)
        assert _same(o1, o2) and r1 == r2
    # the clipped input is what the reward charges: R = I, so -reward/T >= sum b_k^2
    b2 = sum(float(h @ h) for h in env1.action_bound.reshape(-1, 1))
    assert -r1["controller_0"] / env1.control_period >= b2


def test_reset_options_exact_initial_state_and_outputs():
    sc = ne2()
    env = tracking_v0.parallel_env(observation="full", obs_dtype="float64")
    x0 = np.linspace(-1, 1, 9)
    obs, infos = env.reset(seed=0, options={"x0": x0})
    st, p = env.sim_state, env.params
    assert np.array_equal(st.x[0], x0) and np.all(st.z == 0) and np.all(st.gamma == sc.gamma0)
    xhat = estimates(st, p)[0]
    y = outputs(st, p)[0]
    for k, a in enumerate(env.possible_agents):
        lay, o, i = env.observation_layout(a), obs[a], sc.links[k]
        assert list(lay) == ["y", "xhat", "neighbors", "mask", "r", "x", "x_r", "estimates", "gamma", "gamma_s", "time"]
        assert np.allclose(o[lay["y"]], y[i, :sc.C[i].shape[0]], rtol=0, atol=1e-15)
        assert np.allclose(o[lay["xhat"]], xhat[i], rtol=0, atol=1e-14)
        nb = sc.graph.neighbors(i)
        D = env.layout.max_neighbors
        got = o[lay["neighbors"]].reshape(D, 9)
        assert np.allclose(got[:len(nb)], xhat[nb], atol=1e-14) and np.all(got[len(nb):] == 0)
        assert np.array_equal(o[lay["mask"]], (np.arange(D) < len(nb)).astype(float))
        assert np.allclose(o[lay["r"]], sc.reference(0.0)[sc.channel_slices[k]])
        assert np.array_equal(o[lay["x"]], x0) and o[lay["time"]][0] == 0.0
        assert infos[a]["estimation_error"] == pytest.approx(np.linalg.norm(xhat[i] - x0))
        assert infos[a]["tracking_error"] == pytest.approx(np.linalg.norm(x0))
    s = env.state()
    sl = env.state_layout()
    assert np.array_equal(s[sl["x"]], x0) and np.allclose(s[sl["estimates"]], xhat.ravel(), atol=1e-14)
    with pytest.raises(ValueError, match="x0"):
        env.reset(options={"x0": np.zeros(3)})


def test_default_initial_distribution_is_x0_plus_uniform_noise():
    sc = ne2()
    env = tracking_v0.parallel_env()
    xs = []
    for s in range(30):
        env.reset(seed=s)
        xs.append(env.sim_state.x[0] - sc.x0)
    xs = np.array(xs)
    assert np.all(np.abs(xs) <= 1.0) and xs.std() > 0.3
    env0 = tracking_v0.parallel_env(init_noise=0.0)
    env0.reset(seed=3)
    assert np.array_equal(env0.sim_state.x[0], sc.x0)


def test_custom_observation_components_and_errors():
    env = tracking_v0.parallel_env(observation=("xhat", "r", "x_r"))
    obs, _ = env.reset(seed=0)
    assert obs["controller_0"].shape == (19,)
    assert env.observation_layout("controller_0") == {"xhat": slice(0, 9), "r": slice(9, 10), "x_r": slice(10, 19)}
    with pytest.raises(ValueError, match="component"):
        tracking_v0.parallel_env(observation=("xhat", "velocity"))
    with pytest.raises(ValueError, match="reference"):
        disturbance_rejection_v0.parallel_env(observation=("xhat", "r"))
    with pytest.raises(ValueError, match="unknown agent"):
        env.observation_layout("observer_0")


def test_disturbance_modes():
    env = disturbance_rejection_v0.parallel_env(disturbance="random", disturbance_amplitude=1.5, max_cycles=60,
                                                observation="full", obs_dtype="float64")
    obs, _ = env.reset(seed=0)
    vs = []
    while env.agents:
        vs.append(env.sim_state.v[0].copy())
        obs, *_ = env.step(_zero(env))
    vs = np.array(vs)
    assert np.all(np.abs(vs) <= 1.5 + 1e-12) and np.ptp(vs, axis=0).min() > 0.05
    env = disturbance_rejection_v0.parallel_env(disturbance="none", max_cycles=3)
    env.reset(seed=0)
    env.step(_zero(env))
    assert np.all(env.sim_state.v == 0)
    env = disturbance_rejection_v0.parallel_env()
    env.reset(seed=0, options={"v0": [-2.0, 2.0]})
    assert np.array_equal(env.sim_state.v[0], [-2.0, 2.0])
    env.reset(seed=1)
    assert np.linalg.norm(env.sim_state.v[0]) == pytest.approx(np.sqrt(8))  # random phase, paper's amplitude
    with pytest.raises(ValueError, match="disturbance"):
        tracking_v0.parallel_env(disturbance="random")


def test_termination_on_state_bound():
    env = tracking_v0.parallel_env(state_bound=15.0)
    env.reset(seed=0)
    hi = {a: env.action_space(a).high for a in env.agents}
    for _ in range(400):
        _, _, term, trunc, info = env.step(hi)
        if term["controller_0"]:
            break
    assert term["controller_0"] and not trunc["controller_0"] and env.agents == []
    assert info["controller_0"]["termination_reason"] == 1  # REASONS[1] == "state_bound_exceeded"
    assert np.linalg.norm(env.sim_state.x[0]) > 15.0
    with pytest.raises(RuntimeError, match="reset"):
        env.step(hi)


@pytest.mark.parametrize("penalty", [True, False])
def test_termination_penalty_charges_the_rest_of_the_horizon(penalty):
    """With a cost-type reward, diverging early must not pay: the terminating step is
    charged lambda_max(Q) * bound^2 * period for every remaining step of the horizon."""
    bound = 15.0
    env = tracking_v0.parallel_env(state_bound=bound, termination_penalty=penalty)
    env.reset(seed=0)
    hi = {a: env.action_space(a).high for a in env.agents}
    steps, rewards = 0, []
    while env.agents:
        _, rew, term, _, _ = env.step(hi)
        steps += 1
        rewards.append(rew["controller_0"])
    assert term["controller_0"] and steps < 400
    x, x_r = env.sim_state.x[0], env.sim_state.x_r[0]
    u = np.concatenate([hi[a] for a in env.possible_agents]).astype(float)
    step_cost = ((x - x_r) @ (x - x_r) + u @ u) * env.control_period  # Q = I, R = I
    expected_penalty = bound**2 * env.control_period * (400 - steps) if penalty else 0.0
    assert rewards[-1] == pytest.approx(-step_cost - expected_penalty, rel=1e-9)
    if penalty:
        # the diverging episode is worse than sitting exactly on the bound for the whole horizon
        assert sum(rewards) < -bound**2 * env.control_period * (400 - steps)


def test_log_reward_is_the_log_of_the_quadratic_stage_cost():
    """reward='log': -log(1 + c / c0) * period with c0 = lambda_max(Q) cost_scale^2, on the same trajectory."""
    quad = tracking_v0.parallel_env(max_cycles=60)
    log = tracking_v0.parallel_env(max_cycles=60, reward="log", cost_scale=0.2)
    quad.reset(seed=4)
    log.reset(seed=4)
    T = quad.control_period
    while quad.agents:
        act = {a: quad.action_space(a).sample() * 0.1 for a in quad.agents}
        _, rq, *_ = quad.step(act)
        _, rl, *_ = log.step(act)
        c = -rq["controller_0"] / T
        assert rl["controller_0"] == pytest.approx(-math.log1p(c / 0.2**2) * T, rel=1e-12)


def test_sqrt_reward_is_the_root_of_the_quadratic_stage_cost():
    quad = tracking_v0.parallel_env(max_cycles=30)
    sq = tracking_v0.parallel_env(max_cycles=30, reward="sqrt")
    quad.reset(seed=2)
    sq.reset(seed=2)
    T = quad.control_period
    while quad.agents:
        act = {a: quad.action_space(a).sample() * 0.1 for a in quad.agents}
        _, rq, *_ = quad.step(act)
        _, rs, *_ = sq.step(act)
        assert rs["controller_0"] == pytest.approx(-math.sqrt(-rq["controller_0"] / T) * T, rel=1e-12)


def test_log_reward_termination_penalty_uses_the_same_shape():
    bound = 15.0
    env = tracking_v0.parallel_env(state_bound=bound, reward="log", cost_scale=0.1)
    env.reset(seed=0)
    hi = {a: env.action_space(a).high for a in env.agents}
    steps, rewards = 0, []
    while env.agents:
        _, rew, *_ = env.step(hi)
        steps += 1
        rewards.append(rew["controller_0"])
    x, x_r = env.sim_state.x[0], env.sim_state.x_r[0]
    u = np.concatenate([hi[a] for a in env.possible_agents]).astype(float)
    c = (x - x_r) @ (x - x_r) + u @ u
    per_step = math.log1p(bound**2 / 0.1**2) * env.control_period
    assert rewards[-1] == pytest.approx(-math.log1p(c / 0.01) * env.control_period - per_step * (400 - steps), rel=1e-9)


@pytest.mark.parametrize("kw,match", [({"reward": "exp"}, "reward must be one of"),
                                      ({"cost_scale": 0.0}, "cost_scale"), ({"cost_scale": float("nan")}, "cost_scale"),
                                      ({"cost_scale": True}, "cost_scale")])
def test_reward_options_are_validated(kw, match):
    with pytest.raises(ValueError, match=match):
        tracking_v0.parallel_env(**kw)


def test_timing_options():
    env = tracking_v0.parallel_env(dt=2e-3, substeps=10, horizon=1.0)
    assert env.control_period == pytest.approx(0.02) and env.max_cycles == 50
    assert tracking_v0.parallel_env().max_cycles == 400 and hetero_mas_v0.parallel_env().max_cycles == 600
    with pytest.raises(ValueError):
        tracking_v0.parallel_env(max_cycles=10, horizon=1.0)
    with pytest.raises(ValueError):
        tracking_v0.parallel_env(substeps=0)
    assert tracking_v0.parallel_env(horizon=math.inf).max_cycles is None


def test_assumption_errors_surface_from_constructors():
    sc = ne2()
    adj = np.zeros((6, 6))
    for i, j in [(0, 1), (1, 2), (3, 4), (4, 5)]:
        adj[i, j] = adj[j, i] = 1
    with pytest.raises(GraphNotConnectedError, match="Assumption 5"):
        make_parallel_env(sc.replace(graph=Graph(adj)))
    e1 = np.zeros((1, 9))
    e1[0, 0] = 1
    with pytest.raises(CollectiveDetectabilityError, match="Assumption 6"):
        tracking_v0.parallel_env(scenario=sc.replace(C=[e1] * 6))
    with pytest.raises(AssumptionError):
        make_gym_env(sc.replace(graph=Graph(adj)))
    with pytest.raises(ValueError, match="reference"):
        tracking_v0.parallel_env(scenario=ne3())


def test_user_scenario_from_python_and_yaml(tmp_path):
    from dobs_envs.scenarios.io import example_path, save_scenario

    ref = tracking_v0.parallel_env()
    o_ref, _ = ref.reset(seed=11)
    env = make_parallel_env(example_path("ne2"))  # the YAML copy of NE2
    o, _ = env.reset(seed=11)
    assert _same(o, o_ref)
    path = save_scenario(ne3(), str(tmp_path / "mine.yaml"))
    env = disturbance_rejection_v0.parallel_env(scenario=path, max_cycles=3)
    env.reset(seed=0)
    assert np.all(env.action_bound >= 1.0)  # calibrated ('auto') bounds for a user scenario
    g = make_gym_env(ne2(), max_cycles=4)
    g.reset(seed=0)
    for k in range(4):
        *_, term, trunc, _ = g.step(np.zeros(5))
    assert trunc and not term


def test_render_rgb_array():
    env = tracking_v0.parallel_env(render_mode="rgb_array", max_cycles=5)
    env.reset(seed=0)
    while env.agents:
        env.step(_zero(env))
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 and img.shape[0] > 100
    assert img.std() > 5  # not a blank canvas
    genv = gym.make("dobs_envs/HeteroMAS-v0", render_mode="rgb_array")
    genv.reset(seed=0)
    genv.step(genv.action_space.sample())
    assert genv.render().shape[2] == 3
    assert tracking_v0.parallel_env().render_mode is None
    with pytest.raises(ValueError, match="render_mode"):
        tracking_v0.parallel_env(render_mode="ansi")


def _headless_human(make, step):
    """``render_mode="human"`` under a non-interactive backend: one warning, render() None, no error."""
    import matplotlib

    matplotlib.use("Agg")  # what CI and headless machines run (MPLBACKEND=Agg / no display)
    import warnings

    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        env = make()
        env.reset(seed=0)
        for _ in range(3):
            step(env)
        assert env.render() is None
        env.close()
    msgs = [str(x.message) for x in w if "render_mode='human'" in str(x.message)]
    assert len(msgs) == 1 and "rgb_array" in msgs[0], msgs


def test_render_human_headless_warns_once():
    _headless_human(lambda: tracking_v0.parallel_env(render_mode="human"), lambda e: e.step(_zero(e)))
    _headless_human(lambda: gym.make("dobs_envs/Tracking-v0", render_mode="human"),
                    lambda e: e.step(np.zeros(5, np.float32)))
    _headless_human(lambda: gym.make_vec("dobs_envs/Tracking-v0", num_envs=2, render_mode="human"),
                    lambda e: e.step(np.zeros((2, 5), np.float32)))


def test_render_human_backend_detection():
    from dobs_envs.envs.rendering import is_interactive_backend

    assert not is_interactive_backend("agg") and not is_interactive_backend("pdf")
    assert is_interactive_backend("TkAgg") and is_interactive_backend("QtAgg")
    assert not is_interactive_backend("module://matplotlib_inline.backend_inline")
