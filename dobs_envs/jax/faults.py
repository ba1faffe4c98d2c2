"""Communication faults in the JAX environments: the ``faults=`` option of :mod:`dobs_envs.sim.faults`.

Every key is simulated (``oo_period``, ``oo_loss``, ``oo_burst``, ``oo_delay``, ``co_loss``, ``co_delay``,
``switching``, ``measurement_noise``), with the semantics of :mod:`dobs_envs.sim.faults`. The numpy
reference is the specification, and this module follows it part by part, for one copy (``jax.vmap``
batches it):

- :class:`FaultStructure` / :class:`FaultParams`: :class:`~dobs_envs.sim.fault_state.FaultArgs` split into
  what fixes shapes and branches (static: the links, the rings, which processes are on) and the numbers
  (a pytree: the probabilities, the graphs' weights, the noise level), so that ``jax.vmap`` runs copies
  with other loss rates;
- :class:`FaultState`: :class:`~dobs_envs.sim.fault_state.FaultState` of one copy; :func:`init_state` is
  :func:`~dobs_envs.sim.fault_state.init_fault_state`, :func:`period_draws` and :func:`oo_losses` the
  functions of the same names;
- :class:`FaultedExchange`: the O-O exchange of eq. (H_idefine) with held copies,
  ``d_i = sum_j a_ij^{g} (xhat_i - r_ij)`` (:class:`dobs_envs.sim.numpy_step._FaultedExchange`), plugged
  into :func:`dobs_envs.jax.dynamics.control_period` at the seam where the ideal exchange sits
  (``grid(j, xhat, carry)``, ``sub(xhat, carry)``, ``deg``, ``noise``);
- :func:`boundary`: what the agents receive at a control-period boundary -- the C-O link
  (:func:`~dobs_envs.sim.fault_state.co_link_numpy`) and the O-O copies held at the boundary instant
  (:func:`dobs_envs.envs.features.fault_rows`).

Random draws. The fault processes are the counter-based draws of :mod:`dobs_envs.sim.fault_rng`, a pure
function of (seed, stream, period, index) in unsigned 64-bit integers: the functions of that module are
evaluated here, unchanged, on ``jax.numpy`` arrays (:func:`_draws`), so the JAX environment draws bit for
bit the losses, graph switches, burst states and noise of the compiled core from the same fault seed
(``tests/test_jax_faults.py``). That needs 64-bit integers: **faults require** ``jax_enable_x64``
(``jax.config.update("jax_enable_x64", True)``), also when the simulation runs in float32
(``dtype="float32"`` then keeps the state in float32 and computes the draws in 64-bit integers; the noise
is rounded to float32).
"""
from __future__ import annotations

import types
from dataclasses import dataclass
from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from ..sim import fault_rng
from .operators import stack, unstack

__all__ = ["FaultStructure", "FaultParams", "FaultState", "Received", "from_fault_args", "check_x64",
           "init_state", "period_draws", "oo_losses", "next_period", "FaultedExchange", "boundary",
           "received_fraction"]

_U64 = jnp.uint64
#: the functions of :mod:`dobs_envs.sim.fault_rng` evaluated on jax.numpy arrays (:func:`_draws`)
_RNG_FUNCTIONS = ("mix64", "period_key", "uniform_at", "normal_at", "log1m_bits", "cos2pi_bits")


class _Pow2Neg:
    """``fault_rng._POW2NEG[e]`` for a traced ``e`` (the table made a ``jnp`` array where it is read, so that no
    array outlives the trace that made it)."""

    def __getitem__(self, e):
        return jnp.asarray(fault_rng._POW2NEG, dtype=jnp.float64)[e]


@lru_cache(maxsize=1)
def _draws() -> types.SimpleNamespace:
    """The counter-based generator of :mod:`dobs_envs.sim.fault_rng` on ``jax.numpy`` arrays.

    The module's functions are written once with operators that numpy, numba and ``jax.numpy`` share;
    two names they read need a JAX value: ``np.sqrt`` (``jnp.sqrt``, IEEE correctly rounded like numpy's)
    and the table ``_POW2NEG`` indexed by a traced exponent (a ``jnp`` array). The functions are rebuilt
    from their own code objects with those two names bound to the JAX values (so they call each other's
    JAX versions); nothing of the source is copied.
    """
    g = dict(vars(fault_rng))
    g["np"] = jnp
    g["_POW2NEG"] = _Pow2Neg()
    out = {}
    for name in _RNG_FUNCTIONS:
        f = getattr(fault_rng, name)
        g[name] = out[name] = types.FunctionType(f.__code__, g, name, f.__defaults__, f.__closure__)
    return types.SimpleNamespace(**out)


