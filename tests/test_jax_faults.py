"""Communication faults in the JAX environments (dobs_envs.jax.faults) against the compiled core.

The fault processes are the compiled core's counter-based draws (dobs_envs.sim.fault_rng) evaluated on
jax.numpy arrays: the uniforms behind every loss, burst transition and graph switch are compared bit for
bit; the normals of the measurement noise go through two polynomial series that XLA compiles with other
roundings (eager evaluation is bit-identical), so they are compared to a few ulps (4 eps relative).
Then the parity of whole episodes, as tests/test_jax_parity.py does for the ideal network (the same
tolerances, argued there): at every step the JAX form advances the compiled core's state, fault state
included, with the same input; the plant, reward and errors agree to round-off, the observers to the
chattering band, and every draw and received flag exactly. Settings: tracking_lossy's defaults, every
other fault key on tracking (continuous exchange with delays, bursts, switching graphs, measurement
noise), and faults on the other environments.
"""
from __future__ import annotations

import importlib

import numpy as np
import pytest

jax = pytest.importorskip("jax")
jnp = jax.numpy

from baselines.policies import SeparationPolicy  # noqa: E402
from dobs_envs.registry import ENVIRONMENTS  # noqa: E402
from dobs_envs.sim import fault_rng  # noqa: E402

jaxenv = pytest.importorskip("dobs_envs.jax")
from dobs_envs.jax import faults as jfaults  # noqa: E402
from dobs_envs.jax import parity  # noqa: E402

from test_jax_parity import ROUND_OFF, _bang_bang, _chattering_band, _paper, _random, _setup  # noqa: E402


@pytest.fixture(autouse=True)
def _x64():
    with jax.enable_x64(True):
        yield


def test_draws_are_the_compiled_generators():
    rng = np.random.default_rng(0)
    B = 4000
    seed = rng.integers(0, 2**64, size=B, dtype=np.uint64)
    period = rng.integers(0, 10**6, size=B).astype(np.uint64)
    index = rng.integers(0, 200, size=B).astype(np.uint64)
    r = jfaults._draws()
    for stream in fault_rng.STREAMS.values():
        @jax.jit
        def draw(s, p, i):
            key = r.period_key(s, jnp.uint64(stream), p)
            return r.uniform_at(key, i), r.normal_at(key, i)

        u, z = (np.asarray(a) for a in draw(jnp.asarray(seed), jnp.asarray(period), jnp.asarray(index)))
        np.testing.assert_array_equal(u, fault_rng.uniform(seed, stream, period, index))
        ref = fault_rng.normal(seed, stream, period, index)
        np.testing.assert_allclose(z, ref, rtol=4 * np.finfo(float).eps, atol=4 * np.finfo(float).eps)


def test_faults_need_64_bit_jax():
    with jax.enable_x64(False):
        with pytest.raises(ValueError, match="jax_enable_x64"):
            jaxenv.make("dobs_envs/TrackingLossy-v0", dtype="float32")


def _ring_and_path(N):
    ring = np.zeros((N, N))
    for i in range(N):
        ring[i, (i + 1) % N] = ring[(i + 1) % N, i] = 1.0
    path = ring.copy()
    path[0, N - 1] = path[N - 1, 0] = 0.0
    return [ring, path]


CONTINUOUS_DELAYED = {"oo_period": None, "oo_loss": 0.2, "oo_delay": 1, "co_loss": 0.1, "co_delay": 2}
BURSTS_NOISE = {"oo_period": 0.01, "oo_burst": {"p_good_bad": 0.1, "p_bad_good": 0.3, "loss_good": 0.05},
                "oo_delay": 2, "measurement_noise": 0.02}
SWITCHING = {"oo_period": 0.02, "switching": {"graphs": _ring_and_path(6), "rate": 4.0}, "oo_loss": 0.1,
             "co_loss": 0.2}

CASES = [
    ("tracking_lossy", {}, "random"),
    ("tracking_lossy", {}, "paper"),
    ("tracking", {"faults": CONTINUOUS_DELAYED}, "paper"),
    ("tracking", {"faults": BURSTS_NOISE}, "bang_bang"),
    ("tracking", {"faults": SWITCHING, "observation": "full"}, "random"),
    ("disturbance_rejection", {"faults": {"oo_loss": 0.3, "co_delay": 1, "measurement_noise": 0.05}}, "random"),
    ("hetero_mas", {"faults": {"oo_period": 0.02, "oo_loss": 0.2, "measurement_noise": 0.01}}, "paper"),
]


@pytest.mark.parametrize("name,options,source", CASES,
                         ids=[f"{n}-{'+'.join(o) or 'default'}-{s}-{i}" for i, (n, o, s) in enumerate(CASES)])
