r"""Seeded random scenarios that satisfy the paper's assumptions by construction.

Two generators (and the entry point :func:`random_scenario`):

* :func:`random_mas_scenario` -- a heterogeneous multi-agent system, eq. (HMAS),
  designed with the MAS observer of eq. (obidynamicMAS) (Section AIHMAS);
* :func:`random_plant_scenario` -- a general multi-channel plant, eqs. (LTIsys),
  (Busplit), (localmeasure), (splitinput), designed with Lemma 2 per node and
  eq. (barEFGB).

Every draw comes from ``numpy.random.default_rng(seed)`` in a fixed order, so
the same arguments give the same scenario (bit-identical arrays). The
construction makes the assumptions hold generically (with probability one);
each candidate is then *verified numerically*: Assumption 3 (stabilisable,
through the shifted ARE), 4 (matching, when there is an unknown input), 5
(connected graph), 6 (per-node strong detectability, Lemma 2, and
``sum_i Im T_id = R^n``; for a MAS, detectability of every ``(A_i, C_i)``),
``A + B K`` Hurwitz (hypothesis of Theorem lfthm), and the observer design
:attr:`Scenario.design` is built. A candidate that fails (a numerically
borderline draw) is discarded and the generator continues drawing from the same
stream; after ``max_attempts`` failures :class:`RandomScenarioError` is raised
with the last failure. With the default distributions failures are rare.

Spectrum distribution (both generators)
---------------------------------------
The eigenvalues are drawn as a list of *modes*, until ``n`` eigenvalues are
placed: if at least two eigenvalues remain, with probability ``p_complex``
(default 0.3) a complex pair ``a +- i b`` with ``a ~ U[real_range]`` (default
``U[-1, 0.5]``) and ``b ~ U[imag_range]`` (default ``U[0.2, 2]``); otherwise
a real eigenvalue which is exactly ``0`` with probability ``p_zero`` (default
0.25; repeated zeros give integrator chains as in NE1) and ``~ U[real_range]``
otherwise. About a third of the modes are therefore marginal or unstable.
If fewer than ``min_unstable`` modes have ``Re >= 0``, the real parts of the
first modes with ``Re < 0`` are reflected (``a -> -a``) until there are.

Signals (when the controller needs them)
----------------------------------------
Reference ``r^k`` (``controller="tracking"``, eq. refxdy) or prescribed input
(``"open_loop"``, bounded as Assumption 2 requires), per input component:
``a sin(w t + ph)`` with ``a ~ U[0.5, 1.5]``, ``w ~ U[0.5, 2]``,
``ph ~ U[0, 2 pi)``.

Initial state
-------------
``x0 ~ U[-x0_scale, x0_scale]^n`` (default ``x0_scale = 1``), drawn from the
same stream after the system; the scenario's ``x0_scale`` field is set so that
environments can randomise resets from the same distribution
(:meth:`Scenario.sample_x0`).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from scipy.linalg import block_diag

from .. import assumptions as _asm
from ..design.gains import shifted_are_feedback, sliding_mode_P
from ..graphs import Graph, as_graph, random_connected_graph
from ..linalg.subspaces import is_hurwitz
from ..linalg.validation import as_flag, as_float, as_int, check_seed
from .scenario import CONTROLLERS, Scenario
from .composition import TOPOLOGIES, compose_mas, ring_or_path
from .signals import Sinusoids

__all__ = [
    "random_mas_scenario",
    "random_plant_scenario",
    "random_scenario",
    "random_spectrum",
    "RandomScenarioError",
    "GRAPH_TOPOLOGIES",
]

#: Named O-O topologies accepted by the ``graph`` argument (``"ring"`` is a path below 3 nodes).
GRAPH_TOPOLOGIES = ("random",) + tuple(TOPOLOGIES)

#: Adaptive-law constants of NE3 (used by default with the sliding-mode controllers).
_NE3_CONSTANTS = dict(gamma0=0.1, sigma=0.2, phi=5.0, gamma_s0=0.1, sigma_s=0.1, phi_s=10.0,
                      beta0=0.1, sigma_beta=0.1, phi_beta=5.0, epsilon=0.2)

_RETRY_ERRORS = (ValueError, RuntimeError, np.linalg.LinAlgError)


class RandomScenarioError(RuntimeError):
    """No candidate passed the numerical verification within ``max_attempts``."""


# ---------------------------------------------------------------------- helpers
def _check_seed(seed, name: str = "seed") -> int:
    if seed is None:
        raise ValueError(f"{name} must be a nonnegative integer (reproducibility), got None")
    return check_seed(seed, name)


def _check_range(r, name, *, integer=False, lo=None) -> tuple:
    try:
        a, b = r
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (low, high), got {r!r}") from None
    if integer:
        a, b = as_int(a, f"{name}[0]", maximum=MAX_SIZE), as_int(b, f"{name}[1]", maximum=MAX_SIZE)
    else:
        a, b = as_float(a, f"{name}[0]"), as_float(b, f"{name}[1]")
    if a > b:
        raise ValueError(f"{name} must satisfy low <= high, got {r!r}")
    if lo is not None and a < lo:
        raise ValueError(f"{name} must be >= {lo}, got {r!r}")
    return a, b


def _check_prob(p, name) -> float:
    return as_float(p, f"{name} (a probability)", minimum=0.0, maximum=1.0)


#: largest size (states, agents, controller or observer nodes, block dimensions) the generators accept:
#: the design costs O(N n^3) and the simulation holds B x N x n estimates, so larger systems are refused
#: with a named error instead of running for hours or failing to allocate
MAX_SIZE = 1000


def _count(v, name, minimum=1, maximum: int | None = MAX_SIZE) -> int:
    return as_int(v, name, minimum=minimum, maximum=maximum)


def random_spectrum(rng: np.random.Generator, n: int, *, real_range=(-1.0, 0.5), imag_range=(0.2, 2.0),
                    p_zero: float = 0.25, p_complex: float = 0.3, min_unstable: int = 0) -> list:
    """Draw ``n`` eigenvalues as modes (see the module docstring for the distribution).

    Returns
    -------
    list of (float, float)
        Modes ``(a, b)``: ``b = 0`` a real eigenvalue ``a``; ``b > 0`` the pair ``a +- i b``.
    """
    modes, k = [], 0
    while k < n:
        if n - k >= 2 and rng.random() < p_complex:
            modes.append((float(rng.uniform(*real_range)), float(rng.uniform(*imag_range))))
            k += 2
        else:
            lam = 0.0 if rng.random() < p_zero else float(rng.uniform(*real_range))
            modes.append((lam, 0.0))
            k += 1
    n_bad = sum(a >= 0 for a, _ in modes)
    for j, (a, b) in enumerate(modes):
        if n_bad >= min_unstable:
            break
        if a < 0:
            modes[j] = (-a, b)
            n_bad += 1
    return modes


def _eigenvalues(modes) -> np.ndarray:
    ev = []
    for a, b in modes:
        ev.extend([complex(a, b), complex(a, -b)] if b else [complex(a, 0.0)])
    return np.asarray(ev)


def _haar_orthogonal(rng: np.random.Generator, n: int) -> np.ndarray:
    """Haar-distributed orthogonal ``(n, n)`` matrix (QR of a Gaussian with sign fix)."""
    Z = rng.standard_normal((n, n))
    Qm, Rm = np.linalg.qr(Z)
    return Qm * np.sign(np.where(np.diag(Rm) == 0, 1.0, np.diag(Rm)))


def _companion(modes) -> np.ndarray:
    """Controllable-canonical ``A`` (ones on the superdiagonal, last row ``-[c_n ... c_1]``)
    with characteristic polynomial ``prod (s - lambda)`` over the modes' eigenvalues."""
    coeffs = np.real(np.poly(_eigenvalues(modes)))  # [1, c_1, ..., c_n]
    n = coeffs.size - 1
    A = np.diag(np.ones(n - 1), 1) if n > 1 else np.zeros((1, 1))
    A[-1, :] -= coeffs[:0:-1]
    return A