def check_x64() -> None:
    """Faults draw in unsigned 64-bit integers (module doc): refuse to build or trace them without x64."""
    if not jax.config.jax_enable_x64:
        raise ValueError("faults: the JAX environments draw the fault processes with 64-bit integers (the "
                         "compiled core's counter-based generator, bit for bit): call "
                         "jax.config.update('jax_enable_x64', True) first (dtype='float32' still simulates in "
                         "float32), or make the env with faults=None")


def _key(seed, stream: int, period):
    return _draws().period_key(seed, _U64(stream), period.astype(_U64))


def _uniforms(seed, stream: int, period, count: int):
    """The uniforms of the draws ``(seed, stream, period, 0 .. count-1)`` (float64, ``(count,)``)."""
    r = _draws()
    return r.uniform_at(_key(seed, stream, period), jnp.arange(count, dtype=_U64))


@dataclass(frozen=True, eq=False)
class FaultStructure:
    """The static part of :class:`~dobs_envs.sim.fault_state.FaultArgs` (shapes and branches under ``jit``).

    Attributes
    ----------
    sender, receiver (E,) : the directed O-O links ``sender[e] -> receiver[e]`` (sorted by receiver).
    co_nodes (K,) : the observer node of each C-O link (the agents' links).
    E, K, N, P, n, G : links, C-O links, nodes, output rows, states, graphs.
    substeps, exchange_steps : Euler steps per control period and between O-O broadcasts.
    continuous : ``oo_period`` None (``r_ij`` refreshed at every evaluation, also in split steps).
    lag, ring : broadcasts between a snapshot and its arrival, and the snapshots kept (``lag + 1``).
    co_delay : control periods of the C-O delay.
    switching, burst, noisy : a graph chain, Gilbert-Elliott losses, measurement noise.
    incidence (K, E), lonely (K,) : the links into each agent's node (rows scaled to sum 1) and the
        agents whose node has none (``oo_received_fraction`` is 1 there).
    """

    sender: np.ndarray
    receiver: np.ndarray
    co_nodes: np.ndarray
    E: int
    K: int
    N: int
    P: int
    n: int
    G: int
    substeps: int
    exchange_steps: int
    continuous: bool
    lag: int
    ring: int
    co_delay: int
    switching: bool
    burst: bool
    noisy: bool
    incidence: np.ndarray
    lonely: np.ndarray


@struct.dataclass
class FaultParams:
    """The numbers of the fault model (:class:`~dobs_envs.sim.fault_state.FaultArgs`, same names), a pytree.

    ``weight (G, E)``, ``degree (G, N)``, ``cum_transition (G, G)``, ``last_state (G,)``,
    ``initial_graph``; the loss probabilities ``oo_loss``, ``p_good_bad``, ``p_bad_good``, ``loss_good``,
    ``loss_bad``, ``stationary_bad``, ``co_loss``; ``noise_std`` and ``noise_mask (N, P)``. The draws
    are float64 and compared with these in float64, as in the compiled core.
    """

    weight: jax.Array
    degree: jax.Array
    cum_transition: jax.Array
    last_state: jax.Array
    initial_graph: jax.Array
    oo_loss: jax.Array
    p_good_bad: jax.Array
    p_bad_good: jax.Array
    loss_good: jax.Array
    loss_bad: jax.Array
    stationary_bad: jax.Array
    co_loss: jax.Array
    noise_std: jax.Array
    noise_mask: jax.Array


@struct.dataclass
class FaultState:
    """The fault state of one copy (:class:`~dobs_envs.sim.fault_state.FaultState`, same names and meaning).

    ``seed`` uint64, ``period`` int64, ``received (E, n)``, ``snapshots (ring, N, n)``, ``bad (E,)`` bool,
    ``graph`` int64, ``noise (N, P)``, ``co_sent (co_delay + 1, K, n)``, ``co_held (K, n)``.
    """

    seed: jax.Array
    period: jax.Array
    received: jax.Array
    snapshots: jax.Array
    bad: jax.Array
    graph: jax.Array
    noise: jax.Array
    co_sent: jax.Array
    co_held: jax.Array


