"""Communication faults of the observer network (issue 23): the user-facing :class:`Faults` option.

The paper assumes ideal links: every observer node sees its neighbours' current estimates in the
consensus term of eq. (zidynamic) (``d_i = sum_j a_ij (xhat_i - xhat_j)``, eq. (H_idefine)), every
controller node its observer node's current estimate (Section commugraph: O-O and C-O links),
the graph is fixed and connected (Assumption ooconnected) and ``y_i = C_i x`` is exact (eq.
(localmeasure)). :class:`Faults` lists the departures from that, with the same keys everywhere
(``faults={"oo_period": 0.05, "oo_loss": 0.1, ...}`` or ``Faults(oo_period=0.05, ...)``).

Semantics (``dt`` the Euler step, ``T = dt * substeps`` the control period; every random draw is
made per copy from its seed by :mod:`.fault_rng`, so a copy's faults depend on its seed only):

``oo_period`` (seconds or None)
    O-O exchange period ``h``. Node ``j`` broadcasts its estimate ``xhat_j`` at the Euler grid
    instants ``s dt`` with ``s`` a multiple of ``h / dt`` (``s`` counts Euler steps from the copy's
    reset, so broadcasts need not fall on control-period boundaries), and node ``i`` holds the
    last copy ``r_ij`` it received between broadcasts: ``d_i = sum_j a_ij (xhat_i - r_ij)`` with
    its own estimate ``xhat_i`` current. Must be a positive integer multiple of ``dt`` (checked
    where ``dt`` is known: :func:`~dobs_envs.sim.fault_state.fault_args`). ``None``: continuous
    exchange, today's model -- ``r_ij`` is ``xhat_j`` at every evaluation of the observers'
    right-hand side (every Euler step and every shortened step of a split Euler step, see
    "Stable steps" in :mod:`.period_kernel`); ``oo_period = dt`` differs from ``None`` only in
    split Euler steps (there it holds the values of the grid instant).
``oo_loss`` (probability in [0, 1])
    Each directed O-O link ``j -> i`` (each undirected edge is two links) loses every packet of a
    control period with this probability, drawn once per control period and link (Bernoulli,
    independent across links, periods and copies). A lost packet leaves ``r_ij`` at the last
    value received (the receiver uses the last estimate it got, which is what a node holding a
    buffer does); at reset every link holds the sender's initial estimate (as if received at t=0).
``oo_burst`` (mapping or None)
    Gilbert-Elliott bursts instead of ``oo_loss`` (the two are exclusive: a constant background
    loss is ``loss_good``). Keys ``p_good_bad``, ``p_bad_good`` (transition probabilities per
    control period), ``loss_good`` (default 0) and ``loss_bad`` (default 1): loss probabilities
    in each state. Each directed link has its own two-state chain; its state is drawn from the
    stationary distribution (``P(bad) = p_good_bad / (p_good_bad + p_bad_good)``, 0 if both are
    0) for the first control period and makes one transition at the start of every following
    period, then the period's loss is drawn with the state's probability. Long-run loss rate
    ``P(bad) loss_bad + (1 - P(bad)) loss_good`` (:attr:`Burst.loss_rate`).
``oo_delay`` (integer >= 0, control periods)
    What arrives at a broadcast instant ``t`` is the sender's estimate snapshotted at the latest
    broadcast instant ``<= t - oo_delay T``; before the episode's start (``t < oo_delay T``) the
    snapshot of ``t = 0``. Loss applies to the arrival (the period in which the packet arrives).
    The ring of snapshots holds ``ceil(oo_delay substeps / (h / dt)) + 1`` estimates per node
    and copy (``h = dt`` for ``oo_period=None``: 501 at ``oo_delay = 10``, 50 substeps).
``co_loss`` (probability), ``co_delay`` (integer >= 0, control periods)
    The C-O link from an observer node to a controller node, at control-period boundaries (where
    a controller reads an estimate): the estimate sent at boundary ``k`` arrives at boundary
    ``k + co_delay`` (before ``co_delay`` periods have passed: the ``t = 0`` estimate), and is lost
    with probability ``co_loss`` (per period and C-O link); the controller then holds the last
    estimate it received (at reset: the ``t = 0`` estimate).
    (:func:`~dobs_envs.sim.fault_state.co_link_numpy`.)
``switching`` (mapping or None)
    The O-O graph follows a Markov chain over a list of graphs (same ``N`` nodes, undirected,
    disconnected ones allowed, so Assumption ooconnected may hold only on average), stepped once
    per control period per copy (at the start of each period after the first). Keys: ``graphs``
    (list of ``(N, N)`` adjacency matrices or :class:`~dobs_envs.graphs.Graph`), exactly one of
    ``transition`` (row-stochastic ``(G, G)`` matrix: row ``g`` the probabilities of the next
    graph from ``g``) and ``rate`` (switches per second: in each period the chain leaves its graph
    with probability ``1 - exp(-rate T)``, to one of the other graphs uniformly; needed unless
    ``G = 1``), and ``initial`` (the graph of the first period, default 0). The scenario's own
    graph is then not used (include it in ``graphs`` if wanted). A link absent from the active
    graph contributes nothing to ``d_i`` and receives nothing (it keeps its last value).
``measurement_noise`` (standard deviation >= 0)
    Additive Gaussian noise on every output ``y_i`` (every row of every ``C_i``; zero padding
    rows excepted), drawn once per control period, copy, node and row at the period's start and
    held over the period (zero-order hold, like the input). It enters the observers through
    eqs. (hatxieq) and (zidynamic) and the estimates the controllers are sent.

``Faults()`` (every rate 0, ``oo_period=None``) is the ideal exchange: the faulted simulation
then equals the unfaulted one up to rounding (``tests/test_faults_engine.py``); ``faults=None``
runs no fault code at all.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field, fields
import math

import numpy as np

from ..graphs import Graph
from ..linalg.validation import as_float, as_int, as_square

__all__ = ["Faults", "Burst", "Switching", "FAULT_KEYS", "MAX_DELAY", "ROW_SUM_TOL"]

#: largest ``oo_delay`` / ``co_delay`` (control periods): bounds the snapshot rings' memory
MAX_DELAY = 1000
#: tolerance of the row sums of a switching ``transition`` matrix (``|sum - 1| <= ROW_SUM_TOL``)
ROW_SUM_TOL = 1e-9


def _keys_of(cls) -> list:
    return [f.name for f in fields(cls)]


def _from_mapping(cls, value, name: str):
    """``cls(**value)`` for a mapping with only ``cls``'s keys (``TypeError`` naming the first unknown one)."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a mapping with keys {_keys_of(cls)}, got {type(value).__name__} {value!r}")
    valid = _keys_of(cls)
    for k in value:
        if k not in valid:
            raise TypeError(f"{name}: unexpected key {k!r}; valid keys are: {valid}")
    for f in fields(cls):
        if f.default is MISSING and f.name not in value:
            raise TypeError(f"{name}: missing key {f.name!r} (keys: {valid})")
    return cls(**dict(value))


