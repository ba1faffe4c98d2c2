"""Per-agent observation layouts: one flat vector gathered from a per-step feature vector.

Every control step the environment writes, once, a flat *feature vector* ``f``
holding everything any agent may observe::

    f = [ y (sum_i p_i) | xhat_0..xhat_{N-1} (N n) | x (n) | x_r (n) | gamma (N) | gamma_s (N)
          | v (m_v) | r (m) | t (1) | e (n) | 0 (1) | 1 (1) ]

(written for every copy of a batch by one compiled call,
:func:`dobs_envs.envs.features.write_features`; readable numpy reference in
:mod:`dobs_envs.envs.numpy_features`) and the observation of agent ``k`` is
``f[index_k]``. The batched environment core stores all agents' observations in one
array ``(B, K, D)`` with ``D = max_k len(index_k)``: row ``k`` holds agent ``k``'s
``len(index_k)`` entries followed by zeros (:attr:`FeatureLayout.padded_index` points
the padding at the constant 0 of ``f``); ``FeatureLayout.widths[k]`` is agent ``k``'s
true width. Neighbour-padding entries point at the constant 0, mask entries at the
constant 1 (or 0 for padding). This keeps the per-step cost at one gather per copy
whatever components are selected.

Components an agent ``k`` (linked observer node ``i = links[k]``) can observe:

=============  ===============  ================================================================
name           size             content
=============  ===============  ================================================================
``y``          ``p_i``          local measured output ``y_i = C_i x`` (eq. localmeasure)
``xhat``       ``n``            the estimate ``xhat_i`` it receives over its C-O link (eq. hatxieq)
``neighbors``  ``D n``          estimates ``xhat_j`` of node ``i``'s O-O neighbours ``j`` (sorted
                                by index), zero-padded to ``D`` = the largest number of neighbours
                                of any node
``mask``       ``D``            1 for a real neighbour slot, 0 for padding
``r``          ``m_k``          its reference command ``r^k(t)`` (eq. refxdy; tracking only)
``x``          ``n``            true plant state (privileged, debugging)
``x_r``        ``n``            reference-model state (privileged; tracking only)
``estimates``  ``N n``          all observer nodes' estimates (privileged)
``gamma``      ``N``            adaptive gains ``gamma_i`` of eq. (gammaiis)
``gamma_s``    ``N``            adaptive gains ``gamma_is`` of eq. (gammaiis)
``v``          ``m_v``          unknown input ``v`` (privileged; only when ``B_v != 0``)
``time``       ``1``            simulated time ``t`` (s)
``received``   ``1 + D``        with communication faults only (option ``faults``): 1 if its C-O
                                packet arrived at this boundary (else ``xhat`` is the held, stale
                                estimate), then per neighbour slot 1 if that neighbour's value was
                                received at this boundary (else held from an earlier broadcast),
                                0 for padding
=============  ===============  ================================================================

With communication faults (option ``faults``, :mod:`dobs_envs.sim.faults`) an agent observes only
what reached its node: ``y`` with the held measurement noise, ``xhat`` the estimate held at the
controller's end of the C-O link (:func:`~dobs_envs.sim.fault_state.co_link_numpy`: delayed, or the
last one received), ``neighbors`` the copies node ``i`` holds of its O-O neighbours' estimates
(neighbours: those of the union of the switching graphs), and ``received`` (in both presets) the
received/stale mask; the privileged components stay the true values (``estimates``: the nodes' own,
noisy-measurement estimates). The feature vector then ends with ``xhat_rx (K n) | nbr_rx (E n) |
co_rx (K) | oo_rx (E)`` before the constants (written by
:func:`dobs_envs.envs.features.fault_rows`).

Presets: ``"local"`` = ``(y, xhat, neighbors, mask, r, received)`` (``r`` only with a
reference, ``received`` only with faults), ``"full"`` = local + ``(x, x_r, estimates, gamma, gamma_s,
v, time)`` (each only where it exists).

Padded observations (option ``padded_observations=True``, ``FeatureLayout(..., padded=True)``):
when the agents' widths differ, every agent observes ``2 W`` values, ``W`` the widest agent's
width: its own observation followed by zeros up to ``W``, then the component ``obs_mask`` (``W``
entries, 1 where the entry is real, 0 for padding). The gathers point the padding at the constant
0 and the mask at the constants 1/0 of ``f``, so the compiled step writes the mask itself. When
every agent already has width ``W`` (tracking, disturbance_rejection, hetero_mas, random networks
whose agents measure and control alike) nothing is added: no padding, no ``obs_mask`` (it would
be all ones and double the width). Either way every agent gets the same bounds (the union over the
agents, see :meth:`FeatureLayout.bounds`), hence identical spaces (:attr:`FeatureLayout.masked`
tells which case holds).
"""
from __future__ import annotations

