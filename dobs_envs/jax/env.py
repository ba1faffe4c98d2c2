"""The centralised view in JAX, with gymnax's interface: ``dobs_envs.jax.make(id) -> (env, params)``.

The Gymnasium ids of the suite (``dobs_envs/Tracking-v0``, ...) as pure functions of
``(key, state, action, params)``, following gymnax 1.0:

=============================================  ==================================================
``env.reset(key, params)``                     ``(obs, state)``
``env.step(key, state, action, params)``       ``(obs, state, reward, terminated, truncated, info)``,
                                               auto-reset: a copy that ended starts a new episode,
                                               ``info["final_observation"]`` is the last one
``env.observation_space(params)``              ``Box`` of the agents' observations concatenated
``env.action_space(params)``                   ``Box(-b, b, (m,))`` (``normalized_actions``: ``(-1, 1)``)
``env.default_params``                         :class:`~dobs_envs.jax.params.EnvParams`
=============================================  ==================================================

Everything composes with ``jax.jit``, ``jax.vmap`` (over copies, keys and parameters) and
``jax.lax.scan``. The observation, action, reward, termination and info are those of
``gym.make(id)`` (:class:`dobs_envs.envs.centralized.CentralizedEnv`), with one difference: the
episode is truncated by the environment itself after ``params.max_steps_in_episode`` control
steps (gymnax's convention, instead of Gymnasium's ``TimeLimit``), with the reason code 3
(``horizon``) and the termination penalty charged up to that horizon, as the PettingZoo
environment with ``max_cycles`` does.
"""
from __future__ import annotations

import math
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..envs.centralized import reject_horizon_options
from ..registry import ENVIRONMENTS, GYM_IDS
from . import core as _core
from .faults import received_fraction
from .params import EnvParams, EnvState, Structure, from_core
from .spaces import Box

__all__ = ["DObsEnv", "make", "registered_envs"]


def registered_envs() -> tuple:
    """The ids :func:`make` accepts (the suite's Gymnasium ids)."""
    return tuple(GYM_IDS)


def _resolve_dtype(dtype):
    """``dtype`` option -> ``jnp.float32``/``jnp.float64`` (``None``: float64 when x64 is enabled, else
    float32); float64 without ``jax_enable_x64`` is an error, not a silent float32."""
    x64 = bool(jax.config.jax_enable_x64)
    if dtype is None:
        return np.dtype(np.float64 if x64 else np.float32)
    try:
        dt = np.dtype(dtype)
    except TypeError:
        dt = None
    if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype must be 'float32' or 'float64', got {dtype!r}")
    if dt == np.float64 and not x64:
        raise ValueError("dtype='float64' needs 64-bit JAX: call jax.config.update('jax_enable_x64', True) before "
                         "creating any array (or use dtype='float32')")
    return dt


