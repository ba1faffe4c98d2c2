"""The paper's NE2 example (Section NE2; NE3 in Section NE3), transcribed once for the tests.

This is a transcription from the paper, independent of :mod:`dobs_envs.scenarios.paper`
(the code under test); ``tests/test_paper_transcription.py`` checks once that the two agree,
and every other test takes NE2 from here. Indices are 0-based (the paper's are 1-based:
state ``x_k`` is index ``k - 1``, node ``i`` is ``i - 1``, channel ``B^k`` is ``k - 1``).

The paper prints ``T_id`` to 4 decimals; its ``0.7071`` is ``1/sqrt(2)`` (``-6.8e-6``), so the
table below holds the exact values.
"""
from __future__ import annotations

import numpy as np

N_STATES, N_NODES, N_CHANNELS = 9, 6, 5

#: entries of ``A`` equal to 1 (all others 0): paper a_12, a_14, a_29, a_34, a_47, a_56, a_78, a_89
A_ONES = ((0, 1), (0, 3), (1, 8), (2, 3), (3, 6), (4, 5), (6, 7), (7, 8))
#: rows holding a 1 in the columns ``B^1..B^5``: e_2, e_4, e_1 + e_5 + e_6, e_3 + e_9, e_1
CHANNEL_ROWS = ((1,), (3,), (0, 4, 5), (2, 8), (0,))
#: the state each node measures, ``C_i = e_k^T``: x_1, x_3, x_5, x_7, x_2, x_4
OUTPUT_STATES = (0, 2, 4, 6, 1, 3)
#: the input channel each observer node knows: ``u_i = u^i`` (i = 1..5), ``u_6 = u^5``
KNOWN = (0, 1, 2, 3, 4, 4)

_S = float(np.sqrt(0.5))
#: ``T_1d^T .. T_6d^T`` as printed (one row per column of ``T_id``)
T_D_ROWS = (
    ((1, 0, 0, 0, 0, 0, 0, 0, 0),),
    ((0, 0, 0, 0, 0, 0, 0.5, -_S, 0.5),
     (0, 0, 0, -_S, 0, 0, 0.5, 0, -0.5),
     (0, 0, -1, 0, 0, 0, 0, 0, 0)),
    ((0, 0, 0, 0, 0, -1, 0, 0, 0),
     (0, 0, 0, 0, 1, 0, 0, 0, 0)),
    ((0, 0, 0, 0, 0, 0, 0, 1, 0),
     (0, 0, 0, 0, 0, 0, 0, 0, 1),
     (0, 0, 0, 0, 0, 0, -1, 0, 0)),
    ((0, 1, 0, 0, 0, 0, 0, 0, 0),),
    ((0, 0, 0, 1, 0, 0, 0, 0, 0),),
)
#: NE3 adds ``B_v = [B^1 B^2]``, unknown to every node: ``T_2d = e_3``, the other ``T_id`` as NE2
NE3_B_V_CHANNELS = (0, 1)
NE3_T_2D_ROWS = ((0, 0, 1, 0, 0, 0, 0, 0, 0),)


def A() -> np.ndarray:
    """``A`` (9, 9)."""
    M = np.zeros((N_STATES, N_STATES))
    for i, j in A_ONES:
        M[i, j] = 1.0
    return M


def channels() -> list[np.ndarray]:
    """``[B^1, ..., B^5]``, each (9, 1)."""
    out = []
    for rows in CHANNEL_ROWS:
        b = np.zeros((N_STATES, 1))
        b[list(rows), 0] = 1.0
        out.append(b)
    return out


def outputs() -> list[np.ndarray]:
    """``[C_1, ..., C_6]``, each (1, 9)."""
    return [np.eye(N_STATES)[[k]] for k in OUTPUT_STATES]


def b_unknown(i: int, *, ne3: bool = False) -> np.ndarray:
    """The input node ``i`` does not know: the other four channels (and ``B_v`` for NE3), (9, 4 or 6)."""
    B = channels()
    cols = [B[k] for k in range(N_CHANNELS) if k != KNOWN[i]]
    if ne3:
        cols += [B[k] for k in NE3_B_V_CHANNELS]
    return np.hstack(cols)


def b_v() -> np.ndarray:
    """NE3's ``B_v = [B^1 B^2]`` (9, 2)."""
    B = channels()
    return np.hstack([B[k] for k in NE3_B_V_CHANNELS])


def t_d(i: int, *, ne3: bool = False) -> np.ndarray:
    """The printed ``T_id`` (9, delta_i) of NE2 (or NE3)."""
    rows = NE3_T_2D_ROWS if ne3 and i == 1 else T_D_ROWS[i]
    return np.array(rows, dtype=float).T
