"""SB3 ``VecEnv`` over the batched environment core (:class:`dobs_envs.envs.EnvCore`).

One compiled call advances every copy; two slot layouts:

- **centralised** (``shared=False``): slot ``c`` is copy ``c`` seen as the centralised
  Gymnasium env (the agents' observations concatenated, all inputs stacked);
- **parameter-shared** (``shared=True``): slot ``c * K + k`` is agent ``k`` of copy ``c``
  (one policy for every controller node), observations padded to the widest agent plus
  an optional one-hot agent id, actions truncated to the agent's width and clipped to its
  bounds -- :class:`agents.vecenv.slots.SlotEncoder`'s own encoding and decoding (``encode_batch``,
  ``decode_batch``: ``encode``/``decode`` of every slot at once; shared with evaluation).

The core's outputs (observations, infos) and the mapping of actions to inputs come from
:class:`dobs_envs.envs.adapter.CoreAdapter`, as for the PettingZoo, Gymnasium and vector envs.

Semantics (those of :class:`agents.vecenv.parallel.ParallelVecEnv` and of SB3's ``DummyVecEnv``
over the Gymnasium env):

- **Autoreset** in the same step: a finished copy's slots report ``done``,
  ``info["terminal_observation"]`` (that slot's last observation) and the first observation
  of the copy's next episode.
- **Infos**: every slot's info (and ``reset_infos``) has the same keys from ``reset`` on:
  ``"TimeLimit.truncated"`` (True only for a truncation, ``max_cycles``, never for a
  termination) and the integer ``"termination_reason"`` (codes of
  :data:`dobs_envs.envs.env_core.REASONS`: 0 none, 1 state_bound_exceeded, 2 non_finite_state,
  3 horizon); plus ``"terminal_observation"`` on the slots of a finished copy (SB3's
  convention). ``diagnostics=True`` adds the per-step errors the PettingZoo / Gymnasium
  infos carry: per agent ``estimation_error``, ``tracking_error``, ``gamma``, ``gamma_s``
  (shared slots), or ``tracking_error``, ``estimation_errors (N,)``, ``gamma (N,)``,
  ``gamma_s (N,)`` (centralised slots), and the task error (e.g. ``disagreement``). They are
  off by default: a dict entry per slot and key costs Python time that grows with the number
  of slots (measured: +3 % step time at 8 copies x 5 agents, +75 % at 256 x 5); the same
  arrays are always readable as ``venv.get_attr("estimation_errors")[0]`` (the core's ``(B, N)``).
- **Seeding**: :meth:`seed` makes the next :meth:`reset` seed copy ``c`` with ``seed + c``; later
  autoresets draw from the copy's own generator (reproducible runs).
- ``rescale_actions``: actions in ``[-1, 1]`` mapped affinely onto each input's bounds (clipped first).
- The core's options ``normalized_actions`` / ``padded_observations`` apply: the slots' spaces are
  built from the env's own (``dobs_envs.envs.adapter.agent_spaces``, ``central_spaces``), and actions
  in the env's units are mapped to inputs by ``core.action_scale``.
- Wrap it in ``VecMonitor`` for episode returns/lengths in the infos (``agents.training.train.build_vec_env`` does).
"""
from __future__ import annotations

import warnings
from typing import Any, Sequence

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from dobs_envs.envs.adapter import CoreAdapter, agent_spaces, central_spaces
from dobs_envs.linalg.validation import as_numeric, check_seed

from .slots import SlotEncoder

__all__ = ["CoreVecEnv"]