class Received(struct.PyTreeNode):
    """What the agents receive at a boundary (the feature vector's ``xhat_rx | nbr_rx | co_rx | oo_rx``)."""

    xhat_rx: jax.Array  # (K, n) the estimates the controllers hold
    nbr_rx: jax.Array  # (E, n) the O-O copies held at the boundary instant
    co_rx: jax.Array  # (K,) bool: the C-O packet arrived at this boundary
    oo_rx: jax.Array  # (E,) bool: the link's value was received at this boundary


def from_fault_args(fa, co_nodes, n: int, dtype) -> tuple[FaultStructure, FaultParams]:
    """``(structure, params)`` of the resolved :class:`~dobs_envs.sim.fault_state.FaultArgs` ``fa`` (the
    compiled core's own, so that both simulate the same links and rates)."""
    check_x64()
    sender, receiver = np.asarray(fa.sender, dtype=np.intp), np.asarray(fa.receiver, dtype=np.intp)
    co_nodes = np.asarray(co_nodes, dtype=np.intp)
    N, P = np.asarray(fa.noise_mask).shape
    inc = (receiver[None, :] == co_nodes[:, None]).astype(np.float64)
    structure = FaultStructure(
        sender=sender, receiver=receiver, co_nodes=co_nodes, E=int(sender.shape[0]), K=int(co_nodes.shape[0]),
        N=int(N), P=int(P), n=int(n), G=int(np.asarray(fa.weight).shape[0]), substeps=int(fa.substeps),
        exchange_steps=int(fa.exchange_steps), continuous=bool(fa.continuous), lag=int(fa.lag), ring=int(fa.ring),
        co_delay=int(fa.co_delay), switching=bool(fa.switching), burst=bool(fa.burst),
        noisy=bool(fa.noise_std > 0), incidence=inc / np.maximum(inc.sum(axis=1, keepdims=True), 1.0),
        lonely=inc.sum(axis=1) == 0)
    f64 = lambda a: jnp.asarray(np.asarray(a, dtype=np.float64))  # noqa: E731
    params = FaultParams(
        weight=f64(fa.weight), degree=f64(fa.degree), cum_transition=f64(fa.cum_transition),
        last_state=jnp.asarray(np.asarray(fa.last_state, dtype=np.int64)),
        initial_graph=jnp.asarray(int(fa.initial_graph), dtype=jnp.int64), oo_loss=f64(fa.oo_loss),
        p_good_bad=f64(fa.p_good_bad), p_bad_good=f64(fa.p_bad_good), loss_good=f64(fa.loss_good),
        loss_bad=f64(fa.loss_bad), stationary_bad=f64(fa.stationary_bad), co_loss=f64(fa.co_loss),
        noise_std=f64(fa.noise_std), noise_mask=f64(fa.noise_mask))
    return structure, params


# ---------------------------------------------------------------------------------------- draws
def period_draws(fst: FaultStructure, fp: FaultParams, seed, period, graph_prev, bad_prev, dtype):
    """The draws of control period ``period`` (:func:`dobs_envs.sim.fault_state.period_draws`): the active
    graph, the burst states ``(E,)`` and the held measurement noise ``(N, P)`` in ``dtype``."""
    first = period == 0
    if fst.switching:
        u = _draws().uniform_at(_key(seed, fault_rng.STREAM_SWITCHING, period), _U64(0))
        cum = fp.cum_transition[graph_prev]
        nxt = jnp.sum(cum <= u * cum[-1]).astype(jnp.int64)
        nxt = jnp.minimum(nxt, fp.last_state[graph_prev])
        graph = jnp.where(first, fp.initial_graph, nxt)
    else:
        graph = jnp.zeros((), jnp.int64)
    if fst.burst:
        u = _uniforms(seed, fault_rng.STREAM_OO_BURST, period, fst.E)
        stay = jnp.where(bad_prev, u >= fp.p_bad_good, u < fp.p_good_bad)  # bad: stays unless it recovers
        bad = jnp.where(first, u < fp.stationary_bad, stay)
    else:
        bad = jnp.zeros(fst.E, bool)
    if fst.noisy:
        r = _draws()
        z = r.normal_at(_key(seed, fault_rng.STREAM_NOISE, period), jnp.arange(fst.N * fst.P, dtype=_U64))
        noise = (fp.noise_std * z.reshape(fst.N, fst.P) * fp.noise_mask).astype(dtype)
    else:
        noise = jnp.zeros((fst.N, fst.P), dtype)
    return graph, bad, noise