import numpy as np

__all__ = ["COMPONENTS", "LOCAL", "FULL", "FeatureLayout", "resolve_components"]

COMPONENTS = ("y", "xhat", "neighbors", "mask", "r", "x", "x_r", "estimates", "gamma", "gamma_s", "v", "time",
              "received")
LOCAL = ("y", "xhat", "neighbors", "mask", "r", "received")
FULL = LOCAL + ("x", "x_r", "estimates", "gamma", "gamma_s", "v", "time")
#: components that exist only in some systems (silently dropped from the presets)
_OPTIONAL = {"r": "has_reference", "x_r": "has_reference", "v": "has_unknown_input", "received": "has_faults"}


def resolve_components(spec, *, has_reference: bool, has_unknown_input: bool, has_faults: bool = False) -> tuple:
    """The tuple of component names selected by ``spec`` ("local", "full" or a sequence of names)."""
    avail = {"has_reference": has_reference, "has_unknown_input": has_unknown_input, "has_faults": has_faults}
    if isinstance(spec, str):
        if spec not in ("local", "full"):
            raise ValueError(f"observation must be 'local', 'full' or a sequence of component names from {COMPONENTS}, got {spec!r}")
        names = LOCAL if spec == "local" else FULL
        return tuple(c for c in names if c not in _OPTIONAL or avail[_OPTIONAL[c]])
    try:
        names = tuple(spec)
    except TypeError:
        raise ValueError(f"observation must be 'local', 'full' or a sequence of component names, got {spec!r}") from None
    if not names:
        raise ValueError("observation must select at least one component")
    for c in names:
        if c not in COMPONENTS:
            raise ValueError(f"unknown observation component {c!r}; valid components are {COMPONENTS}")
        if c in _OPTIONAL and not avail[_OPTIONAL[c]]:
            what = {"has_reference": "a reference signal", "has_unknown_input": "an unknown input (B_v)",
                    "has_faults": "communication faults (option faults)"}[_OPTIONAL[c]]
            raise ValueError(f"observation component {c!r} needs {what}, which this system does not have")
    if len(set(names)) != len(names):
        raise ValueError(f"observation components must not repeat, got {names}")
    return names