def _make_graph(graph, N: int, edge_prob: float, rng: np.random.Generator) -> Graph:
    if isinstance(graph, str):
        if graph not in GRAPH_TOPOLOGIES:
            raise ValueError(f"graph must be one of {GRAPH_TOPOLOGIES}, a Graph or an adjacency matrix, got {graph!r}")
        if graph == "random":
            return random_connected_graph(N, edge_prob, seed=int(rng.integers(2**31)))
        if graph == "ring":
            return ring_or_path(N)
        return TOPOLOGIES[graph](N)
    g = as_graph(graph)
    if g.n_nodes != N:
        raise ValueError(f"graph has {g.n_nodes} nodes, expected {N}")
    return g


def _signals(rng: np.random.Generator, m: int) -> Sinusoids:
    return Sinusoids(amplitude=rng.uniform(0.5, 1.5, m), frequency=rng.uniform(0.5, 2.0, m),
                     phase=rng.uniform(0.0, 2 * np.pi, m))


def _finish(rng, *, controller, A, B, shift, x0_scale, base: dict, overrides: dict) -> Scenario:
    """Gains, signals, initial state; then the Scenario (validated)."""
    m = B.shape[1]
    _, K = shifted_are_feedback(A, B, shift=shift)
    kw = dict(base)
    kw["K"] = K
    if controller in ("sliding_mode", "adaptive_sliding_mode"):
        kw["P"] = sliding_mode_P(A, B, K)  # (A + BK)^T P + P (A + BK) = -I
        kw.update(_NE3_CONSTANTS)
    if controller == "tracking":
        kw["reference"] = _signals(rng, m)
        kw["x_r0"] = np.zeros(A.shape[0])
    if controller == "open_loop":
        kw["prescribed_input"] = _signals(rng, m)
    kw["x0"] = rng.uniform(-x0_scale, x0_scale, A.shape[0])
    kw["x0_scale"] = x0_scale
    kw["controller"] = controller
    kw.update(overrides)
    return Scenario(**kw)