class DObsEnv:
    """A dobs_envs environment as gymnax's ``Environment`` (module doc). Build it with :func:`make`.

    Attributes
    ----------
    structure : :class:`~dobs_envs.jax.params.Structure` (static under ``jit``).
    core : the batch-1 :class:`~dobs_envs.envs.env_core.EnvCore` it was built from (the same options).
    """

    def __init__(self, name: str, structure: Structure, params: EnvParams, core=None):
        self._name = name
        self.structure = structure
        self._params = params
        self.core = core

    # ------------------------------------------------------------------ gymnax interface
    @property
    def name(self) -> str:
        return self._name

    @property
    def default_params(self) -> EnvParams:
        return self._params

    @property
    def num_actions(self) -> int:
        return self.structure.m

    def __repr__(self) -> str:
        return f"DObsEnv({self._name!r}, dtype={self.structure.dtype.name})"

    @partial(jax.jit, static_argnames=("self",))
    def reset(self, key: jax.Array, params: EnvParams | None = None):
        """``(obs, state)`` of a new episode drawn with ``key``."""
        return self.reset_env(key, self._params if params is None else params)

    @partial(jax.jit, static_argnames=("self",))
    def step(self, key: jax.Array, state: EnvState, action, params: EnvParams | None = None):
        """One control step with auto-reset: ``(obs, state, reward, terminated, truncated, info)``."""
        params = self._params if params is None else params
        key_step, key_reset = jax.random.split(key)
        obs_st, state_st, reward, terminated, truncated, info = self.step_env(key_step, state, action, params)
        obs_re, state_re = self.reset_env(key_reset, params)
        done = terminated | truncated
        state = jax.tree.map(lambda r, s: jax.lax.select(done, r, s), state_re, state_st)
        obs = jax.lax.select(done, obs_re, obs_st)
        info = {**info, "terminated": terminated, "truncated": truncated, "final_observation": obs_st}
        return obs, state, reward, terminated, truncated, info

    def reset_env(self, key: jax.Array, params: EnvParams):
        """The reset without ``jit`` (pure): ``(obs, state)``."""
        state = _core.reset(key, params, self.structure)
        return self.get_obs(state, params), state

    def step_env(self, key: jax.Array, state: EnvState, action, params: EnvParams):
        """The step without auto-reset (pure): ``(obs, state, reward, terminated, truncated, info)``."""
        del key  # the step is deterministic
        u = self.inputs(action, params)
        state, out = _core.advance(state, u, params, self.structure)
        return (self._central(out.obs), state, out.reward, out.terminated, out.truncated,
                self._info(state, out.features, out.reason))

    def get_obs(self, state: EnvState, params: EnvParams | None = None, key=None) -> jax.Array:
        """The concatenated observation of ``state`` (as after a reset: not cleaned)."""
        params = self._params if params is None else params
        return self._central(_core.observations(_core.features(state, params, self.structure), self.structure))

    def observation_space(self, params: EnvParams | None = None) -> Box:
        core = self.core
        lo = np.concatenate([core.observation_bounds(k)[0] for k in range(core.n_agents)])
        hi = np.concatenate([core.observation_bounds(k)[1] for k in range(core.n_agents)])
        return Box(lo, hi, lo.shape, self.structure.obs_dtype)

    def action_space(self, params: EnvParams | None = None) -> Box:
        st = self.structure
        if st.normalized_actions:
            return Box(-1.0, 1.0, (st.m,), jnp.float32)
        b = np.asarray((self._params if params is None else params).action_high, dtype=np.float32)
        return Box(-b, b, (st.m,), jnp.float32)

    # ------------------------------------------------------------------ the centralised view
    def inputs(self, action, params: EnvParams) -> jax.Array:
        """The inputs ``u (m,)`` of a centralised action (scaled by the bounds with ``normalized_actions``)."""
        a = jnp.asarray(action)
        if a.shape != (self.structure.m,):
            raise ValueError(f"action must have shape ({self.structure.m},) (all agents' inputs stacked), "
                             f"got {a.shape}")
        if not jnp.issubdtype(a.dtype, jnp.floating) and not jnp.issubdtype(a.dtype, jnp.integer):
            raise ValueError(f"action must be real numbers (float or integer), got dtype {a.dtype}")
        a = a.astype(self.structure.dtype)
        return a * params.action_scale if self.structure.normalized_actions else a

    def _central(self, padded: jax.Array) -> jax.Array:
        return padded.reshape(-1)[self.structure.concat_index]

    def _info(self, state: EnvState, feat, reason) -> dict:
        st = self.structure
        info = {"tracking_error": feat.tracking_error, "estimation_errors": feat.estimation_errors,
                "gamma": state.gamma, "gamma_s": state.gamma_s}
        if st.task_positions is not None:
            info[st.task_error_key] = _core.task_error(state, st)
        if st.faults is not None:  # per agent, as the compiled env's co_received / oo_received_fraction
            info["co_received"] = feat.received.co_rx
            info["oo_received_fraction"] = received_fraction(st.faults, feat.received.oo_rx)
        info["termination_reason"] = reason
        return info


def _build(entry, options: dict) -> tuple:
    """``(structure, params, core)`` of a registry entry with the keyword ``options`` of :func:`make`."""
    reject_horizon_options(options)
    if options.get("render_mode") is not None:
        raise TypeError("render_mode is not an option of the JAX environments (they run compiled, without a display)")
    options.pop("render_mode", None)
    dtype = _resolve_dtype(options.pop("dtype", None))
    sparse = options.pop("sparse", True)
    if not isinstance(sparse, bool):
        raise ValueError(f"sparse must be True or False, got {sparse!r}")
    steps = options.pop("max_episode_steps", None)
    core = entry.load_class().make_core(1, horizon=math.inf, **options)
    if steps is None:
        steps = core.penalty_cycles  # t_end in control periods
    elif isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"max_episode_steps must be a positive integer, got {steps!r}")
    structure, params = from_core(core, max_steps_in_episode=int(steps), dtype=dtype, sparse=sparse)
    if dtype == np.float32:
        cost = float(core.bound_step_cost) * int(steps)
        if not math.isfinite(cost) or cost > np.finfo(np.float32).max:
            raise ValueError(f"state_bound={core.state_bound:g}: the termination penalty ({cost:.3g}) overflows "
                             f"float32; use dtype='float64' or a smaller state_bound")
    return structure, params, core


def make(env_id: str, **options) -> tuple[DObsEnv, EnvParams]:
    """``(env, default_params)`` of a registered id, as ``gymnax.make``.

    Parameters
    ----------
    env_id : one of :func:`registered_envs` (``"dobs_envs/Tracking-v0"``, ...).
    options : the environment's options (those of ``gym.make(env_id, ...)``: ``state_bound``,
        ``normalized_actions``, ``padded_observations``, ``observation``, ``reward``, ``scenario``, ...),
        plus
        ``max_episode_steps`` : int, the truncation horizon in control steps (default: the scenario's
        ``t_end`` over the control period; ``params.max_steps_in_episode``);
        ``dtype`` : ``"float32"`` or ``"float64"`` (default: float64 when ``jax_enable_x64`` is on, else
        float32); the simulation's float type. Observations keep the ``obs_dtype`` option;
        ``sparse`` : bool, default True: the products run over the nonzeros of the system's matrices
        (:mod:`dobs_envs.jax.operators`); False for parameters with other nonzeros (``vmap`` over systems).
    """
    if not isinstance(env_id, str) or env_id not in GYM_IDS:
        raise ValueError(f"unknown environment id {env_id!r}; registered ids are {list(GYM_IDS)}")
    entry = next(e for e in ENVIRONMENTS.values() if e.gym_id == env_id)
    structure, params, core = _build(entry, dict(options))
    return DObsEnv(env_id, structure, params, core), params