@dataclass(frozen=True)
class Burst:
    """Gilbert-Elliott model of one directed O-O link (the ``oo_burst`` key; module doc).

    Attributes
    ----------
    p_good_bad, p_bad_good : float in [0, 1]
        Transition probabilities per control period (good -> bad, bad -> good).
    loss_good, loss_bad : float in [0, 1]
        Loss probability of a period in each state (defaults 0 and 1: Gilbert's model).
    """

    p_good_bad: float
    p_bad_good: float
    loss_good: float = 0.0
    loss_bad: float = 1.0

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, as_float(getattr(self, f.name), f"faults: oo_burst {f.name}",
                                                      minimum=0.0, maximum=1.0))

    @property
    def stationary_bad(self) -> float:
        """Long-run probability of the bad state, ``p_good_bad / (p_good_bad + p_bad_good)`` (0 if both are 0)."""
        s = self.p_good_bad + self.p_bad_good
        return self.p_good_bad / s if s > 0 else 0.0

    @property
    def loss_rate(self) -> float:
        """Long-run fraction of lost periods, ``P(bad) loss_bad + (1 - P(bad)) loss_good``."""
        pb = self.stationary_bad
        return pb * self.loss_bad + (1.0 - pb) * self.loss_good

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True, eq=False)
class Switching:
    """Markov chain over O-O graphs (the ``switching`` key; module doc).

    Attributes
    ----------
    graphs : tuple of (N, N) read-only arrays
        Undirected weighted adjacency matrices (validated as :class:`~dobs_envs.graphs.Graph`).
    transition : (G, G) read-only array or None
        Row-stochastic transition matrix per control period.
    rate : float or None
        Switching rate (1/s), uniform jumps to the other graphs (:meth:`transition_matrix`).
    initial : int
        Graph of the first control period.
    """

    graphs: tuple
    transition: np.ndarray | None = None
    rate: float | None = None
    initial: int = 0

    def __post_init__(self):
        name = "faults: switching"
        gs = self.graphs
        if isinstance(gs, (np.ndarray, Graph)) or not isinstance(gs, (list, tuple)) or len(gs) == 0:
            raise ValueError(f"{name} graphs must be a non-empty list of (N, N) adjacency matrices or Graphs, "
                             f"got {type(gs).__name__}")
        mats = []
        for k, g in enumerate(gs):
            try:
                a = g.adjacency if isinstance(g, Graph) else Graph(g).adjacency
            except ValueError as exc:
                raise ValueError(f"{name} graphs[{k}]: {exc}") from None
            if mats and a.shape != mats[0].shape:
                raise ValueError(f"{name} graphs[{k}] has {a.shape[0]} nodes, graphs[0] has {mats[0].shape[0]} "
                                 "(all graphs are over the same N nodes)")
            a = np.array(a, dtype=np.float64)
            a.flags.writeable = False
            mats.append(a)
        object.__setattr__(self, "graphs", tuple(mats))
        G = len(mats)
        if self.transition is not None and self.rate is not None:
            raise ValueError(f"{name}: give either transition or rate, not both")
        if self.transition is not None:
            P = as_square(self.transition, f"{name} transition")
            if P.shape != (G, G):
                raise ValueError(f"{name} transition must have shape ({G}, {G}) (one row and column per graph), "
                                 f"got {P.shape}")
            if np.any(P < 0) or np.any(np.abs(P.sum(axis=1) - 1.0) > ROW_SUM_TOL):
                raise ValueError(f"{name} transition must be row-stochastic (entries >= 0, every row summing to 1), "
                                 f"got row sums {P.sum(axis=1)}")
            P.flags.writeable = False
            object.__setattr__(self, "transition", P)
        elif self.rate is not None:
            object.__setattr__(self, "rate", as_float(self.rate, f"{name} rate", minimum=0.0))
        elif G > 1:
            raise ValueError(f"{name}: {G} graphs need a transition matrix or a switching rate")
        object.__setattr__(self, "initial", as_int(self.initial, f"{name} initial", minimum=0, maximum=G - 1))

    @property
    def n_graphs(self) -> int:
        return len(self.graphs)

    @property
    def n_nodes(self) -> int:
        return self.graphs[0].shape[0]

    def transition_matrix(self, period: float) -> np.ndarray:
        """``(G, G)`` transition matrix per control period of length ``period`` (s): ``transition``, or from
        ``rate``: stay with ``exp(-rate period)``, else one of the other ``G - 1`` graphs uniformly."""
        G = self.n_graphs
        if self.transition is not None:
            return np.array(self.transition)
        if G == 1:
            return np.ones((1, 1))
        leave = -math.expm1(-(self.rate or 0.0) * period)
        P = np.full((G, G), leave / (G - 1))
        np.fill_diagonal(P, 1.0 - leave)
        return P

    def to_dict(self) -> dict:
        out = {"graphs": [g.tolist() for g in self.graphs]}
        if self.transition is not None:
            out["transition"] = self.transition.tolist()
        if self.rate is not None:
            out["rate"] = self.rate
        out["initial"] = self.initial
        return out

    def __eq__(self, other):
        if not isinstance(other, Switching):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def __hash__(self):
        return hash(repr(self.to_dict()))