def _verify(sc: Scenario) -> None:
    """Numerical check of the assumptions the construction guarantees generically.

    Raises a ``ValueError`` (an :class:`~dobs_envs.assumptions.AssumptionError`
    naming the assumption where applicable) or ``RuntimeError`` on failure.
    """
    _asm.check_connected(sc.graph)  # Assumption 5
    if sc.K is not None and not is_hurwitz(sc.A + sc.B @ sc.K):  # Theorem lfthm hypothesis
        raise ValueError("A + B K is not Hurwitz")
    if sc.B_v.shape[1]:
        _asm.check_matching(sc.B, sc.B_v)  # Assumption 4
        if sc.exosystem is not None:
            _asm.check_exosystem_bounded(sc.exosystem)  # Assumption 1
    if sc.mas_agents is not None:  # Section AIHMAS: (A_i, C_i) detectable => Assumption 6
        for i, (Ai, _, Ci) in enumerate(sc.mas_agents):
            _asm.check_detectable(Ai, Ci, margin=sc.mas_shift, name=f"agent {i}")
    # The observer design runs Lemma 2 at every node (strong_detectability, whose
    # result is re-checked against Lemma 2's equations) and checks Assumption 6
    # (sum_i Im T_id = R^n) and Assumption 5; it raises a named AssumptionError.
    sc.design  # noqa: B018 - builds eq. (barEFGB)/(obidynamicMAS); raises AssumptionError


def _attempts(max_attempts) -> int:
    return _count(max_attempts, "max_attempts", maximum=None)


