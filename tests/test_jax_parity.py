"""The JAX environments (dobs_envs.jax) against the compiled core: the same mathematics.

One-step parity along whole episodes: at every step of an episode of the compiled core the JAX form
advances the core's own state with the same input; every quantity is compared (next state,
observations, reward, errors, termination, truncation and reason codes). Action sources: random
inputs (a fifth outside the bounds: clipping), bang-bang inputs beyond the bounds, the paper's
controller, and a PPO policy trained briefly on the Gymnasium env. float64 throughout (``jax.enable_x64``).

Tolerances. The plant, reference model, exosystem, time and reward do not depend on the observers
within a step: both implementations evaluate the same float64 expressions in another order, so they
agree to round-off (1e-12 relative, observed 1e-15). The observers' right-hand side holds the
discontinuous term ``gamma_is P_u d / ||P_u d||`` of eq. (H_idefine): once ``||P_u d||`` is at
round-off level its direction is round-off, so the two simulations' observer states differ by up to
the chattering band of one period, ``2 T gamma_s`` (the unit vectors differ by at most 2, over the
period ``T``), propagated through the observer's own dynamics over ``T``; they are checked against
that bound. Without the discontinuous term (``gamma_s = phi_s = 0``, the paper's NE2 ablation) every
quantity must agree to 1e-9 (round-off accumulated over 50 Euler steps, as the compiled step's own
reference test). Free-running episodes with the paper's controller on the benchmark's evaluation
episodes then give the same returns within 1e-4 relative (observed up to 7e-6: the chattering
differences average out over the episode).
"""
from __future__ import annotations

import importlib

import numpy as np
import pytest

jax = pytest.importorskip("jax")
jnp = jax.numpy

from baselines.policies import SeparationPolicy  # noqa: E402
from dobs_envs.registry import ENVIRONMENTS  # noqa: E402

jaxenv = pytest.importorskip("dobs_envs.jax")
from dobs_envs.jax import parity  # noqa: E402
from dobs_envs.jax.env import _build  # noqa: E402

#: relative tolerance of the quantities the observers do not touch within a step (module doc)
ROUND_OFF = 1e-12
#: every quantity without the discontinuous term (module doc)
SMOOTH = 1e-9


@pytest.fixture(autouse=True)
def _x64():
    with jax.enable_x64(True):
        yield


_BUILT = {}


def _setup(name, **options):
    """``(structure, params, core)`` of ``name`` built once per option set (one compilation each)."""
    key = (name, repr(sorted(options.items())))
    if key not in _BUILT:
        structure, params, _ = _build(ENVIRONMENTS[name], dict(options, dtype="float64"))
        _BUILT[key] = (structure, params)
    structure, params = _BUILT[key]
    steps = int(params.max_steps_in_episode)
    core = ENVIRONMENTS[name].load_class().make_core(1, max_cycles=steps, **options)
    return structure, params, core


def _chattering_band(state, structure, params):
    """The bound of the module doc on ``|z_jax - z_compiled|`` after one period from ``state``."""
    T = float(params.dt) * structure.substeps
    gs = float(np.max(np.asarray(state.gamma_s))) + T * float(np.max(np.asarray(params.phi_s))) * 1e3
    E = max(np.linalg.norm(np.asarray(e), 2) for e in params.E_bar)
    g = float(np.max(np.asarray(state.gamma)))
    L = np.linalg.norm(np.asarray(params.laplacian), 2)
    return 2.0 * T * gs * np.exp(T * (E + g * L)) + 1e-9 * max(1.0, float(np.max(np.abs(np.asarray(state.z)))))


def _random(rng, frac_out=0.2):
    def inputs(core, k):
        b = core.action_bound
        u = rng.uniform(-b, b)
        out = rng.random(b.shape) < frac_out
        return np.where(out, 1.5 * b * np.sign(u), u)
    return inputs


def _bang_bang(rng):
    return lambda core, k: 1.2 * core.action_bound * rng.choice([-1.0, 1.0], size=core.action_bound.shape)


def _paper(name, options):
    mod = importlib.import_module(ENVIRONMENTS[name].module)
    holder = {}

    def inputs(core, k):
        if k == 0:
            pe = holder["pe"] = mod.parallel_env(**options)
            holder["pol"] = SeparationPolicy(pe)
        pe = holder["pe"]
        obs = {a: core.observations[0, i, :w] for i, (a, w) in enumerate(zip(pe.possible_agents, core.obs_widths))}
        return holder["pol"].inputs(obs)
    return inputs


