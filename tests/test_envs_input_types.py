"""Inputs of the wrong kind are refused with the argument's name instead of being cast:
cost weights that are not positive (semi)definite, complex numbers, boolean actions
(issue 12, item 4), on every adapter of the batched core."""
from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import dobs_envs  # noqa: F401  (registers the Gymnasium ids)
from dobs_envs import tracking_v0
from dobs_envs.envs import TrackingEnv
from dobs_envs.graphs import Graph
from dobs_envs.scenarios.mas_tasks import ne1_agents, rendezvous_scenario
from dobs_envs.scenarios.signals import Sinusoids

N_STATES, N_INPUTS = 9, 5  # Tracking's default scenario (NE2)


@pytest.fixture(autouse=True)
def _complex_warning_is_an_error():
    """A silent complex -> real cast warns (ComplexWarning); the inputs below must be refused before."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        yield


# ------------------------------------------------------------------ cost weights
@pytest.mark.parametrize("kw,match", [
    ({"Q": -np.eye(N_STATES)}, "Q must be symmetric positive semidefinite"),
    ({"Q": np.diag([1.0] * 8 + [-1e-3])}, "Q must be symmetric positive semidefinite"),
    ({"Q": np.triu(np.ones((N_STATES, N_STATES)))}, "Q must be symmetric"),
    ({"R": -np.eye(N_INPUTS)}, "R must be symmetric positive definite"),
    ({"R": np.zeros((N_INPUTS, N_INPUTS))}, "R must be symmetric positive definite"),
    ({"R": np.diag([1.0, 1.0, 1.0, 1.0, 0.0])}, "R must be symmetric positive definite"),
    ({"Q": np.eye(N_STATES) * (1 + 0j)}, "Q must be real"),
    ({"R": np.eye(N_INPUTS) * 1j}, "R must be real"),
])
def test_cost_weights_are_checked_like_the_scenario(kw, match):
    """``Q = -I`` would reward divergence: the env options go through the Scenario's validator."""
    with pytest.raises(ValueError, match=match):
        TrackingEnv(**kw)
    with pytest.raises(ValueError, match=match):
        gym.make("dobs_envs/Tracking-v0", **kw)


def test_valid_cost_weights_are_accepted_and_symmetrised():
    Q = np.diag(np.arange(N_STATES, dtype=float))  # semidefinite (one zero eigenvalue) is fine for Q
    Q[0, 1] = 1e-14  # round-off asymmetry
    env = TrackingEnv(Q=Q, R=2.0 * np.eye(N_INPUTS))
    np.testing.assert_array_equal(env.Q, env.Q.T)
    assert env.Q[0, 0] == 0.0 and env.R[0, 0] == 2.0


# ------------------------------------------------------------------ complex numbers
@pytest.mark.parametrize("make,match", [
    (lambda: TrackingEnv(action_bound=np.full(N_INPUTS, 1 + 1j)), "action_bound"),
    (lambda: TrackingEnv(action_bound=np.complex128(2.0)), "action_bound"),
    (lambda: Graph(np.array([[0, 1 + 1j], [1 - 1j, 0]])), "adjacency must be real"),
    (lambda: Graph.from_edges(3, [(0, 1), (1, 2)], weights=[1.0, 1j]), "weights must be real"),
    (lambda: Sinusoids(amplitude=[1.0, 1j], frequency=1.0, phase=0.0), "amplitude must be real"),
    (lambda: rendezvous_scenario(agents=[(np.array([[1j]]), [[1.0]], [[1.0]])] + list(ne1_agents())[1:]), r"agents\[0\]\.A must be real"),
])
def test_complex_inputs_are_refused_with_their_name(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_complex_reset_options_are_refused():
    env = tracking_v0.parallel_env()
    with pytest.raises(ValueError, match=r"options\['x0'\] must be real"):
        env.reset(seed=0, options={"x0": np.zeros(N_STATES, complex)})


# ------------------------------------------------------------------ boolean / complex actions
def _bad_action(kind: str, shape):
    return np.ones(shape, dtype=bool) if kind == "bool" else np.ones(shape, dtype=complex)


@pytest.mark.parametrize("kind", ["bool", "complex"])
def test_parallel_env_refuses_bool_and_complex_actions(kind):
    env = tracking_v0.parallel_env()
    env.reset(seed=0)
    acts = {a: np.zeros(env.action_space(a).shape, np.float32) for a in env.agents}
    acts["controller_2"] = _bad_action(kind, acts["controller_2"].shape)
    with pytest.raises(ValueError, match=f"action of agent 'controller_2' must be real numbers.*{kind}"):
        env.step(acts)
    # Python bools too, and nothing was simulated: the next valid step is the first one
    acts["controller_2"] = [True]
    with pytest.raises(ValueError, match="action of agent 'controller_2'"):
        env.step(acts)
    acts["controller_2"] = np.zeros(1, np.float32)
    env.step(acts)
    assert env.core.sim_state.t[0] == pytest.approx(env.core.control_period)


@pytest.mark.parametrize("kind", ["bool", "complex"])
def test_gym_env_refuses_bool_and_complex_actions(kind):
    env = gym.make("dobs_envs/Tracking-v0").unwrapped  # no passive checker in front
    env.reset(seed=0)
    with pytest.raises(ValueError, match=f"action must be real numbers.*{kind}"):
        env.step(_bad_action(kind, env.action_space.shape))


@pytest.mark.parametrize("kind", ["bool", "complex"])
def test_vector_env_refuses_bool_and_complex_actions(kind):
    venv = gym.make_vec("dobs_envs/Tracking-v0", num_envs=2, vectorization_mode="vector_entry_point")
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=f"actions must be real numbers.*{kind}"):
        venv.step(_bad_action(kind, venv.action_space.shape))