# ---------------------------------------------------------------------- MAS
def random_mas_scenario(
    n_agents: int = 4,
    seed: int = 0,
    *,
    state_dims=(1, 3),
    input_dims=(1, 1),
    output_dims=(1, 1),
    real_range=(-1.0, 0.5),
    imag_range=(0.2, 2.0),
    p_zero: float = 0.25,
    p_complex: float = 0.3,
    min_unstable: int = 0,
    similarity: bool = False,
    graph="random",
    edge_prob: float = 0.3,
    controller: str = "feedback",
    shift: float = 0.2,
    mas_shift: float = 0.2,
    x0_scale: float = 1.0,
    verify: bool = True,
    max_attempts: int = 20,
    name: Optional[str] = None,
    **overrides,
) -> Scenario:
    r"""Random heterogeneous multi-agent system, eq. (HMAS), with the MAS design (obidynamicMAS).

    Agent ``i`` (``i = 0..N-1``) has state dimension ``n_i ~ U{state_dims}``
    (integers, inclusive), ``m_i ~ U{input_dims}`` inputs and
    ``p_i ~ U{output_dims}`` outputs (``p_i <= n_i``). Its spectrum is drawn as
    in the module docstring (``min_unstable`` per agent) and

    - ``A_i`` is the controllable canonical (companion) form of that spectrum:
      ones on the superdiagonal, last row ``-[c_{n_i} ... c_1]``;
    - ``B_i = [e_{n_i}, W_B]`` and ``C_i = [e_1^T; W_C]`` with the extra columns
      ``W_B`` (``n_i x (m_i - 1)``) and rows ``W_C`` (``(p_i - 1) x n_i``)
      i.i.d. ``N(0, 1)``.

    ``(A_i, e_{n_i})`` is controllable and ``(A_i, e_1^T)`` observable for
    every characteristic polynomial, so ``(A_i, B_i)`` is stabilisable and
    ``(A_i, C_i)`` detectable by construction (then Assumption 6 holds,
    Section AIHMAS). With all eigenvalues 0 the agents are NE1's integrator
    chains and ``x_i[0]`` (the measured component) is the "position". With
    ``similarity=True`` every agent is further transformed by a Haar-random
    orthogonal ``T_i``: ``(T_i^T A_i T_i, T_i^T B_i, C_i T_i)``.

    The overall system is ``A = diag(A_i)``, channel ``k = i`` is
    ``[0 B_i^T 0]^T`` (each agent controls its own input), node ``i`` measures
    ``[0 C_i 0]`` and knows channel ``i`` only, and controller ``i`` uses agent
    ``i``'s estimate (``links = (0, ..., N-1)``). ``K`` is the shifted-ARE gain
    ``K = -B^T X``, ``(A + sI)^T X + X (A + sI) - X B B^T X + I = 0``
    (``s = shift``; block diagonal here since ``A``, ``B`` are).

    Parameters
    ----------
    n_agents : int
        ``N >= 1`` (``graph="ring"`` falls back to a path for ``N < 3``).
    seed : int
        Nonnegative; same arguments and seed give the same scenario.
    state_dims, input_dims, output_dims : (int, int)
        Inclusive ranges of ``n_i``, ``m_i``, ``p_i``.
    real_range, imag_range, p_zero, p_complex, min_unstable
        Spectrum distribution (module docstring).
    similarity : bool
        Random orthogonal change of coordinates per agent.
    graph : str or Graph or array_like
        One of :data:`GRAPH_TOPOLOGIES` (``"random"``:
        :func:`~dobs_envs.graphs.random_connected_graph` with ``edge_prob`` and a
        seed drawn from the stream) or an explicit graph (unit weights otherwise).
    controller : str
        One of :data:`~dobs_envs.scenarios.scenario.CONTROLLERS`; sliding modes get
        ``P`` from ``(A + BK)^T P + P (A + BK) = -I`` and NE3's adaptive-law
        constants, ``"tracking"``/``"open_loop"`` random sinusoids.
    shift : float
        Shift of the controller ARE (NE2: 0.2).
    mas_shift : float
        Shift of the agents' observer AREs (NE1: 0.2).
    x0_scale : float
        ``x0 ~ U[-x0_scale, x0_scale]^n``.
    verify : bool
        Verify the assumptions and build the design (module docstring).
    max_attempts : int
        Candidates tried before :class:`RandomScenarioError`.
    name : str, optional
        Default ``"random-mas-N{N}-seed{seed}"``.
    **overrides
        Further :class:`Scenario` fields (e.g. ``phi``, ``t_end``).

    Returns
    -------
    Scenario
        With ``mas_agents`` set and ``metadata["generator"]`` recording the arguments.
    """
    N = _count(n_agents, "n_agents")
    seed = _check_seed(seed)
    sd = _check_range(state_dims, "state_dims", integer=True, lo=1)
    idim = _check_range(input_dims, "input_dims", integer=True, lo=1)
    odim = _check_range(output_dims, "output_dims", integer=True, lo=1)
    real_range = _check_range(real_range, "real_range")
    imag_range = _check_range(imag_range, "imag_range")
    p_zero, p_complex = _check_prob(p_zero, "p_zero"), _check_prob(p_complex, "p_complex")
    min_unstable = _count(min_unstable, "min_unstable", minimum=0)
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    x0_scale = as_float(x0_scale, "x0_scale", minimum=0.0)
    edge_prob, shift = _check_prob(edge_prob, "edge_prob"), as_float(shift, "shift", minimum=0.0)
    name = f"random-mas-N{N}-seed{seed}" if name is None else name
    meta = dict(generator="random_mas_scenario", seed=seed, n_agents=N, state_dims=list(sd),
                input_dims=list(idim), output_dims=list(odim), real_range=list(real_range),
                imag_range=list(imag_range), p_zero=p_zero, p_complex=p_complex,
                min_unstable=min_unstable, similarity=bool(similarity), edge_prob=float(edge_prob),
                shift=float(shift))
    rng = np.random.default_rng(seed)

    def candidate(attempt):
        agents = []
        for i in range(N):
            ni = int(rng.integers(sd[0], sd[1] + 1))
            mi = int(rng.integers(idim[0], idim[1] + 1))
            pi = int(rng.integers(odim[0], min(odim[1], ni) + 1)) if odim[0] <= ni else ni
            modes = random_spectrum(rng, ni, real_range=real_range, imag_range=imag_range,
                                    p_zero=p_zero, p_complex=p_complex, min_unstable=min(min_unstable, ni))
            Ai = _companion(modes)
            Bi = np.hstack([np.eye(ni)[:, -1:], rng.standard_normal((ni, mi - 1))])
            Ci = np.vstack([np.eye(ni)[:1], rng.standard_normal((pi - 1, ni))])
            if similarity:
                T = _haar_orthogonal(rng, ni)
                Ai, Bi, Ci = T.T @ Ai @ T, T.T @ Bi, Ci @ T
            agents.append((Ai, Bi, Ci))
        g = _make_graph(graph, N, edge_prob, rng)
        mas = compose_mas(agents)
        base = dict(name=name, **mas._asdict(), graph=g, mas_shift=mas_shift,
                    description=f"Random heterogeneous MAS (eq. HMAS), {N} agents, seed {seed}",
                    metadata=dict(meta, attempt=attempt))
        sc = _finish(rng, controller=controller, A=mas.A, B=np.hstack(mas.channels), shift=shift,
                     x0_scale=x0_scale, base=base, overrides=overrides)
        if verify:
            _verify(sc)
        return sc

    return _first_valid(candidate, max_attempts, f"random_mas_scenario(n_agents={N}, seed={seed})")


