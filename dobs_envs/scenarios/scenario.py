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
from ..linalg.validation import as_array, as_float, as_int, as_symmetric
from ..sim.state import SimParams
from .composition import embed_block
from .signals import Sinusoids

__all__ = ["Scenario", "CONTROLLERS"]

#: Controllers a scenario can name as its paper reference (see dobs_envs.control.laws).
CONTROLLERS = ("open_loop", "feedback", "tracking", "sliding_mode", "adaptive_sliding_mode")


def _ro(a, name, shape=None, ndim=None):
    """Validated read-only float64 copy (:func:`~dobs_envs.linalg.validation.as_array`)."""
    arr = as_array(a, f"Scenario.{name}", shape=shape, ndim=ndim)
    arr.flags.writeable = False
    return arr


def _index(v, name) -> int:
    """A 0-based index: an integer (``bool``, non-integral or non-finite floats, strings are rejected)."""
    return as_int(v, f"Scenario.{name} (an integer index)")


def _sym(M: np.ndarray, name: str, definite: bool) -> np.ndarray:
    """Check that the read-only ``M`` is symmetric PSD (PD if ``definite``); returns ``M`` itself."""
    as_symmetric(M, M.shape[0], f"Scenario.{name}", definite=definite)
    return M


def _scalar(v, name) -> float:
    """A finite real number (bool, complex, strings, NaN/inf, beyond-float integers refused)."""
    return as_float(v, f"Scenario.{name}")