def oo_losses(fst: FaultStructure, fp: FaultParams, fs: FaultState):
    """``(E,)`` bool: the O-O links losing the current period's packets (:func:`~dobs_envs.sim.fault_state.oo_losses`)."""
    p = jnp.where(fs.bad, fp.loss_bad, fp.loss_good) if fst.burst else jnp.full(fst.E, fp.oo_loss)
    return _uniforms(fs.seed, fault_rng.STREAM_OO_LOSS, fs.period, fst.E) < p


def init_state(fst: FaultStructure, fp: FaultParams, seed, xhat0_of, dtype) -> FaultState:
    """The fault state at reset (:func:`~dobs_envs.sim.fault_state.init_fault_state`): the period-0 draws,
    then every link, snapshot slot and C-O buffer holds the ``t = 0`` estimates ``xhat0_of(noise) (N, n)``
    (computed with the period's noise)."""
    seed = jnp.asarray(seed, _U64)
    period = jnp.zeros((), jnp.int64)
    graph, bad, noise = period_draws(fst, fp, seed, period, jnp.zeros((), jnp.int64), jnp.zeros(fst.E, bool), dtype)
    xhat0 = xhat0_of(noise if fst.noisy else None)
    co = xhat0[fst.co_nodes]
    return FaultState(seed=seed, period=period, received=xhat0[fst.sender],
                      snapshots=jnp.broadcast_to(xhat0, (fst.ring, fst.N, fst.n)), bad=bad, graph=graph, noise=noise,
                      co_sent=jnp.broadcast_to(co, (fst.co_delay + 1, fst.K, fst.n)), co_held=co)


def next_period(fst: FaultStructure, fp: FaultParams, fs: FaultState, received, snapshots) -> FaultState:
    """The state after a period (:func:`~dobs_envs.sim.numpy_step.control_period_faulted_numpy`'s end): the
    exchange's received values and snapshots, ``period + 1`` and its draws."""
    period = fs.period + 1
    graph, bad, noise = period_draws(fst, fp, fs.seed, period, fs.graph, fs.bad, fs.noise.dtype)
    return fs.replace(period=period, received=received, snapshots=snapshots, graph=graph, bad=bad, noise=noise)


