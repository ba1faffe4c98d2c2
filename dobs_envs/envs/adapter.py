"""The one layer between the batched core and its front ends: spaces, observations, infos and actions.

An :class:`~dobs_envs.envs.env_core.EnvCore` writes its outputs into batch-first buffers
(``observations (B, K, D)``, ``estimation_errors (B, N)``, ...). The four front ends hand them
out in their own conventions; every conversion is written once here, in :class:`CoreAdapter`:

==================================  ==============================  ===============================
front end                           observations                    infos / actions
==================================  ==============================  ===============================
PettingZoo ``DObsParallelEnv``      :meth:`~CoreAdapter.agent_observations` (copy 0)
                                                                    :meth:`~CoreAdapter.agent_infos`,
                                                                    :meth:`~CoreAdapter.write_agent_actions`
Gymnasium ``CentralizedEnv``        :meth:`~CoreAdapter.central_observations` (copy 0)
                                                                    :meth:`~CoreAdapter.central_info`,
                                                                    :meth:`~CoreAdapter.central_inputs`
Gymnasium ``DObsVectorEnv``         :meth:`~CoreAdapter.central_observations`
                                                                    :meth:`~CoreAdapter.info_arrays`,
                                                                    :meth:`~CoreAdapter.central_inputs`
SB3 ``agents.CoreVecEnv``           :meth:`~CoreAdapter.central_observations` or
                                    ``SlotEncoder.encode_batch`` of :attr:`CoreAdapter.padded_observations`
                                                                    :meth:`~CoreAdapter.agent_infos` /
                                                                    :meth:`~CoreAdapter.central_infos`,
                                                                    ``SlotEncoder.decode_batch`` then
                                                                    :meth:`~CoreAdapter.agent_inputs`
==================================  ==============================  ===============================

The spaces of the two views (one per agent, :func:`agent_spaces`; one centralised agent,
:func:`central_spaces`) are defined here too.

Per-agent infos (the agent's linked observer node ``i = links[k]``): ``estimation_error``,
``tracking_error``, ``gamma``, ``gamma_s`` and the task error if the task has one; per-copy
(centralised) infos: ``tracking_error``, ``estimation_errors (N,)``, ``gamma (N,)``,
``gamma_s (N,)`` and the task error. With communication faults (option ``faults``) also, per agent,
``co_received`` (bool: its C-O packet arrived at this boundary, else its ``xhat`` is stale) and
``oo_received_fraction`` (float: the fraction of the O-O links into its node whose value arrived at
this boundary, 1 for a node without links); per copy the same as ``(K,)`` arrays. Every value is read
from the core when the method is called.
"""
from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ..linalg.validation import NUMERIC_KINDS, as_numeric

__all__ = ["CoreAdapter", "agent_spaces", "central_spaces"]


def agent_spaces(core) -> tuple[list, list]:
    """``(observation Boxes, action Boxes)`` of the agents of ``core``, in agent order.

    Actions: ``Box(-b_k, b_k, (m_k,), float32)`` with channel ``k``'s bounds, or with
    ``normalized_actions`` the common ``Box(-1, 1, (M,), float32)`` (``M = max_k m_k``).
    Observations: ``Box(low_k, high_k)`` of agent ``k``'s width (``padded_observations``: the
    same Box for every agent, padded and masked where the widths differ).
    """
    obs = [spaces.Box(*core.observation_bounds(k), dtype=core.obs_dtype) for k in range(core.n_agents)]
    if core.normalized_actions:
        M = int(core.agent_action_widths[0])
        act = [spaces.Box(-1.0, 1.0, (M,), dtype=np.float32) for _ in range(core.n_agents)]
    else:
        b = core.action_bound.astype(np.float32)
        act = [spaces.Box(-b[s], b[s], dtype=np.float32) for s in core.channel_slices]
    return obs, act


def central_spaces(core):
    """``(observation Box, action Box, agent observation slices)`` of the centralised view of ``core``:
    the agents' observations concatenated in agent order (``padded_observations``: each as the
    parallel env gives it, padded and masked where the widths differ), all inputs stacked
    (``normalized_actions``: ``Box(-1, 1, (m,))``, input ``j`` scaled by its bound, ``core.action_scale``)."""
    lows, highs, sl, pos = [], [], [], 0
    for k, w in enumerate(core.obs_widths):
        lo, hi = core.observation_bounds(k)
        lows.append(lo)
        highs.append(hi)
        sl.append(slice(pos, pos + int(w)))
        pos += int(w)
    b = np.ones(core.n_inputs, np.float32) if core.normalized_actions else core.action_bound.astype(np.float32)
    return (spaces.Box(np.concatenate(lows), np.concatenate(highs), dtype=core.obs_dtype),
            spaces.Box(-b, b, dtype=np.float32), tuple(sl))