def _is_user_error(exc) -> bool:
    """Errors from bad user arguments (Scenario field overrides, graph) are not retried."""
    msg = str(exc)
    return msg.startswith("Scenario.") or msg.startswith("graph ") or msg.startswith("Graph")


def _first_valid(candidate, max_attempts, what: str):
    """``candidate(attempt)`` for attempt = 0, 1, ... until one passes verification.

    Numerical failures of a draw (:data:`_RETRY_ERRORS`) are retried from the same
    random stream; errors in the user's arguments (and ``TypeError``) propagate.
    Raises :class:`RandomScenarioError` after ``max_attempts`` failed draws.
    """
    last = None
    n_attempts = _attempts(max_attempts)
    for attempt in range(n_attempts):
        try:
            return candidate(attempt)
        except TypeError:
            raise
        except _RETRY_ERRORS as exc:
            if _is_user_error(exc):
                raise
            last = exc
    raise RandomScenarioError(
        f"{what}: no candidate passed verification in {n_attempts} attempts; "
        f"last failure: {type(last).__name__}: {last}"
    ) from last


# ---------------------------------------------------------------------- plant
def random_plant_scenario(
    n_states: int = 6,
    n_controllers: int = 3,
    n_observers: int = 4,
    seed: int = 0,
    *,
    inputs_per_controller=(1, 1),
    known_per_node=(1, 2),
    measurement: str = "selection",
    coupling: float = 0.5,
    real_range=(-1.0, 0.5),
    imag_range=(0.2, 2.0),
    p_zero: float = 0.25,
    p_complex: float = 0.3,
    min_unstable: int = 1,
    graph="random",
    edge_prob: float = 0.3,
    unknown_input: bool = False,
    exo_frequency_range=(0.2, 1.0),
    v0_scale: float = 1.0,
    controller: Optional[str] = None,
    shift: float = 0.2,
    x0_scale: float = 1.0,
    verify: bool = True,
    max_attempts: int = 20,
    name: Optional[str] = None,
    **overrides,
) -> Scenario:
    r"""Random multi-channel plant, eqs. (LTIsys), (Busplit), (localmeasure), (splitinput).

    Distributions (in draw order):

    1. ``A = Q M Q^T``: ``M`` is block upper triangular (real Schur form) with
       the modes of the module docstring on its diagonal (``[a]``, or
       ``[[a, b], [-b, a]]`` for ``a +- i b``; at least ``min_unstable`` modes
       with ``Re >= 0``, default 1) and i.i.d. ``N(0, coupling^2)`` entries
       above the diagonal blocks; ``Q`` is Haar-random orthogonal. So
       ``eig(A)`` is exactly the drawn spectrum (repeated zeros generically
       form Jordan blocks).
    2. Channels ``B^k`` (``k = 0..K-1``): ``m_k ~ U{inputs_per_controller}``
       columns with i.i.d. ``N(0, 1)`` entries ((A, B) is then controllable with
       probability one: Assumption 3).
    3. Outputs: a random ownership of the states -- with ``perm``, ``nodes``
       uniform permutations of the states and nodes, state ``perm[j]`` is owned by
       ``nodes[j]`` for ``j < N`` and by a uniform node for ``j >= N``; a node
       owning no state (when ``N > n``) gets one uniform state. With
       ``measurement="selection"`` ``C_i`` holds the unit rows of its states
       (sorted); with ``"gaussian"`` the same number of i.i.d. ``N(0, 1)`` rows.
       Either way ``col(C_i)`` has full column rank, the sufficient condition for
       Assumption 6 of the Remark after the assumptions.
    4. Known channels: node ``i`` knows ``k_i ~ U{known_per_node}`` (capped at
       ``K``) distinct channels drawn uniformly (its ``u_i``, eq. splitinput).
    5. O-O graph as in :func:`random_mas_scenario` (Assumption 5).
    6. C-O links: controller ``k`` uses the estimate of a node drawn uniformly
       among the nodes that know channel ``k`` (among all nodes if none does).
    7. With ``unknown_input=True``: ``B_v = B X_v`` with ``X_v`` (``m x 2``)
       i.i.d. ``N(0, 1)`` (matched, Assumption 4), exosystem
       ``S = [[0, w], [-w, 0]]`` with ``w ~ U[exo_frequency_range]`` (bounded,
       Assumption 1) and ``v0 ~ U[-v0_scale, v0_scale]^2``.
    8. ``K = -B^T X`` from ``(A + sI)^T X + X (A + sI) - X B B^T X + I = 0``
       (``s = shift``, :func:`~dobs_envs.design.gains.shifted_are_feedback`);
       sliding modes add ``P`` with ``(A + BK)^T P + P (A + BK) = -I``; then the
       signals and ``x0`` as in the module docstring.

    Parameters
    ----------
    n_states, n_controllers, n_observers : int
        ``n``, ``K = N_c``, ``N`` (all >= 1).
    seed : int
    inputs_per_controller, known_per_node : (int, int)
        Inclusive ranges.
    measurement : {"selection", "gaussian"}
    coupling : float
        Standard deviation of the off-diagonal Schur entries (>= 0).
    real_range, imag_range, p_zero, p_complex, min_unstable
        Spectrum (module docstring).
    graph, edge_prob
        As in :func:`random_mas_scenario`.
    unknown_input : bool
        Add the matched exosystem disturbance of step 7 (NE3-like).
    controller : str, optional
        Default ``"adaptive_sliding_mode"`` with an unknown input (Theorem
        adsmthm), else ``"feedback"`` (Theorem lfthm).
    shift, x0_scale, verify, max_attempts, name, **overrides
        As in :func:`random_mas_scenario` (default name
        ``"random-plant-n{n}-K{K}-N{N}-seed{seed}"``).

    Returns
    -------
    Scenario
    """
    n = _count(n_states, "n_states")
    Kc = _count(n_controllers, "n_controllers")
    N = _count(n_observers, "n_observers")
    seed = _check_seed(seed)
    ipc = _check_range(inputs_per_controller, "inputs_per_controller", integer=True, lo=1)
    kpn = _check_range(known_per_node, "known_per_node", integer=True, lo=0)
    if measurement not in ("selection", "gaussian"):
        raise ValueError(f"measurement must be 'selection' or 'gaussian', got {measurement!r}")
    coupling = as_float(coupling, "coupling", minimum=0.0)
    real_range = _check_range(real_range, "real_range")
    imag_range = _check_range(imag_range, "imag_range")
    exo = _check_range(exo_frequency_range, "exo_frequency_range")
    p_zero, p_complex = _check_prob(p_zero, "p_zero"), _check_prob(p_complex, "p_complex")
    min_unstable = _count(min_unstable, "min_unstable", minimum=0)
    if controller is None:
        controller = "adaptive_sliding_mode" if unknown_input else "feedback"
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    x0_scale, v0_scale = as_float(x0_scale, "x0_scale", minimum=0.0), as_float(v0_scale, "v0_scale", minimum=0.0)
    edge_prob, shift = _check_prob(edge_prob, "edge_prob"), as_float(shift, "shift", minimum=0.0)
    unknown_input = as_flag(unknown_input, "unknown_input")
    name = f"random-plant-n{n}-K{Kc}-N{N}-seed{seed}" if name is None else name
    meta = dict(generator="random_plant_scenario", seed=seed, n_states=n, n_controllers=Kc,
                n_observers=N, inputs_per_controller=list(ipc), known_per_node=list(kpn),
                measurement=measurement, coupling=coupling, real_range=list(real_range),
                imag_range=list(imag_range), p_zero=p_zero, p_complex=p_complex,
                min_unstable=min_unstable, edge_prob=float(edge_prob),
                unknown_input=bool(unknown_input), shift=float(shift))
    rng = np.random.default_rng(seed)

    def candidate(attempt):
        # 1. A
        modes = random_spectrum(rng, n, real_range=real_range, imag_range=imag_range, p_zero=p_zero,
                                p_complex=p_complex, min_unstable=min(min_unstable, n))
        blocks = [np.array([[a]]) if b == 0 else np.array([[a, b], [-b, a]]) for a, b in modes]
        M = block_diag(*blocks)
        upper = np.triu(np.ones((n, n)), 1)
        start = 0
        for blk in blocks:  # keep the 2x2 diagonal blocks intact
            w = blk.shape[0]
            upper[start:start + w, start:start + w] = 0.0
            start += w
        M = M + upper * rng.normal(0.0, coupling, (n, n)) if coupling > 0 else M
        Qo = _haar_orthogonal(rng, n)
        A = Qo @ M @ Qo.T
        # 2. channels
        channels = [rng.standard_normal((n, int(rng.integers(ipc[0], ipc[1] + 1)))) for _ in range(Kc)]
        # 3. outputs
        perm, nodes = rng.permutation(n), rng.permutation(N)
        owned = [[] for _ in range(N)]
        for j in range(n):
            owned[int(nodes[j]) if j < N else int(rng.integers(N))].append(int(perm[j]))
        for i in range(N):
            if not owned[i]:
                owned[i].append(int(rng.integers(n)))
        if measurement == "selection":
            C = [np.eye(n)[sorted(o)] for o in owned]
        else:
            C = [rng.standard_normal((len(o), n)) for o in owned]
        # 4. known channels
        known = []
        for i in range(N):
            ki = int(rng.integers(min(kpn[0], Kc), min(kpn[1], Kc) + 1))
            known.append(tuple(sorted(int(k) for k in rng.choice(Kc, size=ki, replace=False))))
        # 5. graph, 6. links
        g = _make_graph(graph, N, edge_prob, rng)
        links = []
        for k in range(Kc):
            cand = [i for i in range(N) if k in known[i]] or list(range(N))
            links.append(int(cand[int(rng.integers(len(cand)))]))
        B = np.hstack(channels)
        base = dict(name=name, A=A, channels=channels, C=C, known=known, graph=g, links=links,
                    description=(f"Random multi-channel plant: n={n}, {Kc} controller nodes, "
                                 f"{N} observer nodes, seed {seed}"),
                    metadata=dict(meta, attempt=attempt))
        # 7. unknown input
        if unknown_input:
            base["B_v"] = B @ rng.standard_normal((B.shape[1], 2))
            w = float(rng.uniform(*exo))
            base["exosystem"] = np.array([[0.0, w], [-w, 0.0]])
            base["v0"] = rng.uniform(-v0_scale, v0_scale, 2)
        # 8. gains, signals, x0
        sc = _finish(rng, controller=controller, A=A, B=B, shift=shift, x0_scale=x0_scale,
                     base=base, overrides=overrides)
        if verify:
            _verify(sc)
        return sc

    return _first_valid(candidate, max_attempts,
                        f"random_plant_scenario(n_states={n}, n_controllers={Kc}, n_observers={N}, seed={seed})")


# ---------------------------------------------------------------------- entry point
def random_scenario(kind: str = "plant", seed: int = 0, **kwargs) -> Scenario:
    """Entry point: ``kind="mas"`` -> :func:`random_mas_scenario`, ``"plant"`` -> :func:`random_plant_scenario`.

    ``kwargs`` are the generator's sizes and options (e.g. ``n_agents=5`` or
    ``n_states=8, n_controllers=3, n_observers=5``).
    """
    if kind == "mas":
        return random_mas_scenario(seed=seed, **kwargs)
    if kind == "plant":
        return random_plant_scenario(seed=seed, **kwargs)
    raise ValueError(f"random_scenario: kind must be 'mas' or 'plant', got {kind!r}")