@pytest.mark.parametrize("kind", ["bool", "complex"])
def test_core_refuses_bool_and_complex_inputs(kind):
    core = TrackingEnv.make_core(2)
    core.reset(seeds=[0, 1])
    with pytest.raises(ValueError, match=f"u must be real numbers.*{kind}"):
        core.advance(_bad_action(kind, (2, N_INPUTS)))


@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize("kind", ["bool", "complex"])
def test_core_vec_env_refuses_bool_and_complex_actions(kind, shared):
    from agents.vecenv.batched_core import CoreVecEnv

    venv = CoreVecEnv(TrackingEnv.make_core(2), shared=shared)
    venv.reset()
    with pytest.raises(ValueError, match=f"actions must be real numbers.*{kind}"):
        venv.step(_bad_action(kind, (venv.num_envs,) + venv.action_space.shape))


def test_integer_actions_still_accepted():
    env = tracking_v0.parallel_env()
    env.reset(seed=0)
    env.step({a: np.zeros(env.action_space(a).shape, np.int64) for a in env.agents})
    g = gym.make("dobs_envs/Tracking-v0").unwrapped
    g.reset(seed=0)
    g.step(np.zeros(g.action_space.shape, np.int32))


def test_action_bound_arrays_share_one_compiled_step_and_clip_alike():
    """The default bound, or the same bound given as an array (writable, read-only or strided), clips alike, and
    the step is not compiled again for it (a read-only or strided array is another numba type: the env's own
    default bound was writable and a user's read-only, and each compiled the whole step, minutes cold)."""
    from numba.core.registry import CPUDispatcher

    from dobs_envs.envs import step_kernel

    def compiled():  # the specialisations of the step's compiled functions (advance_range, first_non_finite, ...)
        return sum(len(d.signatures) for d in vars(step_kernel).values() if isinstance(d, CPUDispatcher))

    plain = np.array(TrackingEnv().core.action_bound)  # the default bound (NE2's), given by the user
    frozen = plain.copy()
    frozen.flags.writeable = False
    strided = np.repeat(plain, 2)[::2]
    results, n_signatures = [], []
    for bound in (None, plain, frozen, strided):  # None: the env's default, the others given as an option
        env = TrackingEnv() if bound is None else TrackingEnv(action_bound=bound)
        env.reset(seed=0)
        big = {a: np.full(env.action_space(a).shape, 50.0, dtype=np.float32) for a in env.agents}
        obs = env.step(big)[0]
        results.append(np.concatenate([obs[a] for a in env.possible_agents]))
        n_signatures.append(compiled())
        env.close()
    assert n_signatures[0] > 0  # the step ran compiled code
    assert n_signatures[1:] == n_signatures[:1] * 3
    for r in results[1:]:
        np.testing.assert_array_equal(r, results[0])


def test_parallel_env_refuses_an_array_of_actions():
    """The ParallelEnv takes a dict agent -> action: an array is refused by name, not with numpy's IndexError."""
    env = TrackingEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="actions must be a dict agent -> action, got ndarray"):
        env.step(np.zeros(N_INPUTS, dtype=np.float32))