class FeatureLayout:
    """Positions of the quantities in the feature vector ``f`` and the per-agent gathers.

    Parameters
    ----------
    p : (N,) output sizes ``p_i``; n : state size; m : input size; m_v : unknown-input size.
    neighbors : list of sorted neighbour arrays per node.
    links : (K,) linked observer node per controller node.
    channel_slices : per controller node, its columns of ``u`` (and ``r``).
    components : tuple of selected component names.
    padded : identical agent spaces: where the agents' widths differ, every agent observes its
        observation zero-padded to the widest agent's width ``W`` followed by the ``obs_mask``
        component (``W`` entries, 1 = real entry); with equal widths only the bounds are united
        (see module doc).
    fault_links : ``(sender (E,), receiver (E,))`` of the directed O-O links, sorted by receiver then
        sender (:class:`~dobs_envs.sim.fault_state.FaultArgs`), with communication faults: adds the
        received quantities to the feature vector, the agents observe them (module doc) and the
        neighbours are the links' senders (``neighbors`` is then not used).
    """

    def __init__(self, p, n, m, m_v, neighbors, links, channel_slices, components, padded: bool = False,
                 fault_links=None):
        N = len(p)
        K = len(links)
        if fault_links is not None:
            sender, receiver = (np.asarray(a, dtype=np.intp) for a in fault_links)
            neighbors = [sender[receiver == i] for i in range(N)]
            #: first link into each node (links sorted by receiver): link of neighbour slot s of node i
            link0 = np.searchsorted(receiver, np.arange(N))
        self.N, self.n, self.m, self.m_v = N, n, m, m_v
        pos = 0

        def take(size):
            nonlocal pos
            s = slice(pos, pos + size)
            pos += size
            return s

        y_off = np.concatenate([[0], np.cumsum(p)]).astype(int)
        self.y = take(int(y_off[-1]))
        self.y_nodes = [slice(self.y.start + y_off[i], self.y.start + y_off[i + 1]) for i in range(N)]
        self.xhat = take(N * n)
        self.x = take(n)
        self.x_r = take(n)
        self.gamma = take(N)
        self.gamma_s = take(N)
        self.v = take(m_v)
        self.r = take(m)
        self.time = take(1)
        self.e = take(n)  # task error x - x_r (or x); not observable, used for the reward
        #: communication faults: what the agents receive (module doc); None without faults
        self.faults = fault_links is not None
        if self.faults:
            E = len(fault_links[0])
            self.xhat_rx, self.nbr_rx, self.co_rx, self.oo_rx = take(K * n), take(E * n), take(K), take(E)
        self.zero = take(1).start
        self.one = take(1).start
        self.size = pos
        self.max_neighbors = max((len(nb) for nb in neighbors), default=0)
        self.components = tuple(components)
        D = self.max_neighbors
        self.agent_index = []
        self.agent_layout = []
        for k, i in enumerate(links):
            parts, layout, start = [], {}, 0
            nb = list(neighbors[i])
            for c in components:
                if c == "y":
                    idx = np.arange(self.y_nodes[i].start, self.y_nodes[i].stop)
                elif c == "xhat" and self.faults:
                    idx = self.xhat_rx.start + k * n + np.arange(n)
                elif c == "xhat":
                    idx = self.xhat.start + i * n + np.arange(n)
                elif c == "neighbors":
                    idx = np.full(D * n, self.zero)
                    for s, j in enumerate(nb):
                        src = self.nbr_rx.start + (link0[i] + s) * n if self.faults else self.xhat.start + j * n
                        idx[s * n:(s + 1) * n] = src + np.arange(n)
                elif c == "received":
                    idx = np.full(1 + D, self.zero)
                    idx[0] = self.co_rx.start + k
                    for s in range(len(nb)):
                        idx[1 + s] = self.oo_rx.start + link0[i] + s
                elif c == "mask":
                    idx = np.array([self.one if s < len(nb) else self.zero for s in range(D)], dtype=int)
                elif c == "r":
                    sl = channel_slices[k]
                    idx = self.r.start + np.arange(sl.start, sl.stop)
                elif c == "estimates":
                    idx = np.arange(self.xhat.start, self.xhat.stop)
                else:  # x, x_r, gamma, gamma_s, v, time
                    s_ = getattr(self, c)
                    idx = np.arange(s_.start, s_.stop)
                idx = np.asarray(idx, dtype=np.intp)
                layout[c] = slice(start, start + idx.size)
                start += idx.size
                parts.append(idx)
            self.agent_index.append(np.concatenate(parts) if parts else np.zeros(0, dtype=np.intp))
            self.agent_layout.append(layout)
        #: true width of every agent's own observation (without padding and mask)
        self.feature_widths = np.array([ix.size for ix in self.agent_index], dtype=np.intp)
        self.padded = bool(padded)
        W = int(self.feature_widths.max()) if len(self.feature_widths) else 0
        #: padded layout whose agents differ in width: padding and the ``obs_mask`` component are added
        #: (agents of equal widths already have identical shapes: nothing is added, only the bounds unite)
        self.masked = self.padded and bool(np.any(self.feature_widths != W))
        if self.masked:
            for k, ix in enumerate(self.agent_index):
                w = ix.size
                pad = np.full(W - w, self.zero, dtype=np.intp)
                mask = np.array([self.one] * w + [self.zero] * (W - w), dtype=np.intp)
                self.agent_index[k] = np.concatenate([ix, pad, mask])
                self.agent_layout[k]["obs_mask"] = slice(W, 2 * W)
        self.all_index = np.concatenate(self.agent_index)
        #: true observation width of every agent (K,) and the padded width D
        self.widths = np.array([ix.size for ix in self.agent_index], dtype=np.intp)
        self.obs_dim = int(self.widths.max()) if len(self.widths) else 0
        #: (K, D) gather of the padded per-agent observations (padding -> the constant 0)
        self.padded_index = np.full((len(self.agent_index), self.obs_dim), self.zero, dtype=np.intp)
        for k, ix in enumerate(self.agent_index):
            self.padded_index[k, :ix.size] = ix
        #: positions of the true entries in the flattened (K * D) padded observations, agent-major:
        #: ``padded.reshape(-1)[concat_index]`` is the agents' observations concatenated
        self.concat_index = np.concatenate([k * self.obs_dim + np.arange(w) for k, w in enumerate(self.widths)]) \
            .astype(np.intp) if len(self.widths) else np.zeros(0, dtype=np.intp)
        #: every agent observes ``obs_dim`` values: the padded rows are already the concatenation
        self.uniform = bool(np.all(self.widths == self.obs_dim))

    def state_index(self, has_reference: bool):
        """Gather of the global state ``(x, x_r if tracking, xhat_0..xhat_{N-1}, v)`` from ``f`` and its
        ``{component: slice}`` layout."""
        n, N = self.n, self.N
        parts, lay, pos = [np.arange(self.x.start, self.x.stop)], {"x": slice(0, n)}, n
        if has_reference:
            parts.append(np.arange(self.x_r.start, self.x_r.stop))
            lay["x_r"] = slice(pos, pos + n)
            pos += n
        parts.append(np.arange(self.xhat.start, self.xhat.stop))
        lay["estimates"] = slice(pos, pos + N * n)
        pos += N * n
        if self.m_v:
            parts.append(np.arange(self.v.start, self.v.stop))
            lay["v"] = slice(pos, pos + self.m_v)
            pos += self.m_v
        return np.concatenate(parts).astype(np.intp), lay

    def offsets(self, p_i) -> np.ndarray:
        """Start offsets ``(y, xhat, x, x_r, gamma, gamma_s, v, r, time, e)`` followed by the
        output sizes ``p_i`` (the ``off`` argument of the feature kernel)."""
        return np.array([self.y.start, self.xhat.start, self.x.start, self.x_r.start, self.gamma.start,
                         self.gamma_s.start, self.v.start, self.r.start, self.time.start, self.e.start]
                        + list(p_i), dtype=np.int64)

    def fault_offsets(self) -> np.ndarray:
        """Start offsets ``(xhat_rx, nbr_rx, co_rx, oo_rx)`` of the received quantities (faults only)."""
        return np.array([self.xhat_rx.start, self.nbr_rx.start, self.co_rx.start, self.oo_rx.start], dtype=np.int64)

    def bounds(self, k: int, dtype):
        """``(low, high)`` of agent ``k``'s observation (mask entries in [0, 1], the rest unbounded).

        Padded layouts: the same bounds for every agent, the element-wise union over the agents
        of their own bounds, padding entries counted as exactly 0 (so every agent's padded
        observation lies in it); ``obs_mask`` in [0, 1].
        """
        if not self.padded:
            return self._own_bounds(k, dtype)
        W = int(self.feature_widths.max())
        D = 2 * W if self.masked else W
        low = np.full(D, np.inf, dtype=dtype)
        high = np.full(D, -np.inf, dtype=dtype)
        for j, w in enumerate(self.feature_widths):
            lo, hi = self._own_bounds(j, dtype)
            np.minimum(low[:w], lo, out=low[:w])
            np.maximum(high[:w], hi, out=high[:w])
            np.minimum(low[w:W], 0, out=low[w:W])
            np.maximum(high[w:W], 0, out=high[w:W])
        low[W:], high[W:] = 0.0, 1.0
        return low, high

    def _own_bounds(self, k: int, dtype):
        L = int(self.feature_widths[k])
        low = np.full(L, -np.inf, dtype=dtype)
        high = np.full(L, np.inf, dtype=dtype)
        lay = self.agent_layout[k]
        for c in ("mask", "received"):
            if c in lay:
                low[lay[c]] = 0.0
                high[lay[c]] = 1.0
        if "time" in lay:
            low[lay["time"]] = 0.0
        return low, high