class CoreAdapter:
    """The outputs of ``core`` (all ``B`` copies) in the front ends' shapes, and their actions as the
    core's inputs (see module doc). Holds no state but index tables; reads the core on every call."""

    def __init__(self, core):
        self.core = c = core
        self.agents = tuple(c.agents)
        self._agent_id = {a: k for k, a in enumerate(self.agents)}
        #: width of each agent's observation (its first entries of the core's padded row)
        self.obs_widths = tuple(int(w) for w in c.obs_widths)
        #: width of each agent's action and its offset in the agents' actions concatenated
        self.action_widths = tuple(int(w) for w in c.agent_action_widths)
        self.action_offsets = tuple(int(o) for o in np.cumsum((0,) + self.action_widths[:-1]))
        self._shapes = [(w,) for w in self.action_widths]
        self._cat = None if c.layout.uniform else c.layout.concat_index

    # ------------------------------------------------------------------ observations
    @property
    def padded_observations(self) -> np.ndarray:
        """``(B, K, D)`` every agent's observation zero-padded to the widest (read-only view of the core)."""
        return self.core.observations

    def agent_observations(self, b: int = 0) -> dict:
        """``{agent: (w_k,) observation}`` of copy ``b``: views into a fresh copy of its ``(K, D)`` row."""
        o = self.core.observations[b].copy()
        return {a: o[k, :w] for k, (a, w) in enumerate(zip(self.agents, self.obs_widths))}

    def central_observations(self, b: int | None = None) -> np.ndarray:
        """The agents' observations concatenated in agent order: ``(B, sum w_k)`` (a new array), or
        ``(sum w_k,)`` of copy ``b``."""
        obs = self.core.observations
        if b is not None:
            flat = obs[b].reshape(-1)
            return flat.copy() if self._cat is None else flat[self._cat]
        flat = obs.reshape(obs.shape[0], -1)
        return flat.copy() if self._cat is None else flat[:, self._cat]

    # ------------------------------------------------------------------ infos
    def _tails(self, extra: dict) -> list:
        """Per copy: the task error (if the task has one) and then ``extra``, as one dict."""
        c = self.core
        key = c.task_error_key
        if key is None:
            return [extra] * c.num_envs
        return [{key: t, **extra} for t in c.task_errors().tolist()]

    def _fault_infos(self):
        """``(co_received (B, K) bool, oo_received_fraction (B, K))`` or None without faults."""
        c = self.core
        if c.faults is None:
            return None
        return c.co_received, c.oo_received_fraction

    def agent_infos(self, into: list | None = None, **extra) -> list[dict]:
        """One info per (copy, agent), copy-major (``B * K`` dicts): ``estimation_error``,
        ``tracking_error``, ``gamma``, ``gamma_s`` of the agent's linked node, the task error if
        any, then ``extra``; Python floats. ``into``: ``B * K`` dicts updated in place instead."""
        c = self.core
        te = c.tracking_errors.tolist()
        ee, g, gs = c.estimation_errors.tolist(), c.gamma.tolist(), c.gamma_s.tolist()
        tails, links = self._tails(extra), c.links
        fi = self._fault_infos()
        K = len(links)
        if into is None:
            out = [{"estimation_error": eb[i], "tracking_error": tb, "gamma": gb[i], "gamma_s": gsb[i], **tail}
                   for eb, tb, gb, gsb, tail in zip(ee, te, g, gs, tails) for i in links]
        else:
            out = into
            for s, info in enumerate(into):
                b, k = divmod(s, K)
                i = links[k]
                info.update(estimation_error=ee[b][i], tracking_error=te[b], gamma=g[b][i], gamma_s=gs[b][i])
                info.update(tails[b])
        if fi is not None:
            rec, frac = fi[0].tolist(), fi[1].tolist()
            for s, info in enumerate(out):
                b, k = divmod(s, K)
                info.update(co_received=rec[b][k], oo_received_fraction=frac[b][k])
        return out

    def central_info(self, b: int = 0, **extra) -> dict:
        """The info of copy ``b`` (centralised): ``tracking_error`` (float), ``estimation_errors (N,)``,
        ``gamma (N,)``, ``gamma_s (N,)`` (new arrays), the task error if any (float), then ``extra``."""
        c = self.core
        info = {"tracking_error": float(c.tracking_errors[b]), "estimation_errors": c.estimation_errors[b].copy(),
                "gamma": c.gamma[b].copy(), "gamma_s": c.gamma_s[b].copy()}
        if c.task_error_key is not None:
            info[c.task_error_key] = float(c.task_errors()[b])
        fi = self._fault_infos()
        if fi is not None:
            info.update(co_received=fi[0][b], oo_received_fraction=fi[1][b])
        info.update(extra)
        return info

    def central_infos(self, into: list | None = None, **extra) -> list[dict]:
        """:meth:`central_info` of every copy (``B`` dicts; the arrays rows of one copy per key).
        ``into``: ``B`` dicts updated in place instead."""
        c = self.core
        te = c.tracking_errors.tolist()
        ee, g, gs = c.estimation_errors.copy(), c.gamma.copy(), c.gamma_s.copy()
        tails = self._tails(extra)
        out = [{} for _ in te] if into is None else into
        fi = self._fault_infos()
        for b, info in enumerate(out):
            info.update(tracking_error=te[b], estimation_errors=ee[b], gamma=g[b], gamma_s=gs[b])
            if fi is not None:
                info.update(co_received=fi[0][b], oo_received_fraction=fi[1][b])
            info.update(tails[b])
        return out

    def info_arrays(self) -> dict:
        """The per-copy infos as arrays over the copies (new arrays): ``tracking_error (B,)``,
        ``estimation_errors (B, N)``, ``gamma (B, N)``, ``gamma_s (B, N)`` and the task error ``(B,)``."""
        c = self.core
        info = {"tracking_error": c.tracking_errors.copy(), "estimation_errors": c.estimation_errors.copy(),
                "gamma": c.gamma.copy(), "gamma_s": c.gamma_s.copy()}
        if c.task_error_key is not None:
            info[c.task_error_key] = np.array(c.task_errors(), dtype=np.float64)
        fi = self._fault_infos()
        if fi is not None:
            info.update(co_received=fi[0], oo_received_fraction=fi[1])
        return info

    # ------------------------------------------------------------------ actions
    def central_inputs(self, actions) -> np.ndarray:
        """Inputs from centralised actions ``(..., m)`` in the env's units: scaled by their bounds
        with ``normalized_actions``, else the actions themselves."""
        c = self.core
        return actions * c.action_scale if c.normalized_actions else actions

    def agent_inputs(self, actions, out: np.ndarray | None = None) -> np.ndarray:
        """Inputs ``(B, m)`` from the agents' actions concatenated in agent order
        (:meth:`EnvCore.agent_inputs <dobs_envs.envs.env_core.EnvCore.agent_inputs>`)."""
        return self.core.agent_inputs(actions, out=out)

    def write_agent_actions(self, actions, out: np.ndarray) -> None:
        """Write the dict ``{agent: action}`` (every agent, shape ``(w_k,)``) into ``out`` (the agents'
        actions concatenated, ``(sum w_k,)``). Errors name the agent; nothing is written on error."""
        try:  # fast path: exactly the agents, right shapes, float/int arrays -> one concatenate into out
            vals = [actions[a] for a in self.agents]
            ok = (len(actions) == len(vals) and [v.shape for v in vals] == self._shapes
                  and all(v.dtype.kind in NUMERIC_KINDS for v in vals))  # bool/complex: refused by the slow path
            if ok:
                np.concatenate(vals, out=out, casting="same_kind")
        except (KeyError, IndexError, TypeError, ValueError, AttributeError):  # IndexError: an array, not a dict
            ok = False
        if not ok:
            self._parse_agent_actions(actions, out)

    def _parse_agent_actions(self, actions, out) -> None:
        if not isinstance(actions, dict):
            raise ValueError(f"actions must be a dict agent -> action, got {type(actions).__name__}")
        new = out.copy()
        for agent, a in actions.items():
            k = self._agent_id.get(agent)
            if k is None:
                raise ValueError(f"unknown agent {agent!r}; agents are {list(self.agents)}")
            arr = as_numeric(a, f"action of agent {agent!r}")
            w, o = self.action_widths[k], self.action_offsets[k]
            if arr.shape != (w,):
                raise ValueError(f"action of agent {agent!r} must have shape ({w},), got {arr.shape}")
            new[o:o + w] = arr
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"missing action(s) for agent(s) {missing}")
        out[:] = new

    def actions_from_inputs(self, u) -> dict:
        """``{agent: action}`` that applies the inputs ``u (m,)``: the channels' parts of ``u``, or with
        ``normalized_actions`` divided by their bounds and zero-padded."""
        c = self.core
        u = np.asarray(u, dtype=np.float64).reshape(c.n_inputs)
        if not c.normalized_actions:
            return {a: u[s].copy() for a, s in zip(self.agents, c.channel_slices)}
        flat = np.zeros(sum(self.action_widths))
        flat[c.action_gather] = u / c.action_scale
        return {a: flat[o:o + w] for a, o, w in zip(self.agents, self.action_offsets, self.action_widths)}