class CoreVecEnv(VecEnv):
    """SB3 VecEnv over ``core`` (see module doc).

    Parameters
    ----------
    core : EnvCore with ``B`` copies.
    shared : one slot per (copy, agent) (parameter sharing) instead of one per copy.
    agent_id : (shared) append a one-hot agent id to the observations.
    rescale_actions : actions in ``[-1, 1]`` mapped onto the inputs' bounds.
    diagnostics : add the per-step errors and gains to every slot's info (see module doc).
    """

    def __init__(self, core, *, shared: bool = False, agent_id: bool = False, rescale_actions: bool = False,
                 diagnostics: bool = False):
        self.core = c = core
        self.shared = bool(shared)
        self.diagnostics = bool(diagnostics)
        self.n_copies = B = c.num_envs
        self.agents = list(c.agents)
        self.n_agents = K = c.n_agents if self.shared else 1
        self.rescale_actions = bool(rescale_actions)
        central_obs, central_act, _ = central_spaces(c)
        # the env's own action units per input (the bounds, or [-1, 1] with the option normalized_actions);
        # core.action_scale maps them to inputs
        b = np.ones(c.n_inputs) if c.normalized_actions else np.asarray(c.action_bound, dtype=np.float64)
        self._lo, self._hi = -b, b
        self.env_action_space = central_act  # the inputs' own bounds (evaluation undoes the rescaling with them)
        if self.shared:
            obs_spaces, act_spaces = agent_spaces(c)  # the PettingZoo env's spaces
            self.encoder = SlotEncoder(self.agents, dict(zip(self.agents, obs_spaces)),
                                       dict(zip(self.agents, act_spaces)), agent_id=agent_id,
                                       rescale_actions=rescale_actions)
            obs_space, act_space = self.encoder.observation_space, self.encoder.action_space
        else:
            self.encoder = None
            obs_space = central_obs
            act_space = spaces.Box(-1.0, 1.0, central_act.shape, dtype=np.float32) if rescale_actions else central_act
        #: the core's outputs and inputs in the front ends' shapes (dobs_envs.envs.adapter)
        self._adapter = CoreAdapter(c)
        super().__init__(B * K, obs_space, act_space)
        self._actions = None
        self._copy_seeds: list | None = None
        self._closed = False

    # ------------------------------------------------------------------ encoding
    def _encode(self) -> np.ndarray:
        if not self.shared:
            return self._adapter.central_observations()
        return self.encoder.encode_batch(self._adapter.padded_observations)

    def _decode(self, actions) -> np.ndarray:
        a = np.asarray(as_numeric(actions, "actions"), dtype=np.float64)
        if self.shared:  # SlotEncoder.decode of every slot: truncated, rescaled, clipped to the agent's box
            return self._adapter.agent_inputs(self.encoder.decode_batch(a))
        a = a.reshape(self.n_copies, -1)
        if self.rescale_actions:
            a = self._lo + (np.clip(a, -1.0, 1.0) + 1.0) * 0.5 * (self._hi - self._lo)
        return self._adapter.central_inputs(a)

    def slot_info(self, slot: int) -> tuple[int, str]:
        """``slot -> (copy index, agent name)`` (centralised: agent ``"all"``)."""
        c, k = divmod(int(slot), self.n_agents)
        return c, self.agents[k] if self.shared else "all"

    # ------------------------------------------------------------------ core API
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        seed = check_seed(seed, "seed")  # fractional or negative seeds are refused, never truncated
        if seed is None:
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        self._copy_seeds = [seed + c for c in range(self.n_copies)]
        return [s for s in self._copy_seeds for _ in range(self.n_agents)]

    def reset(self) -> np.ndarray:
        opts = self._options[0] if self._options and self._options[0] else None
        self.core.reset(None, self._copy_seeds, opts)
        self._copy_seeds = None
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = self._infos(np.zeros(self.n_copies, dtype=np.int8), np.zeros(self.n_copies, dtype=bool))
        return self._encode()

    def _infos(self, reason: np.ndarray, trunc: np.ndarray) -> list[dict]:
        """One info per slot with the fixed keys (see module doc) from copy-level ``reason``/``trunc``."""
        K = self.n_agents
        reasons, truncs = reason.tolist(), trunc.tolist()
        infos = [{"TimeLimit.truncated": t, "termination_reason": r}
                 for r, t in zip(reasons, truncs) for _ in range(K)]
        if self.diagnostics:
            if self.shared:
                self._adapter.agent_infos(into=infos)
            else:
                self._adapter.central_infos(into=infos)
        return infos

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        u = self._decode(self._actions)
        self._actions = None
        res = self.core.advance(u)
        K = self.n_agents
        term, trunc = res.terminated, res.truncated
        done_c = term | trunc
        rew = res.reward.astype(np.float32)
        obs = self._encode()
        infos = self._infos(res.reason, trunc & ~term)  # before a reset overwrites the core's buffers
        if done_c.any():
            rows = np.flatnonzero(done_c)
            for c in rows:
                for s in range(c * K, c * K + K):
                    infos[s]["terminal_observation"] = obs[s].copy()
            dones = np.repeat(done_c, K)  # copied before the reset overwrites the core's buffers
            self.core.reset(rows)
            obs = self._encode()
        else:
            dones = np.zeros(self.num_envs, dtype=bool)
        return obs, np.repeat(rew, K), dones, infos

    def close(self) -> None:
        self.core.close()
        self._closed = True

    @property
    def closed(self) -> bool:
        return self._closed

    # ------------------------------------------------------------------ attributes (shared by all slots)
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        n = len(self._get_indices(indices))
        if attr_name == "render_mode":
            return [None] * n
        return [getattr(self.core, attr_name)] * n

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.core, attr_name, value)  # one core: the attribute is shared by every slot

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        out = getattr(self.core, method_name)(*method_args, **method_kwargs)
        return [out] * len(self._get_indices(indices))

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._get_indices(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        warnings.warn("CoreVecEnv does not render; use a single environment with render_mode='rgb_array'")
        return [None] * self.num_envs
