r"""The multi-agent system written as one plant (Section AIHMAS): the composition, once.

``N`` agents (eq. HMAS), agent ``i`` with state ``breve x_i`` of dimension ``n_i``,
``m_i`` inputs and ``p_i`` outputs,

    ``breve x_i' = breve A_i breve x_i + breve B_i u_i``,  ``y_i = breve C_i breve x_i``,

form the overall system of eqs. (LTIsys), (Busplit), (localmeasure), (splitinput) with
``x = col(breve x_i)`` (``n = sum_i n_i``), ``A = diag(breve A_i)``, the input channel of
agent ``i`` ``B^i = [0 breve B_i^T 0]^T`` and its output matrix ``C_i = [0 breve C_i 0]``
(the zero blocks ``sum_{q<i} n_q`` and ``sum_{q>i} n_q`` wide). Agent ``i`` is at once
observer node ``i``, which knows exactly its own input (``known[i] = (i,)``, the ``u_i`` of
eq. splitinput), and controller node ``i``, which uses its own estimate (C-O link
``links[i] = i``, eq. linearfeedback).

Pure matrix arithmetic (numpy/scipy), in the design layer so that both the MAS observer
(:func:`~dobs_envs.design.observer.design_mas_observer`, eq. obidynamicMAS) and every builder
of a MAS scenario compose through :func:`compose_mas`: the paper's NE1
(:func:`~dobs_envs.scenarios.paper.ne1`), the random MAS
(:func:`~dobs_envs.scenarios.random.random_mas_scenario`), the rendezvous task
(:mod:`~dobs_envs.scenarios.mas_tasks`) and the ``mas_agents`` key of scenario files
(:mod:`~dobs_envs.scenarios.io`); :class:`~dobs_envs.scenarios.scenario.Scenario` checks a
given composition against its agents with the same :func:`embed_block`. The scenarios import
these names from :mod:`dobs_envs.scenarios.composition`, which adds the named topologies.
The arguments are validated at those boundaries (the observer design and :class:`Scenario`
with the shared validators of :mod:`dobs_envs.linalg.validation`, the file reader naming the
key); here only the block shapes the assembly relies on are checked.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.linalg import block_diag

__all__ = ["MASComposition", "compose_mas", "embed_block", "agent_offsets"]


def embed_block(M: np.ndarray, offset: int, n: int, axis: int) -> np.ndarray:
    """Place the agent block ``M`` at rows (``axis=0``) or columns (``axis=1``) ``offset:`` of zeros ``n`` wide.

    Parameters
    ----------
    M : ndarray, shape (n_i, k) for ``axis=0``, (k, n_i) for ``axis=1``
    offset : int
        ``sum_{q<i} n_q``.
    n : int
        Overall state dimension.

    Returns
    -------
    ndarray, shape (n, k) (``[0 M^T 0]^T``, a channel ``B^i``) or (k, n) (``[0 M 0]``, an output ``C_i``)
    """
    if axis == 0:
        out = np.zeros((n, M.shape[1]))
        out[offset:offset + M.shape[0]] = M
    else:
        out = np.zeros((M.shape[0], n))
        out[:, offset:offset + M.shape[1]] = M
    return out


def agent_offsets(dims) -> np.ndarray:
    """Offsets of the agents' blocks in ``x``: ``[0, n_0, n_0 + n_1, ..., n]``, shape ``(N + 1,)``."""
    return np.cumsum([0] + list(dims))


class MASComposition(NamedTuple):
    """The overall system of ``N`` agents (module docstring); the field names are :class:`Scenario` fields,
    so ``Scenario(**composition._asdict(), graph=..., x0=..., ...)`` builds the scenario."""

    A: np.ndarray  # (n, n) diag(breve A_i), eq. (LTIsys)
    channels: list  # N arrays (n, m_i): B^i = [0 breve B_i^T 0]^T, eq. (Busplit)
    C: list  # N arrays (p_i, n): C_i = [0 breve C_i 0], eq. (localmeasure)
    known: list  # [(0,), ..., (N-1,)]: node i knows u_i only, eq. (splitinput)
    links: tuple  # (0, ..., N-1): controller i uses xhat_i, eq. (linearfeedback)
    mas_agents: tuple  # the N float64 blocks (breve A_i, breve B_i, breve C_i), eq. (HMAS)


def compose_mas(agents, *, name: str = "agents") -> MASComposition:
    """The overall system of the agents ``(breve A_i, breve B_i, breve C_i)`` (eq. HMAS, Section AIHMAS).

    Parameters
    ----------
    agents : sequence of N triples of array_like
        ``breve A_i`` shape ``(n_i, n_i)`` (a scalar is ``(1, 1)``), ``breve B_i`` shape
        ``(n_i, m_i)`` (a vector or scalar is one column), ``breve C_i`` shape ``(p_i, n_i)``
        (a vector is one row). Real numbers; finiteness, squareness and rank are the
        caller's boundary checks (:class:`Scenario` refuses them by name).
    name : str, default "agents"
        What the caller calls ``agents``, for error messages (``"mas_agents"`` for the key of
        scenario files).

    Returns
    -------
    MASComposition
        ``A (n, n)``, ``channels[i] (n, m_i)``, ``C[i] (p_i, n)``, ``known[i] = (i,)``,
        ``links = (0, ..., N-1)`` and the agent blocks as float64 arrays (``n = sum_i n_i``).

    Raises
    ------
    ValueError
        ``breve B_i`` without ``n_i`` rows or ``breve C_i`` without ``n_i`` columns
        (``"{name}[i]: ..."``, naming the agent).
    """
    blocks = []
    for i, (Ai, Bi, Ci) in enumerate(agents):
        Ai = np.atleast_2d(np.asarray(Ai, dtype=float))
        ni = Ai.shape[0]
        Bi = np.asarray(Bi, dtype=float)
        Bi = Bi.reshape(ni, -1) if Bi.ndim < 2 else Bi
        Ci = np.atleast_2d(np.asarray(Ci, dtype=float))
        if Bi.shape[0] != ni or Ci.shape[1] != ni:
            raise ValueError(f"{name}[{i}]: B must have {ni} rows and C {ni} columns, "
                             f"got B of shape {Bi.shape} and C of shape {Ci.shape}")
        blocks.append((Ai, Bi, Ci))
    A = block_diag(*[a for a, _, _ in blocks])
    n = A.shape[0]
    offs = agent_offsets(a.shape[0] for a, _, _ in blocks)
    channels = [embed_block(Bi, offs[i], n, axis=0) for i, (_, Bi, _) in enumerate(blocks)]
    C = [embed_block(Ci, offs[i], n, axis=1) for i, (_, _, Ci) in enumerate(blocks)]
    N = len(blocks)
    return MASComposition(A=A, channels=channels, C=C, known=[(i,) for i in range(N)], links=tuple(range(N)),
                          mas_agents=tuple(blocks))
