"""The :class:`Scenario`: the single place that defines a system of the suite.

A scenario holds everything the paper's framework needs (Fig. ofdobc):

- the plant (eq. LTIsys): ``A``, the controller nodes' input channels ``B^k``
  (eq. Busplit), the unknown-input matrix ``B_v`` and its exosystem ``v' = S v``;
- the observer nodes: ``C_i`` (eq. localmeasure), the channels each node knows
  (the C-O links that deliver ``u_i``, eq. splitinput) and the O-O graph;
- the C-O links delivering estimates: controller ``k`` uses ``xhat_{links[k]}``;
- gains: ``K`` (stacked ``K^k``), ``P`` (sliding mode), the adaptive-law
  constants of eqs. (gammaiis)/(gagasbeta) and the controller's (adlawbeta);
- signals: the reference command ``r`` of eq. (refxdy) or prescribed inputs;
- initial conditions and horizon.

Everything is validated in ``__post_init__`` and converted to read-only arrays;
the observer design (Lemma 2 per node, eq. barEFGB) is computed once on first
use and raises the design layer's named :class:`~dobs_envs.assumptions.AssumptionError`
when the system does not satisfy the paper's assumptions.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Optional

import numpy as np

from ..graphs import Graph, as_graph
from ..sim.state import SimParams
from .signals import Sinusoids

__all__ = ["Scenario", "CONTROLLERS"]

#: Controllers a scenario can name as its paper reference (see baselines.paper).
CONTROLLERS = ("open_loop", "feedback", "tracking", "sliding_mode", "adaptive_sliding_mode")


def _ro(a, name, shape=None, ndim=None):
    try:
        arr = np.array(a, dtype=float, copy=True)
    except (TypeError, ValueError):
        raise ValueError(f"Scenario.{name} must be a numeric array, got {type(a).__name__}") from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"Scenario.{name} must be {ndim}-D, got shape {arr.shape}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"Scenario.{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"Scenario.{name} contains NaN or inf")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class Scenario:
    """A closed-loop system of the suite (see module docstring).

    Node and channel indices are 0-based. ``channels[k]`` is the ``(n, m_k)``
    input matrix of controller node ``k``; the stacked input is
    ``u = col(u^0, ..., u^{K-1})`` with ``B = [B^0 ... B^{K-1}]``.
    """

    name: str
    A: np.ndarray
    channels: tuple
    C: tuple
    known: tuple
    graph: Graph
    links: tuple
    x0: np.ndarray
    B_v: Optional[np.ndarray] = None
    exosystem: Optional[np.ndarray] = None
    v0: Optional[np.ndarray] = None
    K: Optional[np.ndarray] = None
    P: Optional[np.ndarray] = None
    reference: Optional[Sinusoids] = None
    x_r0: Optional[np.ndarray] = None
    prescribed_input: Optional[Sinusoids] = None
    controller: str = "feedback"
    # team cost of the environments: -(e'Qe + u'Ru) * period with e = x - x_r (x_r = 0 without reference)
    Q: Optional[np.ndarray] = None
    R: Optional[np.ndarray] = None
    # observer adaptive laws, eqs. (gammaiis) / (gagasbeta)
    gamma0: float = 0.1
    gamma_s0: float = 0.1
    phi: float = 0.2
    phi_s: float = 0.5
    sigma: float = 0.0
    sigma_s: float = 0.0
    # controller adaptive law (adlawbeta) and boundary layer (hepsfunc)
    beta0: float = 0.1
    sigma_beta: float = 0.1
    phi_beta: float = 5.0
    epsilon: float = 0.2
    # heterogeneous MAS form (obidynamicMAS): agent blocks (A_i, B_i, C_i); None for the general design
    mas_agents: Optional[tuple] = None
    mas_shift: float = 0.2
    t_end: float = 20.0
    dt: float = 1e-3
    description: str = ""
    metadata: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ validation
    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        A = _ro(self.A, "A", ndim=2)
        n = A.shape[0]
        if A.shape != (n, n):
            raise ValueError(f"Scenario.A must be square, got {A.shape}")
        set_("A", A)
        chans = tuple(_ro(np.reshape(b, (n, -1)) if np.ndim(b) == 1 else b, f"channels[{k}]", ndim=2) for k, b in enumerate(self.channels))
        for k, b in enumerate(chans):
            if b.shape[0] != n or b.shape[1] < 1:
                raise ValueError(f"Scenario.channels[{k}] must have shape ({n}, m_k>=1), got {b.shape}")
        if not chans:
            raise ValueError("Scenario.channels must contain at least one input channel B^k")
        set_("channels", chans)
        Cs = tuple(_ro(np.atleast_2d(c), f"C[{i}]", ndim=2) for i, c in enumerate(self.C))
        for i, c in enumerate(Cs):
            if c.shape[1] != n:
                raise ValueError(f"Scenario.C[{i}] must have {n} columns, got shape {c.shape}")
        if not Cs:
            raise ValueError("Scenario.C must contain at least one observer node")
        set_("C", Cs)
        N, K = len(Cs), len(chans)
        known = tuple(tuple(int(k) for k in kn) for kn in self.known)
        if len(known) != N:
            raise ValueError(f"Scenario.known must list the known channels of each of the {N} observer nodes, got {len(known)} entries")
        for i, kn in enumerate(known):
            bad = [k for k in kn if not 0 <= k < K]
            if bad:
                raise ValueError(f"Scenario.known[{i}] refers to channels {bad}; valid channel indices are 0..{K - 1}")
        set_("known", known)
        g = as_graph(self.graph)
        if g.n_nodes != N:
            raise ValueError(f"Scenario.graph has {g.n_nodes} nodes but there are {N} observer nodes")
        set_("graph", g)
        links = tuple(int(l) for l in self.links)
        if len(links) != K:
            raise ValueError(f"Scenario.links must give, for each of the {K} controller nodes, the observer node whose estimate it uses; got {len(links)}")
        if any(not 0 <= l < N for l in links):
            raise ValueError(f"Scenario.links entries must be observer nodes 0..{N - 1}, got {links}")
        set_("links", links)
        set_("x0", _ro(self.x0, "x0", shape=(n,)))
        m = sum(b.shape[1] for b in chans)
        B_v = np.zeros((n, 0)) if self.B_v is None else np.reshape(np.asarray(self.B_v, dtype=float), (n, -1))
        set_("B_v", _ro(B_v, "B_v", shape=(n, B_v.shape[1])))
        m_v = B_v.shape[1]
        if self.exosystem is not None:
            set_("exosystem", _ro(self.exosystem, "exosystem", shape=(m_v, m_v)))
        set_("v0", _ro(np.zeros(m_v) if self.v0 is None else self.v0, "v0", shape=(m_v,)))
        if self.K is not None:
            set_("K", _ro(self.K, "K", shape=(m, n)))
        if self.P is not None:
            set_("P", _ro(self.P, "P", shape=(n, n)))
        if self.x_r0 is not None:
            set_("x_r0", _ro(self.x_r0, "x_r0", shape=(n,)))
        for sig_name in ("reference", "prescribed_input"):
            sig = getattr(self, sig_name)
            if sig is not None:
                if not isinstance(sig, Sinusoids):
                    sig = Sinusoids(**sig) if isinstance(sig, dict) else sig
                if sig.size != m:
                    raise ValueError(f"Scenario.{sig_name} must have {m} components (one per control input), got {sig.size}")
                set_(sig_name, sig)
        set_("Q", _ro(np.eye(n) if self.Q is None else self.Q, "Q", shape=(n, n)))
        set_("R", _ro(np.eye(m) if self.R is None else self.R, "R", shape=(m, m)))
        if self.controller not in CONTROLLERS:
            raise ValueError(f"Scenario.controller must be one of {CONTROLLERS}, got {self.controller!r}")
        if self.controller in ("feedback", "tracking", "sliding_mode", "adaptive_sliding_mode") and self.K is None:
            raise ValueError(f"Scenario.controller={self.controller!r} needs the feedback gain K")
        if self.controller in ("sliding_mode", "adaptive_sliding_mode") and self.P is None:
            raise ValueError(f"Scenario.controller={self.controller!r} needs the sliding-mode matrix P")
        if self.controller == "tracking" and self.reference is None:
            raise ValueError("Scenario.controller='tracking' needs a reference signal r")
        for name in ("gamma0", "gamma_s0", "phi", "phi_s", "sigma", "sigma_s", "beta0", "sigma_beta", "phi_beta"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"Scenario.{name} must be finite and >= 0, got {v}")
            set_(name, v)
        for name in ("epsilon", "t_end", "dt"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Scenario.{name} must be finite and > 0, got {v}")
            set_(name, v)

    # ------------------------------------------------------------------ derived
    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_observers(self) -> int:
        return len(self.C)

    @property
    def n_controllers(self) -> int:
        return len(self.channels)

    @property
    def B(self) -> np.ndarray:
        return np.hstack(self.channels)

    @property
    def channel_slices(self) -> tuple:
        out, start = [], 0
        for b in self.channels:
            out.append(slice(start, start + b.shape[1]))
            start += b.shape[1]
        return tuple(out)

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @cached_property
    def design(self):
        """The distributed-observer design (eq. barEFGB per node), computed once."""
        from ..design.observer import design_distributed_observer, design_mas_observer

        if self.mas_agents is not None:
            return design_mas_observer(self.mas_agents, self.graph, shift=self.mas_shift)
        return design_distributed_observer(
            self.A, self.channels, self.C, self.known, self.graph, B_v=self.B_v if self.B_v.shape[1] else None
        )

    def sim_params(self, *, dt: float | None = None, substeps: int = 1, ablation: bool = False) -> SimParams:
        """:class:`SimParams` of this scenario (Euler step ``dt``, ``substeps`` per control period)."""
        K_ref = self.K if self.reference is not None else None
        return SimParams.from_design(
            self.design,
            phi=self.phi, phi_s=self.phi_s, sigma=self.sigma, sigma_s=self.sigma_s,
            dt=self.dt if dt is None else dt, substeps=substeps,
            exosystem=self.exosystem, K_ref=K_ref,
        )

    def initial_state(self, params: SimParams, x0=None, batch: int = 1):
        """Initial :class:`SimState` (paper: ``z_i(0) = 0``, ``gamma(0)``, ``v(0)``, ``x_r(0)``)."""
        x0 = self.x0 if x0 is None else x0
        x0 = np.broadcast_to(np.asarray(x0, dtype=float), (batch, self.n_states)) if np.ndim(x0) == 1 else x0
        return params.initial_state(
            x0, gamma0=self.gamma0, gamma_s0=self.gamma_s0, v0=self.v0,
            x_r0=self.x_r0 if self.x_r0 is not None else np.zeros(self.n_states),
        )

    def replace(self, **changes) -> "Scenario":
        """A modified copy (validated again). Unknown field names raise ``TypeError``."""
        names = {f.name for f in fields(self)}
        unknown = set(changes) - names
        if unknown:
            raise TypeError(f"Scenario has no field(s) {sorted(unknown)}; fields are {sorted(names)}")
        return replace(self, **changes)