@dataclass(frozen=True, eq=False)
class Scenario:
    """A closed-loop system of the suite (see module docstring).

    Node and channel indices are 0-based. ``channels[k]`` is the ``(n, m_k)``
    input matrix of controller node ``k``; the stacked input is
    ``u = col(u^0, ..., u^{K-1})`` with ``B = [B^0 ... B^{K-1}]``.

    Parameters
    ----------
    name : str
        Non-empty identifier.
    A : array_like, shape (n, n)
        Plant matrix of eq. (LTIsys).
    channels : sequence of array_like, each shape (n, m_k)
        Controller input channels ``B^k`` of eq. (Busplit); a 1-D entry of
        length ``n`` is one column.
    C : sequence of array_like, each shape (p_i, n)
        Observer outputs ``y_i = C_i x`` (eq. localmeasure); full row rank as
        the paper requires (a 1-D entry is one row).
    known : sequence of sequences of int
        ``known[i]``: the channels whose inputs node ``i`` receives (its ``u_i``
        of eq. splitinput); a bare int means one channel. Duplicates are rejected.
    graph : Graph or array_like, shape (N, N)
        O-O graph (Section commugraph); connectivity (Assumption 5) is checked by
        the design.
    links : sequence of int, length K
        C-O links: controller ``k`` uses ``xhat_{links[k]}`` (eq. linearfeedback).
    x0 : array_like, shape (n,)
        Default initial plant state.
    B_v, exosystem, v0 : array_like, shapes (n, m_v), (m_v, m_v), (m_v,), optional
        Unknown input ``B_v v`` with ``v' = S v`` (NE3).
    K : array_like, shape (m, n), optional
        Stacked feedback gains ``K = col(K^k)``.
    P : array_like, shape (n, n), optional
        Sliding-mode matrix of eqs. (centralsliding)/(slidingfeedback).
    reference, prescribed_input : Sinusoids or dict, optional, size m
        ``r^k`` of eq. (refxdy) / NE1's open-loop inputs.
    x_r0 : array_like, shape (n,), optional
        Reference-model initial state.
    controller : str
        One of :data:`CONTROLLERS`.
    Q, R : array_like, shapes (n, n) symmetric PSD, (m, m) symmetric PD, optional
        Team cost weights (default identities).
    gamma0, ..., epsilon : float
        Adaptive-law constants of eqs. (gammaiis), (gagasbeta), (adlawbeta), (hepsfunc).
    mas_agents : sequence of (A_i, B_i, C_i), optional
        Heterogeneous-MAS form (eq. HMAS) designed with eq. (obidynamicMAS);
        must agree with ``A = diag(A_i)``, ``C[i] = [0 C_i 0]`` and
        ``[channels[k] for k in known[i]] = [0 B_i^T 0]^T``.
    mas_shift : float
        Shift ``s`` of the agents' observer AREs (NE1: 0.2).
    x0_scale : float, optional
        Half-width ``s`` of the initial-state distribution ``U[-s, s]^n`` that
        environments may use to randomise resets (:meth:`sample_x0`); ``None``
        means every episode starts from ``x0``.
    t_end, dt : float
        Horizon and Euler step (s).
    description : str
    metadata : dict
        Free-form (copied; e.g. the rendezvous task stores its position indices).
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
    # additive (v0.2): initial-state distribution for randomised resets
    x0_scale: Optional[float] = None

    # ------------------------------------------------------------------ validation
    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"Scenario.name must be a non-empty string, got {self.name!r}")
        if not isinstance(self.description, str):
            raise ValueError(f"Scenario.description must be a string, got {type(self.description).__name__}")
        if not isinstance(self.metadata, dict):
            raise ValueError(f"Scenario.metadata must be a dict, got {type(self.metadata).__name__}")
        set_("metadata", dict(self.metadata))  # never share the caller's dict
        A = _ro(self.A, "A", ndim=2)
        n = A.shape[0]
        if A.shape != (n, n) or n < 1:
            raise ValueError(f"Scenario.A must be square (n, n) with n >= 1, got shape {A.shape}")
        set_("A", A)
        try:
            raw_chans = list(self.channels)
        except TypeError:
            raise ValueError("Scenario.channels must be a sequence of (n, m_k) input matrices B^k") from None
        chans = []
        for k, b in enumerate(raw_chans):
            b = _ro(b, f"channels[{k}]")
            if b.ndim == 1:
                if b.shape[0] != n:
                    raise ValueError(f"Scenario.channels[{k}] given as a vector must have length n = {n}, got {b.shape[0]}")
                b = _ro(b.reshape(n, 1), f"channels[{k}]")
            if b.ndim != 2 or b.shape[0] != n or b.shape[1] < 1:
                raise ValueError(f"Scenario.channels[{k}] must have shape ({n}, m_k>=1), got {b.shape}")
            chans.append(b)
        if not chans:
            raise ValueError("Scenario.channels must contain at least one input channel B^k")
        chans = tuple(chans)
        set_("channels", chans)
        try:
            raw_C = list(self.C)
        except TypeError:
            raise ValueError("Scenario.C must be a sequence of (p_i, n) output matrices C_i") from None
        Cs = []
        for i, c in enumerate(raw_C):
            c = _ro(c, f"C[{i}]")
            c = _ro(np.atleast_2d(c), f"C[{i}]", ndim=2)
            if c.shape[1] != n:
                raise ValueError(f"Scenario.C[{i}] must have n = {n} columns, got shape {c.shape}")
            if c.shape[0] and np.linalg.matrix_rank(c) < c.shape[0]:
                raise ValueError(
                    f"Scenario.C[{i}] must have full row rank (eq. localmeasure), got rank "
                    f"{np.linalg.matrix_rank(c)} < {c.shape[0]} rows; drop the redundant rows"
                )
            Cs.append(c)
        if not Cs:
            raise ValueError("Scenario.C must contain at least one observer node")
        Cs = tuple(Cs)
        set_("C", Cs)
        N, K = len(Cs), len(chans)
        try:
            raw_known = list(self.known)
        except TypeError:
            raise ValueError("Scenario.known must list, per observer node, the channels it knows") from None
        if len(raw_known) != N:
            raise ValueError(f"Scenario.known must list the known channels of each of the {N} observer nodes, got {len(raw_known)} entries")
        known = []
        for i, kn in enumerate(raw_known):
            kn = (kn,) if np.ndim(kn) == 0 else tuple(kn)
            kn = tuple(_index(k, f"known[{i}]") for k in kn)
            bad = [k for k in kn if not 0 <= k < K]
            if bad:
                raise ValueError(f"Scenario.known[{i}] refers to channels {bad}; valid channel indices are 0..{K - 1}")
            if len(set(kn)) != len(kn):
                raise ValueError(f"Scenario.known[{i}] lists a channel twice: {kn}")
            known.append(kn)
        known = tuple(known)
        set_("known", known)
        try:
            g = as_graph(self.graph)
        except ValueError as exc:
            raise ValueError(f"Scenario.graph: {exc}") from None
        if g.n_nodes != N:
            raise ValueError(f"Scenario.graph has {g.n_nodes} nodes but there are {N} observer nodes (len(C))")
        set_("graph", g)
        try:
            raw_links = list(self.links)
        except TypeError:
            raise ValueError("Scenario.links must be a sequence of observer-node indices, one per controller node") from None
        links = tuple(_index(l, f"links[{k}]") for k, l in enumerate(raw_links))
        if len(links) != K:
            raise ValueError(f"Scenario.links must give, for each of the {K} controller nodes, the observer node whose estimate it uses; got {len(links)}")
        bad = [(k, l) for k, l in enumerate(links) if not 0 <= l < N]
        if bad:
            raise ValueError(f"Scenario.links[{bad[0][0]}] = {bad[0][1]} is not an observer node; valid nodes are 0..{N - 1} (links = {links})")
        set_("links", links)
        set_("x0", _ro(self.x0, "x0", shape=(n,)))
        m = sum(b.shape[1] for b in chans)
        if self.B_v is None:
            B_v = np.zeros((n, 0))
        else:
            B_v = _ro(self.B_v, "B_v")
            if B_v.ndim == 1 and B_v.shape[0] == n:
                B_v = B_v.reshape(n, 1)
            if B_v.ndim != 2 or B_v.shape[0] != n:
                raise ValueError(f"Scenario.B_v must have shape ({n}, m_v), got {B_v.shape}")
        set_("B_v", _ro(B_v, "B_v", shape=(n, B_v.shape[1])))
        m_v = B_v.shape[1]
        if self.exosystem is not None:
            set_("exosystem", _ro(self.exosystem, "exosystem", shape=(m_v, m_v)))
        set_("v0", _ro(np.zeros(m_v) if self.v0 is None else self.v0, "v0", shape=(m_v,)))
        if self.K is not None:
            set_("K", _ro(self.K, "K", shape=(m, n)))
        if self.P is not None:
            set_("P", _sym(_ro(self.P, "P", shape=(n, n)), "P", definite=True))
        if self.x_r0 is not None:
            set_("x_r0", _ro(self.x_r0, "x_r0", shape=(n,)))
        for sig_name in ("reference", "prescribed_input"):
            sig = getattr(self, sig_name)
            if sig is not None:
                if isinstance(sig, dict):
                    try:
                        sig = Sinusoids(**sig)
                    except TypeError as exc:
                        raise ValueError(f"Scenario.{sig_name}: a dict needs the keys amplitude, frequency, phase ({exc})") from None
                    except ValueError as exc:
                        raise ValueError(f"Scenario.{sig_name}: {exc}") from None
                if not isinstance(sig, Sinusoids):
                    raise ValueError(f"Scenario.{sig_name} must be a Sinusoids or a dict, got {type(sig).__name__}")
                if sig.size != m:
                    raise ValueError(f"Scenario.{sig_name} must have {m} components (one per control input), got {sig.size}")
                set_(sig_name, sig)
        set_("Q", _sym(_ro(np.eye(n) if self.Q is None else self.Q, "Q", shape=(n, n)), "Q", definite=False))
        set_("R", _sym(_ro(np.eye(m) if self.R is None else self.R, "R", shape=(m, m)), "R", definite=True))
        if self.controller not in CONTROLLERS:
            raise ValueError(f"Scenario.controller must be one of {CONTROLLERS}, got {self.controller!r}")
        if self.controller in ("feedback", "tracking", "sliding_mode", "adaptive_sliding_mode") and self.K is None:
            raise ValueError(f"Scenario.controller={self.controller!r} needs the feedback gain K")
        if self.controller in ("sliding_mode", "adaptive_sliding_mode") and self.P is None:
            raise ValueError(f"Scenario.controller={self.controller!r} needs the sliding-mode matrix P")
        if self.controller == "tracking" and self.reference is None:
            raise ValueError("Scenario.controller='tracking' needs a reference signal r")
        for name in ("gamma0", "gamma_s0", "phi", "phi_s", "sigma", "sigma_s", "beta0", "sigma_beta", "phi_beta"):
            v = _scalar(getattr(self, name), name)
            if not v >= 0:
                raise ValueError(f"Scenario.{name} must be finite and >= 0, got {v}")
            set_(name, v)
        for name in ("epsilon", "t_end", "dt"):
            v = _scalar(getattr(self, name), name)
            if not v > 0:
                raise ValueError(f"Scenario.{name} must be finite and > 0, got {v}")
            set_(name, v)
        v = _scalar(self.mas_shift, "mas_shift")
        if not v >= 0:
            raise ValueError(f"Scenario.mas_shift must be finite and >= 0, got {v}")
        set_("mas_shift", v)
        if self.x0_scale is not None:
            v = _scalar(self.x0_scale, "x0_scale")
            if not v >= 0:
                raise ValueError(f"Scenario.x0_scale must be finite and >= 0 (or None), got {v}")
            set_("x0_scale", v)
        if self.mas_agents is not None:
            set_("mas_agents", self._check_mas_agents())

    def _check_mas_agents(self) -> tuple:
        """Validate the agent blocks of eq. (HMAS) against ``A``, ``C``, ``channels``, ``known``."""
        try:
            raw = list(self.mas_agents)
        except TypeError:
            raise ValueError("Scenario.mas_agents must be a sequence of (A_i, B_i, C_i) triples") from None
        N, n = self.n_observers, self.n_states
        if len(raw) != N:
            raise ValueError(f"Scenario.mas_agents has {len(raw)} agents but there are {N} observer nodes (one per agent)")
        agents, offset = [], 0
        for i, ag in enumerate(raw):
            try:
                Ai, Bi, Ci = ag
            except (TypeError, ValueError):
                raise ValueError(f"Scenario.mas_agents[{i}] must be a triple (A_i, B_i, C_i)") from None
            Ai = _ro(np.atleast_2d(Ai), f"mas_agents[{i}].A", ndim=2)
            ni = Ai.shape[0]
            if Ai.shape != (ni, ni):
                raise ValueError(f"Scenario.mas_agents[{i}].A must be square, got shape {Ai.shape}")
            Bi = _ro(Bi, f"mas_agents[{i}].B")
            Bi = _ro(Bi.reshape(ni, -1) if Bi.ndim < 2 else Bi, f"mas_agents[{i}].B", ndim=2)
            Ci = _ro(np.atleast_2d(Ci), f"mas_agents[{i}].C", ndim=2)
            if Bi.shape[0] != ni:
                raise ValueError(f"Scenario.mas_agents[{i}].B must have {ni} rows, got shape {Bi.shape}")
            if Ci.shape[1] != ni:
                raise ValueError(f"Scenario.mas_agents[{i}].C must have {ni} columns, got shape {Ci.shape}")
            if offset + ni > n:
                raise ValueError(f"Scenario.mas_agents: the agent state dimensions exceed n = {n}")
            tol = dict(rtol=1e-12, atol=1e-12)
            blk = self.A[offset:offset + ni, offset:offset + ni]
            off = self.A[offset:offset + ni].copy()
            off[:, offset:offset + ni] = 0.0
            if not (np.allclose(blk, Ai, **tol) and not np.any(off)):
                raise ValueError(f"Scenario.mas_agents[{i}].A does not match Scenario.A: A must be diag(A_1, ..., A_N) (eq. HMAS)")
            Ce = embed_block(Ci, offset, n, axis=1)
            if self.C[i].shape != Ce.shape or not np.allclose(self.C[i], Ce, **tol):
                raise ValueError(f"Scenario.C[{i}] must equal [0 C_{i} 0] of mas_agents[{i}] (eq. HMAS)")
            Bk = np.hstack([self.channels[k] for k in self.known[i]]) if self.known[i] else np.zeros((n, 0))
            if Bk.shape != (n, Bi.shape[1]) or not np.allclose(Bk, embed_block(Bi, offset, n, axis=0), **tol):
                raise ValueError(
                    f"Scenario.known[{i}] / channels: the channels known by agent {i} must stack to "
                    f"[0 B_{i}^T 0]^T of mas_agents[{i}] (eq. HMAS: agent i knows exactly its own input)"
                )
            agents.append((Ai, Bi, Ci))
            offset += ni
        if offset != n:
            raise ValueError(f"Scenario.mas_agents: the agent state dimensions sum to {offset}, but n = {n}")
        return tuple(agents)

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

    def sample_x0(self, rng: np.random.Generator | None = None, batch: int | None = None) -> np.ndarray:
        """Initial plant state(s) for an episode reset.

        With ``x0_scale = None`` this is ``x0`` (copied). Otherwise each state
        is drawn i.i.d. ``U[-x0_scale, x0_scale]^n`` from ``rng`` (required).

        Returns
        -------
        ndarray, shape (n,) or (batch, n)
        """
        shape = (self.n_states,) if batch is None else (int(batch), self.n_states)
        if self.x0_scale is None:
            return np.broadcast_to(self.x0, shape).copy()
        if rng is None:
            raise ValueError(f"Scenario {self.name!r} randomises x0 (x0_scale = {self.x0_scale:g}); pass a numpy Generator rng")
        return rng.uniform(-self.x0_scale, self.x0_scale, size=shape)

    def equals(self, other: "Scenario", *, check_text: bool = True) -> bool:
        """Field-by-field equality (arrays exactly equal; graphs by adjacency).

        ``check_text=False`` ignores ``name``, ``description`` and ``metadata``.
        """
        if not isinstance(other, Scenario):
            return False
        return not self.differences(other, check_text=check_text)

    def differences(self, other: "Scenario", *, check_text: bool = True) -> list:
        """Names of the fields in which ``self`` and ``other`` differ (see :meth:`equals`)."""
        out = []
        text = ("name", "description", "metadata")
        for f in fields(self):
            if not check_text and f.name in text:
                continue
            a, b = getattr(self, f.name), getattr(other, f.name)
            if not _field_equal(a, b):
                out.append(f.name)
        return out


def _field_equal(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and bool(np.array_equal(a, b))
    if isinstance(a, (tuple, list)) and isinstance(b, (tuple, list)):
        return len(a) == len(b) and all(_field_equal(x, y) for x, y in zip(a, b))
    return bool(a == b)
