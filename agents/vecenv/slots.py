"""The slot encoding of parameter sharing: :class:`SlotEncoder` maps each agent's observations and actions to
one shared (padded) slot space and back, one slot at a time (``encode`` / ``decode``) or every slot at once
(``encode_batch`` / ``decode_batch``, the same arithmetic). Used by both VecEnvs
(:class:`agents.vecenv.parallel.ParallelVecEnv`, :class:`agents.vecenv.batched_core.CoreVecEnv`) and by a loaded
shared policy (:mod:`agents.training.loading`), so a trained policy sees identical inputs at test time.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from gymnasium import spaces

__all__ = ["SlotEncoder"]

def _flat_box(space: spaces.Space, what: str, agent) -> spaces.Box:
    if not isinstance(space, spaces.Box):
        raise TypeError(f"{what} space of agent {agent!r} must be a gymnasium Box, got {type(space).__name__}")
    return space


class SlotEncoder:
    """Maps per-agent observations/actions to the shared (padded) slot spaces.

    Used both by :class:`ParallelVecEnv` during training and by the evaluation code,
    so a trained shared policy sees identical inputs at test time.

    Parameters
    ----------
    agents : agent names in slot order.
    obs_spaces, act_spaces : dict agent -> Box.
    agent_id : append a one-hot agent index to every observation.
    rescale_actions : shared actions live in ``[-1, 1]`` and are mapped onto each
        agent's own bounds (which must then be finite).
    """

    def __init__(self, agents: Sequence[str], obs_spaces: dict, act_spaces: dict, agent_id: bool = False,
                 rescale_actions: bool = False):
        self.agents = list(agents)
        self.agent_id = bool(agent_id)
        self.rescale_actions = bool(rescale_actions)
        self.obs_spaces = {a: _flat_box(obs_spaces[a], "observation", a) for a in self.agents}
        self.act_spaces = {a: _flat_box(act_spaces[a], "action", a) for a in self.agents}
        self.obs_dims = [int(np.prod(self.obs_spaces[a].shape)) for a in self.agents]
        self.act_dims = [int(np.prod(self.act_spaces[a].shape)) for a in self.agents]
        self.obs_dim = max(self.obs_dims)
        self.act_dim = max(self.act_dims)
        M = len(self.agents)
        width = self.obs_dim + (M if self.agent_id else 0)
        lo = np.zeros(width, dtype=np.float32)
        hi = np.zeros(width, dtype=np.float32)
        # union of the agents' bounds on the components they have; padding is exactly 0
        lo[: self.obs_dim] = np.inf
        hi[: self.obs_dim] = -np.inf
        for a, d in zip(self.agents, self.obs_dims):
            sp = self.obs_spaces[a]
            lo[:d] = np.minimum(lo[:d], np.asarray(sp.low, dtype=np.float32).reshape(-1))
            hi[:d] = np.maximum(hi[:d], np.asarray(sp.high, dtype=np.float32).reshape(-1))
            if d < self.obs_dim:
                lo[d:self.obs_dim] = np.minimum(lo[d:self.obs_dim], 0.0)
                hi[d:self.obs_dim] = np.maximum(hi[d:self.obs_dim], 0.0)
        if self.agent_id:
            hi[self.obs_dim:] = 1.0
        self.observation_space = spaces.Box(lo, hi, dtype=np.float32)
        alo = np.full(self.act_dim, np.inf, dtype=np.float32)
        ahi = np.full(self.act_dim, -np.inf, dtype=np.float32)
        for a, d in zip(self.agents, self.act_dims):
            sp = self.act_spaces[a]
            alo[:d] = np.minimum(alo[:d], np.asarray(sp.low, dtype=np.float32).reshape(-1))
            ahi[:d] = np.maximum(ahi[:d], np.asarray(sp.high, dtype=np.float32).reshape(-1))
        if self.rescale_actions:
            for a in self.agents:
                sp = self.act_spaces[a]
                if not (np.all(np.isfinite(sp.low)) and np.all(np.isfinite(sp.high))):
                    raise ValueError(f"rescale_actions needs finite action bounds; agent {a!r} has {sp}")
            alo[:] = -1.0
            ahi[:] = 1.0
        self.action_space = spaces.Box(alo, ahi, dtype=np.float32)
        self._eye = np.eye(M, dtype=np.float32)
        # each agent's own action bounds (float64 of its Box), zero beyond its width: rows of decode_batch
        self._act_lo = np.zeros((M, self.act_dim))
        self._act_hi = np.zeros((M, self.act_dim))
        for j, (a, d) in enumerate(zip(self.agents, self.act_dims)):
            sp = self.act_spaces[a]
            self._act_lo[j, :d] = sp.low.reshape(-1).astype(np.float64)
            self._act_hi[j, :d] = sp.high.reshape(-1).astype(np.float64)
        #: the agents' actions concatenated (slot order) <- (agent, component) of a (M * act_dim) row
        self._act_gather = np.concatenate([j * self.act_dim + np.arange(d) for j, d in enumerate(self.act_dims)])
        self._act_dtype = np.result_type(*[self.act_spaces[a].dtype for a in self.agents])
        self._onehots: dict = {}

    @property
    def n_agents(self) -> int:
        return len(self.agents)

    def encode(self, j: int, obs) -> np.ndarray:
        """Observation of agent number ``j`` -> slot observation (padded, + one-hot)."""
        out = np.zeros(self.observation_space.shape, dtype=np.float32)
        flat = np.asarray(obs, dtype=np.float32).reshape(-1)
        out[: flat.size] = flat
        if self.agent_id:
            out[self.obs_dim:] = self._eye[j]
        return out

    def encode_all(self, obs: dict) -> np.ndarray:
        """``{agent: obs}`` -> (M, width) in slot order (missing agents give zeros)."""
        return np.stack([self.encode(j, obs[a]) if a in obs else self.encode(j, np.zeros(0)) for j, a in enumerate(self.agents)])

    def encode_batch(self, obs) -> np.ndarray:
        """``(C, M, d)`` observations of every agent of ``C`` copies (``d <= obs_dim``; each agent's
        observation in its first entries, zeros after) -> ``(C * M, width)`` slot observations in slot
        order: :meth:`encode` of every slot, vectorised."""
        obs = np.asarray(obs)
        C, M, d = obs.shape
        if M != self.n_agents or d > self.obs_dim:
            raise ValueError(f"obs must have shape (copies, {self.n_agents}, <= {self.obs_dim}), got {obs.shape}")
        o = obs.reshape(C * M, d).astype(np.float32)
        if d < self.obs_dim:
            o = np.concatenate([o, np.zeros((C * M, self.obs_dim - d), np.float32)], axis=1)
        if not self.agent_id:
            return o
        onehot = self._onehots.get(C)
        if onehot is None:
            onehot = self._onehots[C] = np.tile(self._eye, (C, 1))
        return np.concatenate([o, onehot], axis=1)

    @staticmethod
    def _decode_rows(act, lo, hi, rescale: bool) -> np.ndarray:
        """Shared actions (float64, truncated to the agents' widths) -> the agents' actions (float64):
        mapped from ``[-1, 1]`` onto ``[lo, hi]`` (``rescale``), clipped to ``[lo, hi]``."""
        if rescale:
            act = lo + (np.clip(act, -1.0, 1.0) + 1.0) * 0.5 * (hi - lo)
        return np.clip(act, lo, hi)

    def decode(self, j: int, action) -> np.ndarray:
        """Shared action of slot agent ``j`` -> that agent's action (truncated, clipped)."""
        sp = self.act_spaces[self.agents[j]]
        d = self.act_dims[j]
        act = np.asarray(action, dtype=np.float64).reshape(-1)[:d]
        act = self._decode_rows(act, self._act_lo[j, :d], self._act_hi[j, :d], self.rescale_actions)
        return act.reshape(sp.shape).astype(sp.dtype, copy=False)

    def decode_batch(self, actions) -> np.ndarray:
        """Shared actions of every slot of ``C`` copies, ``(C * M, act_dim)`` in slot order -> ``(C,
        sum act_dims)``: each copy's agents' actions (:meth:`decode`) concatenated in agent order, in
        the agents' common dtype (vectorised; the same arithmetic element by element)."""
        act = np.asarray(actions, dtype=np.float64).reshape(-1, self.n_agents, self.act_dim)
        act = self._decode_rows(act, self._act_lo, self._act_hi, self.rescale_actions)
        return act.reshape(act.shape[0], -1)[:, self._act_gather].astype(self._act_dtype, copy=False)

    def decode_all(self, actions) -> dict:
        actions = np.asarray(actions)
        return {a: self.decode(j, actions[j]) for j, a in enumerate(self.agents)}
