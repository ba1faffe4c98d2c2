r"""Cooperative tasks on heterogeneous multi-agent systems (Section AIHMAS): rendezvous.

The ``hetero_mas_v0`` task uses the five NE1 agents (eq. HMAS: two integrators,
two double integrators, one triple integrator). The *position* of agent ``i``
is the first component of its state ``breve x_i`` (the measured output
``y_i = breve C_i breve x_i`` for NE1's chains); the other components
(velocities, accelerations) should settle. Each agent applies a linear gain to
its **own** distributed estimate ``xhat_i`` (eq. obidynamicMAS), which
Theorem lfthm allows for any stabilising linear state feedback:
``u_i = K_i xhat_i`` with ``K_i`` the rows of agent ``i``'s input.

Cost
----
With ``S (N x n)`` selecting the positions ``p = S x`` and
``Pi = (N I_N - 1 1^T) / N`` (the complete-graph Laplacian divided by ``N``,
so ``p^T Pi p = sum_i (p_i - pbar)^2``)::

    Q = S^T Pi S + q_rest (I_n - S^T S)            (n x n),   R = r I_m.

The environments' team cost is ``x^T Q x + u^T R u`` (:attr:`Scenario.Q`, ``.R``).

The analytic reference gain and the common-position mode
--------------------------------------------------------
The common position ``v_c = S^T 1`` (all agents at the same place, at rest) is
an integrator mode (``A v_c = 0`` for NE1) that ``Q`` does not see
(``Q v_c = 0``): ``(Q, A)`` is not detectable, so the CARE with ``Q`` has no
*stabilising* solution. Two correct treatments are provided:

* ``rho > 0`` (default ``rho = 1e-3``): the LQR is solved for
  ``Q_rho = Q + rho S^T (1 1^T / N) S`` (the position block becomes
  ``Pi + rho 1 1^T / N``; ``rho = 1`` would weight every position fully).
  ``(Q_rho, A)`` is detectable, the CARE has its unique stabilising solution and
  ``A + B K`` is Hurwitz, which is exactly the hypothesis of Theorem lfthm, so
  the paper's separation result applies verbatim. The price is that the
  rendezvous point drifts slowly to the origin: for NE1 (``q_rest = 0.1``,
  ``r = 1``) the slow real eigenvalue is ``~ -1.47 sqrt(rho)`` (``-0.047`` at
  ``rho = 1e-3``, time constant ~21 s) while every disagreement/velocity mode has
  ``Re <= -0.54``, i.e. the rendezvous transient is >10x faster than the drift.
* ``rho = 0``: the LQR is solved exactly in disagreement coordinates
  ``xi = W^T x`` (``W`` an orthonormal basis of ``v_c^perp``). Because
  ``A v_c = 0`` the ``xi`` dynamics ``xi' = W^T A W xi + W^T B u`` do not depend
  on the common coordinate, ``W^T Q W > 0``, and ``K = K_xi W^T`` with
  ``K_xi`` from the CARE of ``(W^T A W, W^T B, W^T Q W, R)``. Then
  ``K v_c = 0`` and ``eig(A + B K) = {0} U eig(W^T (A + B K) W)``, the latter
  Hurwitz: the agents meet at a point determined by the initial state, and
  ``x^T X x`` (``X = W X_xi W^T``) is the optimal value of the environments'
  infinite-horizon cost. This gain is the ``rho -> 0`` limit of the first one,
  but it is *not* stabilising, so Theorem lfthm does not cover it formally.

The default is ``rho = 1e-3`` because it keeps the paper's guarantee (Hurwitz
``A + B K``) while staying within a few percent of the exact rendezvous gain
(``||K_rho - K_0|| = O(sqrt(rho))``).
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
import scipy.linalg as sla

from ..design.gains import shifted_are_feedback, stabilising_are
from ..linalg.validation import as_array, as_float
from .scenario import Scenario
from .composition import agent_offsets, compose_mas, ring_or_path
from .paper import ne1_agents

__all__ = [
    "position_indices",
    "rendezvous_cost",
    "rendezvous_lqr",
    "rendezvous_scenario",
    "disagreement",
    "mean_position",
    "rest_norm",
    "rendezvous_metrics",
    "DEFAULT_RHO",
    "DEFAULT_Q_REST",
]

#: Default weight on the average position (see the module docstring).
DEFAULT_RHO = 1e-3
#: Default weight on the non-position components.
DEFAULT_Q_REST = 0.1

#: NE1's initial state (agents 1..5 stacked).
_NE1_X0 = (-1.0, -2.0, -3.0, -4.0, 5.0, 4.0, 3.0, 2.0, 1.0)


def _agent_dims(agents) -> list:
    """``[n_0, ..., n_{N-1}]`` of the agents, after the checks every function here makes at its boundary.

    Each block must be finite and real (complex entries are refused: the float block assembly would
    drop the imaginary part) and ``A_i`` square (a scalar is ``(1, 1)``); errors name ``agents[i].A``
    (``.B``, ``.C``) as the caller passed them. The block shapes against each other are
    :func:`~dobs_envs.scenarios.composition.compose_mas`'s check (``agents[i]: ...``).
    """
    try:
        triples = [(a, b, c) for a, b, c in agents]
    except (TypeError, ValueError):
        raise ValueError("agents must be a sequence of (A_i, B_i, C_i) triples") from None
    if not triples:
        raise ValueError("agents must contain at least one agent")
    dims = []
    for i, triple in enumerate(triples):
        A_i, _, _ = (as_array(M, f"agents[{i}].{name}") for name, M in zip("ABC", triple))
        A_i = np.atleast_2d(A_i)
        if A_i.ndim != 2 or A_i.shape[0] != A_i.shape[1]:
            raise ValueError(f"agents[{i}].A must be square (n_i, n_i), got shape {A_i.shape}")
        dims.append(int(A_i.shape[0]))
    return dims


def position_indices(agents) -> np.ndarray:
    """Indices of the agents' positions (first state component of each agent) in ``x``.

    Parameters
    ----------
    agents : sequence of (A_i, B_i, C_i) (eq. HMAS), or a Scenario with ``mas_agents``.

    Returns
    -------
    ndarray of int, shape (N,)
        ``[0, n_1, n_1 + n_2, ...]`` (NE1: ``[0, 1, 2, 4, 6]``).
    """
    if isinstance(agents, Scenario):
        if agents.mas_agents is None:
            raise ValueError(f"scenario {agents.name!r} is not a multi-agent system (mas_agents is None)")
        agents = agents.mas_agents
    return agent_offsets(_agent_dims(agents))[:-1].astype(int)


def _selector(agents) -> tuple[np.ndarray, int]:
    dims = _agent_dims(agents)
    n = int(sum(dims))
    S = np.eye(n)[position_indices(agents)]
    return S, n


def rendezvous_cost(agents=None, q_rest: float = DEFAULT_Q_REST) -> np.ndarray:
    """Rendezvous state weight ``Q = S^T Pi S + q_rest (I - S^T S)`` (module docstring).

    Parameters
    ----------
    agents : sequence of (A_i, B_i, C_i), optional
        Default: the NE1 agents.
    q_rest : float
        Weight ``>= 0`` on the non-position components.

    Returns
    -------
    Q : ndarray, shape (n, n)
        Symmetric PSD; ``Q S^T 1 = 0`` (the common position is free).
    """
    agents = ne1_agents() if agents is None else agents
    q_rest = as_float(q_rest, "q_rest", minimum=0.0)
    S, n = _selector(agents)
    N = S.shape[0]
    Pi = (N * np.eye(N) - np.ones((N, N))) / N
    return S.T @ Pi @ S + q_rest * (np.eye(n) - S.T @ S)


def rendezvous_lqr(agents=None, *, q_rest: float = DEFAULT_Q_REST, r: float = 1.0,
                   rho: float = DEFAULT_RHO) -> tuple[np.ndarray, np.ndarray]:
    """Analytic rendezvous gain: LQR for ``Q`` of :func:`rendezvous_cost`, ``R = r I``.

    Parameters
    ----------
    agents : sequence of (A_i, B_i, C_i), optional
        Default: the NE1 agents. ``A = diag(A_i)``, ``B = diag(B_i)``.
    q_rest, r : float
        Cost weights (``r > 0``).
    rho : float
        ``> 0``: CARE with ``Q + rho S^T (1 1^T / N) S`` (``A + B K`` Hurwitz);
        ``0``: exact LQR in disagreement coordinates (requires ``A S^T 1 = 0``;
        ``A + B K`` has the eigenvalue 0 with eigenvector ``S^T 1``).
        See the module docstring.

    Returns
    -------
    X : ndarray, shape (n, n)
        CARE solution (for ``rho = 0``: ``W X_xi W^T``).
    K : ndarray, shape (m, n)
        ``K = -R^{-1} B^T X``; the rows of agent ``i``'s input form ``K_i``.
    """
    agents = ne1_agents() if agents is None else agents
    r, rho = as_float(r, "r", positive=True), as_float(rho, "rho", minimum=0.0)
    Q = rendezvous_cost(agents, q_rest)
    mas = compose_mas(agents)
    A, B = mas.A, np.hstack(mas.channels)  # B = diag(B_i)
    n, m = B.shape
    R = r * np.eye(m)
    S, _ = _selector(agents)
    N = S.shape[0]
    if rho > 0:
        Q_rho = Q + rho * S.T @ (np.ones((N, N)) / N) @ S
        return shifted_are_feedback(A, B, shift=0.0, Q=Q_rho, R=R)
    v = S.T @ np.ones(N) / np.sqrt(N)
    if np.linalg.norm(A @ v) > 1e-12 * max(1.0, np.linalg.norm(A)):
        raise ValueError(
            "rendezvous_lqr(rho=0) needs the common position S^T 1 to be an equilibrium (A S^T 1 = 0), "
            "so that the disagreement dynamics decouple; use rho > 0 for these agents"
        )
    W = sla.null_space(v[None, :])  # (n, n-1) orthonormal, W^T v = 0
    X_xi = stabilising_are(W.T @ A @ W, W.T @ B, W.T @ Q @ W, R,
                           what="rendezvous_lqr(rho=0): the disagreement-coordinate CARE")
    X = W @ X_xi @ W.T
    K = -B.T @ X / r  # -R^{-1} B^T X with R = r I
    return X, K


def rendezvous_scenario(
    *,
    agents: Optional[Sequence] = None,
    q_rest: float = DEFAULT_Q_REST,
    r: float = 1.0,
    rho: float = DEFAULT_RHO,
    x0=None,
    graph=None,
    mas_shift: float = 0.2,
    t_end: float = 30.0,
    dt: float = 1e-3,
    name: str = "ne1-rendezvous",
) -> Scenario:
    """The ``hetero_mas_v0`` rendezvous task (module docstring).

    Parameters
    ----------
    agents : sequence of (A_i, B_i, C_i), optional
        Default: NE1's five agents (eq. HMAS).
    q_rest, r, rho : float
        Cost and reference-gain weights (:func:`rendezvous_cost`, :func:`rendezvous_lqr`).
    x0 : array_like, shape (n,), optional
        Default: NE1's ``x(0) = (-1, -2, -3, -4, 5, 4, 3, 2, 1)`` (NE1 agents only).
    graph : Graph or array_like, optional
        O-O graph; default the ring ``0-1-...-(N-1)-0`` used for NE1 (a path for ``N < 3``).
    mas_shift : float
        Shift of the agents' observer AREs (eq. obidynamicMAS; NE1: 0.2).
    t_end, dt : float
    name : str

    Returns
    -------
    Scenario
        MAS design, ``controller="feedback"`` with the rendezvous gain ``K``,
        ``Q``/``R`` the rendezvous cost, agent ``i`` knows and controls its own
        input (``known[i] = (i,)``, ``links[i] = i``), NE1's adaptive-law
        constants; ``metadata`` holds ``task``, ``positions``, ``q_rest``,
        ``r``, ``rho``.
    """
    default_agents = agents is None
    agents = ne1_agents() if default_agents else list(agents)
    N = len(_agent_dims(agents))  # refuses what is not a sequence of real (A_i, B_i, C_i) triples
    Q = rendezvous_cost(agents, q_rest)
    _, K = rendezvous_lqr(agents, q_rest=q_rest, r=r, rho=rho)
    m = K.shape[0]
    if x0 is None:
        if not default_agents:
            raise ValueError("rendezvous_scenario: give x0 for custom agents (the default is NE1's)")
        x0 = np.array(_NE1_X0)
    if graph is None:
        graph = ring_or_path(N)
    return Scenario(
        name=name,
        # A = diag(A_i), B^i = [0 B_i^T 0]^T, C_i = [0 C_i 0]; agent i knows u_i and uses xhat_i
        **compose_mas(agents)._asdict(),
        graph=graph,
        x0=x0,
        K=K,
        controller="feedback",
        Q=Q, R=float(r) * np.eye(m),
        gamma0=0.1, gamma_s0=0.1, phi=0.2, phi_s=0.5,
        mas_shift=mas_shift,
        t_end=t_end, dt=dt,
        description=("Rendezvous of heterogeneous agents (eq. HMAS): positions agree, other components "
                     "settle; u_i = K_i xhat_i with the rendezvous LQR gain"),
        metadata=dict(task="rendezvous", positions=position_indices(agents).tolist(),
                      q_rest=float(q_rest), r=float(r), rho=float(rho)),
    )


# ---------------------------------------------------------------------- metrics
def _positions(positions) -> np.ndarray:
    if isinstance(positions, Scenario):
        if "positions" in positions.metadata:
            return np.asarray(positions.metadata["positions"], dtype=int)
        return position_indices(positions)
    return np.asarray(positions, dtype=int).reshape(-1)


def disagreement(x, positions) -> np.ndarray:
    """Position disagreement ``||p - pbar 1|| = sqrt(x^T S^T Pi S x)``.

    Parameters
    ----------
    x : array_like, shape (..., n)
        Plant states (any leading batch/time axes).
    positions : Scenario or array_like of int, shape (N,)
        The position indices (:func:`position_indices`).

    Returns
    -------
    ndarray, shape (...)
    """
    p = np.asarray(x, dtype=float)[..., _positions(positions)]
    return np.linalg.norm(p - p.mean(axis=-1, keepdims=True), axis=-1)


def mean_position(x, positions) -> np.ndarray:
    """Average position ``pbar = 1^T S x / N``, shape ``(...)``."""
    return np.asarray(x, dtype=float)[..., _positions(positions)].mean(axis=-1)


def rest_norm(x, positions) -> np.ndarray:
    """Norm of the non-position components (velocities, accelerations), shape ``(...)``."""
    x = np.asarray(x, dtype=float)
    mask = np.ones(x.shape[-1], dtype=bool)
    mask[_positions(positions)] = False
    return np.linalg.norm(x[..., mask], axis=-1)


def rendezvous_metrics(x, scenario: Scenario) -> dict:
    """``{"disagreement", "mean_position", "rest_norm", "cost_rate"}`` of states ``x (..., n)``;
    ``cost_rate = x^T Q x`` with the scenario's ``Q``."""
    x = np.asarray(x, dtype=float)
    return {
        "disagreement": disagreement(x, scenario),
        "mean_position": mean_position(x, scenario),
        "rest_norm": rest_norm(x, scenario),
        "cost_rate": np.einsum("...i,ij,...j->...", x, scenario.Q, x),
    }