@dataclass(frozen=True)
class Faults:
    """Communication faults and sensor noise of the observer network (module doc for the semantics).

    Attributes
    ----------
    oo_period : float or None
        O-O exchange period (s), a positive integer multiple of ``dt``; ``None``: continuous.
    oo_loss : float in [0, 1]
        Loss probability per directed O-O link and control period (Bernoulli).
    oo_burst : Burst or mapping or None
        Gilbert-Elliott losses (keys ``p_good_bad``, ``p_bad_good``, ``loss_good``, ``loss_bad``);
        exclusive with ``oo_loss > 0``.
    oo_delay : int >= 0
        O-O delay in control periods.
    co_loss : float in [0, 1]
        Loss probability per C-O link and control period.
    co_delay : int >= 0
        C-O delay in control periods.
    switching : Switching or mapping or None
        Markov-switching O-O graph (keys ``graphs``, ``transition`` or ``rate``, ``initial``).
    measurement_noise : float >= 0
        Standard deviation of the additive Gaussian noise on every ``y_i`` (held over a period).

    ``Faults()`` is the ideal exchange (:attr:`is_ideal`). Build one from a user's value with
    :meth:`from_value`; :meth:`to_dict` gives the keys back (JSON-ready).
    """

    oo_period: float | None = None
    oo_loss: float = 0.0
    oo_burst: Burst | None = None
    oo_delay: int = 0
    co_loss: float = 0.0
    co_delay: int = 0
    switching: Switching | None = field(default=None)
    measurement_noise: float = 0.0

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        if self.oo_period is not None:
            set_("oo_period", as_float(self.oo_period, "faults: oo_period", positive=True))
        set_("oo_loss", as_float(self.oo_loss, "faults: oo_loss", minimum=0.0, maximum=1.0))
        if self.oo_burst is not None and not isinstance(self.oo_burst, Burst):
            set_("oo_burst", _from_mapping(Burst, self.oo_burst, "faults: oo_burst"))
        if self.oo_burst is not None and self.oo_loss > 0:
            raise ValueError("faults: oo_loss and oo_burst are exclusive (a constant background loss in the burst "
                             f"model is its loss_good), got oo_loss={self.oo_loss} and oo_burst")
        set_("oo_delay", as_int(self.oo_delay, "faults: oo_delay", minimum=0, maximum=MAX_DELAY))
        set_("co_loss", as_float(self.co_loss, "faults: co_loss", minimum=0.0, maximum=1.0))
        set_("co_delay", as_int(self.co_delay, "faults: co_delay", minimum=0, maximum=MAX_DELAY))
        if self.switching is not None and not isinstance(self.switching, Switching):
            set_("switching", _from_mapping(Switching, self.switching, "faults: switching"))
        set_("measurement_noise", as_float(self.measurement_noise, "faults: measurement_noise", minimum=0.0))

    @classmethod
    def keys(cls) -> list:
        """The user keys, in declaration order."""
        return _keys_of(cls)

    @classmethod
    def from_value(cls, value) -> "Faults | None":
        """``None`` (no faults: no fault code runs), a :class:`Faults` (returned as is) or a mapping with
        only the keys of :meth:`keys` (an unknown key raises ``TypeError`` naming it and the valid keys)."""
        if value is None or isinstance(value, Faults):
            return value
        if not isinstance(value, Mapping):
            raise ValueError(f"faults must be None, a dict with keys {cls.keys()} or a Faults, "
                             f"got {type(value).__name__} {value!r}")
        for k in value:
            if k not in cls.keys():
                raise TypeError(f"faults: unexpected key {k!r}; valid keys are: {cls.keys()}")
        return cls(**dict(value))

    @property
    def is_ideal(self) -> bool:
        """Every fault off: continuous exchange, no loss, delay, switching or noise."""
        return (self.oo_period is None and self.oo_loss == 0 and self.oo_burst is None and self.oo_delay == 0
                and self.co_loss == 0 and self.co_delay == 0 and self.switching is None
                and self.measurement_noise == 0)

    def exchange_steps(self, dt: float) -> int:
        """Euler steps per O-O exchange, ``oo_period / dt`` (1 for ``None``). ``ValueError`` naming
        ``oo_period`` unless it is a positive integer multiple of ``dt`` (to ``1e-9`` relative)."""
        if self.oo_period is None:
            return 1
        q = self.oo_period / dt
        M = round(q)
        if M < 1 or abs(q - M) > 1e-9 * max(1.0, q):
            raise ValueError(f"faults: oo_period must be a positive integer multiple of the Euler step dt = {dt:g} s, "
                             f"got {self.oo_period:g} s ({q:.6g} dt)")
        return int(M)

    def to_dict(self) -> dict:
        """The user keys and their values (nested mappings for ``oo_burst`` and ``switching``)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        if self.oo_burst is not None:
            out["oo_burst"] = self.oo_burst.to_dict()
        if self.switching is not None:
            out["switching"] = self.switching.to_dict()
        return out