def test_one_step_parity_with_faults(name, options, source):
    structure, params, core = _setup(name, **options)
    rng = np.random.default_rng(7)
    inputs = {"random": lambda: _random(rng), "bang_bang": lambda: _bang_bang(rng),
              "paper": lambda: _paper(name, options)}[source]()
    w = parity.one_step_episode(core, structure, params, inputs, seed=10_000, steps=120,
                                max_z_diff=_chattering_band)
    assert w["ends"] == 0, f"termination/truncation/reason differ ({w})"
    assert w["draws"] == 0, f"fault draws or received flags differ ({w})"
    for q in ("t", "x", "x_r", "v", "reward", "tracking_error", "task_error"):
        assert w[q] <= ROUND_OFF, f"{q}: {w[q]:.3g} > {ROUND_OFF} ({w})"
    assert w["z_band"] <= 1.0, f"observer states beyond the chattering band ({w})"
    # the held copies, snapshots and C-O buffers are estimates taken inside the period: within the same band
    assert w["fault_band"] <= 1.0, f"fault state beyond the chattering band ({w})"


def test_reset_matches_the_compiled_reset():
    """From the compiled core's reset draws (x0 and the fault seed), the JAX reset state builds the same fault
    state (period-0 draws, held copies, C-O buffers) and the same first observation."""
    structure, params, core = _setup("tracking", faults=BURSTS_NOISE)
    for seed in (1, 2, 3):
        core.reset(None, [seed])
        s, fs = core.sim_state, core.fault_state
        js = jaxenv.core.initial_state(params, structure, s.x[0], v0=s.v[0], x_r0=s.x_r[0], fault_seed=fs.seed[0])
        for q in ("seed", "period", "bad", "graph"):
            np.testing.assert_array_equal(np.asarray(getattr(js.fault, q)), getattr(fs, q)[0], err_msg=q)
        for q in ("received", "snapshots", "noise", "co_sent", "co_held"):
            np.testing.assert_allclose(np.asarray(getattr(js.fault, q)), getattr(fs, q)[0], rtol=1e-14, atol=1e-15,
                                       err_msg=q)
        obs = jaxenv.core.observations(jaxenv.core.features(js, params, structure), structure)
        np.testing.assert_allclose(np.asarray(obs), core.observations[0], rtol=1e-6, atol=1e-7)


def test_paper_controller_returns_with_faults():
    """Free-running episodes (the benchmark's evaluation seeds): the same returns as the compiled env."""
    structure, params, _ = _setup("tracking_lossy")
    penv = importlib.import_module(ENVIRONMENTS["tracking_lossy"].module).parallel_env(
        max_cycles=int(params.max_steps_in_episode))
    for seed in (10_000, 10_001):
        ra, rb, steps = parity.free_run_episode(penv, structure, params, SeparationPolicy, seed=seed)
        assert steps == int(params.max_steps_in_episode)
        assert abs(rb - ra) <= 1e-4 * abs(ra), f"seed {seed}: return {rb} vs compiled {ra}"


def test_fault_parameters_vmap_and_infos():
    """The loss rate is a parameter: one vmapped step over oo_loss = 0 and 1 gives every O-O value received
    (tracking_lossy exchanges at every boundary) and none; the infos carry the compiled env's fault keys."""
    env, params = jaxenv.make("dobs_envs/TrackingLossy-v0")
    stacked = jax.tree.map(lambda *a: jnp.stack(a), params, params, params)  # loss rates 0, 1 and the defaults
    f = params.faults
    stacked = stacked.replace(faults=stacked.faults.replace(oo_loss=jnp.array([0.0, 1.0, f.oo_loss]),
                                                            co_loss=jnp.array([0.0, 1.0, f.co_loss])))
    keys = jax.random.split(jax.random.key(0), 3)
    obs, state = jax.jit(jax.vmap(env.reset_env))(keys, stacked)
    act = jnp.zeros((3, env.num_actions))
    obs, new, reward, term, trunc, info = jax.jit(jax.vmap(env.step_env))(keys, state, act, stacked)
    frac, co = np.asarray(info["oo_received_fraction"]), np.asarray(info["co_received"])
    assert frac.shape == co.shape == (3, len(env.structure.agents))
    assert np.all(frac[0] == 1.0) and np.all(frac[1] == 0.0)
    assert np.all(co[0]) and not np.any(co[1])
    assert obs.shape == (3,) + env.observation_space(params).shape
    assert np.all(np.isfinite(np.asarray(obs)))
    marl = jaxenv.make_marl("tracking_lossy")  # the multi-agent view: the same keys, one entry per agent
    one = jax.tree.map(lambda a: a[2], state)
    actions = {a: jnp.zeros(w) for a, w in zip(marl.agents, marl.structure.action_widths)}
    _, _, _, _, infos = jax.jit(marl.step_env)(keys[2], one, actions)
    np.testing.assert_array_equal(np.asarray(infos["oo_received_fraction"]), frac[2])
    np.testing.assert_array_equal(np.asarray(infos["co_received"]), co[2])