# ---------------------------------------------------------------------------------------- the O-O exchange
class FaultedExchange:
    """The faulted O-O exchange of one control period of one copy (:class:`dobs_envs.sim.numpy_step._FaultedExchange`).

    Built by :func:`dobs_envs.jax.dynamics.control_period` as ``FaultedExchange(params, structure, coefs, zero,
    fs)`` (bind ``fs``, the :class:`FaultState` at the period's start, with ``functools.partial``); its
    ``carry`` is ``(received, snapshots)``: the held copies ``r_e`` (a tuple of ``E n`` scalars) and the
    snapshot ring ``(ring, N, n)``.
    """

    def __init__(self, params, structure, K, zero, fs: FaultState):
        fst, fp = structure.faults, params.faults
        self.fst, self.zero, self.k = fst, zero, fs.period
        w = fp.weight[fs.graph].astype(structure.dtype)  # a_ij^{g} of every link in the copy's active graph
        self.w = unstack(w)
        self.deg = unstack(fp.degree[fs.graph].astype(structure.dtype))
        self.deliver = unstack((fp.weight[fs.graph] > 0) & ~oo_losses(fst, fp, fs))
        self.noise = unstack(fs.noise) if fst.noisy else None
        self.refresh = fst.continuous and fst.lag == 0  # continuous exchange: fresh r_ij in split steps too
        self.dtype = structure.dtype

    def grid(self, j, xhat, carry):
        """Broadcasts at Euler step ``s = k S + j`` (when ``s`` is a multiple of ``exchange_steps``), then ``d``."""
        fst = self.fst
        r, snaps = carry
        n = fst.n
        s = self.k * fst.substeps + j
        now = True if fst.continuous else (s % fst.exchange_steps == 0)
        if fst.lag > 0:
            q = s // fst.exchange_steps  # broadcast number
            xh = stack(xhat, (fst.N, n), self.dtype)
            slot = q % fst.ring
            snaps = snaps.at[slot].set(jnp.where(now, xh, snaps[slot]))  # one slot written (not the whole ring)
            src = unstack(snaps[(q - fst.lag) % fst.ring])  # not yet written before lag broadcasts: t = 0
        else:
            src = xhat
        r = tuple(jnp.where(self.deliver[e] & now, src[fst.sender[e] * n + c], r[e * n + c])
                  for e in range(fst.E) for c in range(n))
        return self._d(xhat, r), (r, snaps)

    def sub(self, xhat, carry):
        """``d`` inside a split Euler step: a continuous exchange refreshes ``r``."""
        r, snaps = carry
        if self.refresh:
            n = self.fst.n
            r = tuple(jnp.where(self.deliver[e], xhat[self.fst.sender[e] * n + c], r[e * n + c])
                      for e in range(self.fst.E) for c in range(n))
        return self._d(xhat, r), (r, snaps)

    def _d(self, xhat, r):
        """Eq. (H_idefine) with held copies, ``d_i = sum_{e: receiver e = i} a_e (xhat_i - r_e)`` (links of
        weight 0 add nothing, even when a value is not finite), summed in link order."""
        fst, n = self.fst, self.fst.n
        d = [None] * (fst.N * n)
        for e in range(fst.E):
            i = int(fst.receiver[e])
            we = self.w[e]
            for c in range(n):
                term = jnp.where(we != 0.0, we * (xhat[i * n + c] - r[e * n + c]), 0.0)
                o = i * n + c
                d[o] = term if d[o] is None else d[o] + term
        return tuple(self.zero if a is None else a for a in d)


# ---------------------------------------------------------------------------------------- the boundary
def boundary(fst: FaultStructure, fp: FaultParams, fs: FaultState, xhat, *, link: bool):
    """What the agents receive at the boundary of period ``fs.period`` (:func:`dobs_envs.envs.features.fault_rows`).

    ``xhat (N, n)``: the estimates now (with the period's measurement noise). ``link``: run the C-O link
    (:func:`~dobs_envs.sim.fault_state.co_link_numpy`: the sent estimate enters the ring, the one sent
    ``co_delay`` boundaries before arrives unless lost with probability ``co_loss``); False at a reset
    (every controller holds the ``t = 0`` estimate, received). Returns ``(fs, Received)``; the O-O copies
    are read, not changed (the period's first Euler step makes the same broadcast).
    """
    if link:
        Lc = fst.co_delay + 1
        k = fs.period
        co_sent = fs.co_sent.at[k % Lc].set(xhat[fst.co_nodes])
        arrived = co_sent[(k - fst.co_delay) % Lc]  # not yet written before co_delay boundaries: t = 0
        lost = _uniforms(fs.seed, fault_rng.STREAM_CO_LOSS, k, fst.K) < fp.co_loss
        held = jnp.where(lost[:, None], fs.co_held, arrived)
        fs = fs.replace(co_sent=co_sent, co_held=held)
        co_rx = ~lost
    else:
        co_rx = jnp.ones(fst.K, bool)
    s = fs.period * fst.substeps
    due = True if fst.continuous else (s % fst.exchange_steps == 0)
    fresh = due & (fp.weight[fs.graph] > 0) & ~oo_losses(fst, fp, fs)
    if fst.lag > 0:
        src = fs.snapshots[(s // fst.exchange_steps - fst.lag) % fst.ring][fst.sender]
    else:
        src = xhat[fst.sender]
    nbr = jnp.where(fresh[:, None], src, fs.received)
    return fs, Received(xhat_rx=fs.co_held, nbr_rx=nbr, co_rx=co_rx, oo_rx=fresh)


def received_fraction(fst: FaultStructure, oo_rx):
    """``(K,)``: the fraction of the O-O links into each agent's node received at the boundary (1 without links)."""
    frac = jnp.asarray(fst.incidence) @ oo_rx.astype(jnp.float64)
    return jnp.where(jnp.asarray(fst.lonely), 1.0, frac)