def _trained(name, options):
    """A PPO policy trained briefly on the Gymnasium env (SB3, 512 steps): network-shaped actions."""
    sb3 = pytest.importorskip("stable_baselines3")
    import gymnasium as gym

    from stable_baselines3.common.logger import Logger

    from dobs_envs.envs.adapter import CoreAdapter

    genv = gym.make(ENVIRONMENTS[name].gym_id, **options)
    model = sb3.PPO("MlpPolicy", genv, n_steps=256, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.set_logger(Logger(folder=None, output_formats=[]))  # SB3's default logger leaves an empty temp directory
    model.learn(512)

    def inputs(core, k):
        obs = CoreAdapter(core).central_observations(0)
        action, _ = model.predict(obs, deterministic=True)
        return CoreAdapter(core).central_inputs(np.asarray(action, dtype=np.float64))
    return inputs


CASES = [
    ("tracking", {}, "random"),
    ("tracking", {}, "bang_bang"),
    ("tracking", {}, "paper"),
    ("tracking", {}, "trained"),
    ("tracking", {"observation": "full", "reward": "log", "normalized_actions": True, "padded_observations": True},
     "random"),
    ("disturbance_rejection", {}, "random"),
    ("disturbance_rejection", {}, "paper"),
    ("disturbance_rejection", {"disturbance": "random", "reward": "sqrt"}, "random"),
    ("hetero_mas", {}, "random"),
    ("hetero_mas", {}, "paper"),
    ("hetero_mas", {}, "trained"),
    ("hetero_mas", {"state_bound": 30.0}, "bang_bang"),
    ("random_network", {}, "paper"),
    ("random_network", {"padded_observations": True, "termination_penalty": False, "observation": "full"}, "bang_bang"),
]


@pytest.mark.parametrize("name,options,source", CASES, ids=[f"{n}-{'+'.join(o) or 'default'}-{s}" for n, o, s in CASES])
def test_one_step_parity_along_an_episode(name, options, source):
    structure, params, core = _setup(name, **options)
    if "state_bound" in options:  # params differ from the cached structure's only in the bound: no recompilation
        params = params.replace(state_bound=jnp.asarray(options["state_bound"], params.state_bound.dtype))
    rng = np.random.default_rng(7)
    inputs = {"random": lambda: _random(rng), "bang_bang": lambda: _bang_bang(rng),
              "paper": lambda: _paper(name, options), "trained": lambda: _trained(name, options)}[source]()
    w = parity.one_step_episode(core, structure, params, inputs, seed=10_000, steps=200,
                                max_z_diff=_chattering_band)
    assert w["ends"] == 0, f"termination/truncation/reason differ ({w})"
    for q in ("t", "x", "x_r", "v", "reward", "tracking_error", "task_error"):
        assert w[q] <= ROUND_OFF, f"{q}: {w[q]:.3g} > {ROUND_OFF} ({w})"
    assert w["z_band"] <= 1.0, f"observer states beyond the chattering band ({w})"
    if source == "bang_bang" and name == "hetero_mas":
        assert w["steps"] < 200, "the state bound was expected to end this episode (the test's premise)"


def _smooth(name):
    from dobs_envs.scenarios.paper import ne2, ne3

    return {"tracking": ne2, "disturbance_rejection": ne3}[name]().replace(gamma_s0=0.0, phi_s=0.0)


@pytest.mark.parametrize("name", ["tracking", "disturbance_rejection"])
def test_without_the_discontinuous_term_every_quantity_agrees(name):
    structure, params, core = _setup(name, scenario=_smooth(name))
    w = parity.one_step_episode(core, structure, params, _random(np.random.default_rng(3)), seed=10_001, steps=150)
    assert w["ends"] == 0
    for q in parity.QUANTITIES:
        tol = 1e-6 if q == "obs" else SMOOTH  # observations are float32 (one rounding of equal float64 values)
        assert w[q] <= tol, f"{q}: {w[q]:.3g} > {tol} ({w})"


@pytest.mark.parametrize("name", ["tracking", "disturbance_rejection", "hetero_mas", "random_network"])
def test_paper_controller_returns_on_evaluation_episodes(name):
    structure, params, _ = _setup(name)
    mod = importlib.import_module(ENVIRONMENTS[name].module)
    penv = mod.parallel_env(max_cycles=int(params.max_steps_in_episode))
    for seed in (10_000, 10_001, 10_002):
        ra, rb, steps = parity.free_run_episode(penv, structure, params, SeparationPolicy, seed=seed)
        assert steps == int(params.max_steps_in_episode)
        assert abs(rb - ra) <= 1e-4 * abs(ra), f"seed {seed}: return {rb} vs compiled {ra}"


@pytest.mark.parametrize("name", ["tracking", "disturbance_rejection", "hetero_mas", "random_network"])
def test_from_states_away_from_consensus_every_quantity_agrees(name):
    """From random states whose observers disagree (||P_u d|| of order 1 at every node, so that the direction
    of the discontinuous term is well defined throughout the period), with random gains and inputs, one step
    of the JAX form equals the compiled step to 1e-9: the discontinuous term included."""
    from dobs_envs.sim import SimState

    structure, params, core = _setup(name)
    adv = parity.advance_fn(structure)
    rng = np.random.default_rng(11)
    core.reset(None, [10_003])
    n, N, m_v = core.n_states, core.n_nodes, core.n_unknown
    for trial in range(20):
        s = core.sim_state
        x = rng.normal(0.0, 2.0, n)
        new = SimState(t=np.array([rng.uniform(0, 10)]), x=x[None], z=rng.normal(0.0, 3.0, (1, N, n)),
                       gamma=rng.uniform(0.05, 2.0, (1, N)), gamma_s=rng.uniform(0.05, 2.0, (1, N)),
                       v=s.v + rng.normal(0.0, 0.5, (1, m_v)), x_r=x[None] + rng.normal(0.0, 0.5, (1, n)))
        core.set_sim_state(new)
        u = rng.uniform(-1.0, 1.0, core.n_inputs) * core.action_bound
        js = parity.state_from_core(core, 0, jnp.float64)
        ns, out = adv(js, jnp.asarray(u), params)
        res = core.advance(u[None])
        after = core.sim_state
        for q in ("x", "z", "gamma", "gamma_s", "v", "x_r"):
            a, b = np.asarray(getattr(ns, q)), getattr(after, q)[0]
            np.testing.assert_allclose(a, b, rtol=SMOOTH, atol=SMOOTH * max(1.0, np.abs(b).max(initial=0.0)),
                                       err_msg=f"{q}, trial {trial}")
        np.testing.assert_allclose(float(out.reward), res.reward[0], rtol=ROUND_OFF)
        assert bool(out.terminated) == bool(res.terminated[0]) and int(out.reason) == int(res.reason[0])
        core.reset(None, [10_003])
