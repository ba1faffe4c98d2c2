"""numba-compiled counterpart of :meth:`SeparationController.act_rows` for one copy.

The readable reference is :meth:`dobs_envs.control.laws.SeparationController.act_rows`
(batched numpy); :func:`law_copy` computes the same input for one copy from the
estimates of all observer nodes, so that a whole closed-loop run can stay in compiled
code (:mod:`dobs_envs.rollout`). The two are tested against each other
(``tests/test_rollout.py``).

Law codes (:data:`LAW_CODES`): 0 open loop (prescribed ``u(t)``), 1 linear feedback
(eq. linearfeedback), 2 tracking (``K xhat + r``), 3 ideal sliding mode (eq. idealslidinglaw
with eq. hfunc), 4 adaptive boundary-layer sliding mode (eqs. hepsfunc, adlawbeta).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from ..numba_cache import ensure_fresh

ensure_fresh()  # numba's cache keys each file alone: drop caches built from other kernel sources

__all__ = ["LAW_CODES", "LawArrays", "law_copy", "law_arrays"]

#: controller kind -> integer code of :func:`law_copy`
LAW_CODES = {"open_loop": 0, "feedback": 1, "tracking": 2, "sliding_mode": 3, "adaptive_sliding_mode": 4}

# IEEE arithmetic (no fast-math), as the environment kernels
_njit = numba.njit(cache=True, fastmath=False, nogil=True, error_model="numpy")


class LawArrays(NamedTuple):
    """A controller of :mod:`dobs_envs.control.laws` as :func:`law_copy` reads it (:func:`law_arrays`)."""

    code: int  # LAW_CODES
    row_link: np.ndarray  # (m,) int64 observer node feeding input row j
    K: np.ndarray  # (m, n) stacked K^k
    BtP: np.ndarray  # (m, n) stacked (B^k)^T P
    starts: np.ndarray  # (Nc,) int64 first column of each channel
    ends: np.ndarray  # (Nc,) int64 end of each channel
    beta0: float  # initial (code 3: fixed) gain, eqs. (idealslidinglaw), (adlawbeta)
    sigma_beta: float  # leakage of eq. (adlawbeta)
    phi_beta: float  # adaptation gain of eq. (adlawbeta)
    epsilon: float  # boundary layer of eq. (hepsfunc)


def law_arrays(ctrl, m: int, n: int) -> LawArrays:
    """The :class:`LawArrays` of a controller of :mod:`dobs_envs.control.laws`; for the open-loop
    :class:`PrescribedInput` the matrices are zeros and ``Nc = 0``."""
    kind = getattr(ctrl, "kind", "open_loop")
    code = LAW_CODES[kind]
    if code == 0:
        z = np.zeros((m, n))
        return LawArrays(code=code, row_link=np.zeros(m, np.int64), K=z, BtP=z, starts=np.zeros(0, np.int64),
                         ends=np.zeros(0, np.int64), beta0=0.0, sigma_beta=0.0, phi_beta=0.0, epsilon=1.0)
    starts = np.asarray(ctrl.starts, dtype=np.int64)
    ends = np.append(starts[1:], m).astype(np.int64)
    BtP = ctrl.BtP if ctrl.BtP is not None else np.zeros((m, n))
    return LawArrays(code=code, row_link=np.asarray(ctrl.row_link, dtype=np.int64),
                     K=np.ascontiguousarray(ctrl.K, dtype=float), BtP=np.ascontiguousarray(BtP, dtype=float),
                     starts=starts, ends=ends, beta0=ctrl.beta0, sigma_beta=ctrl.sigma_beta, phi_beta=ctrl.phi_beta,
                     epsilon=ctrl.epsilon)


@_njit
def law_copy(law, xhat, x, oracle, r, cmd, beta, eps, phi_beta, decay, gain, u, w):
    """The input of one copy, in place: ``u (m,)``; updates ``beta (Nc,)`` in place.

    Parameters
    ----------
    law : :class:`LawArrays` (``code``, ``row_link``, ``K``, ``BtP``, ``starts``, ``ends`` are read;
        the per-copy ``eps``, ``phi_beta`` below replace its scalars).
    xhat : (N, n) estimates of all observer nodes; ``x (n,)`` the true state (used for every
        row when ``oracle``).
    r, cmd : (m,) reference command (tracking) and prescribed input (open loop).
    beta : (Nc,) adaptive gains (fixed gains for code 3). ``eps``, ``phi_beta`` : boundary
        layer and adaptation gain (code 4); ``decay = exp(-sigma T)``, ``gain = (1 - decay)/sigma``
        (``T`` when ``sigma = 0``): the exact leakage step of :mod:`dobs_envs.control.laws`.
    w : (m,) scratch.
    """
    code, row_link, K, BtP, starts, ends = law.code, law.row_link, law.K, law.BtP, law.starts, law.ends
    m = u.shape[0]
    n = K.shape[1]
    if code == 0:
        for j in range(m):
            u[j] = cmd[j]
        return
    for j in range(m):
        src = x if oracle else xhat[row_link[j]]
        s = 0.0
        t = 0.0
        for q in range(n):
            s += K[j, q] * src[q]
            t += BtP[j, q] * src[q]
        u[j] = s + r[j] if code == 2 else s
        w[j] = t
    if code < 3:
        return
    for c in range(starts.shape[0]):
        a, e = starts[c], ends[c]
        nrm2 = 0.0
        for j in range(a, e):
            nrm2 += w[j] * w[j]
        nrm = math.sqrt(nrm2)
        bc = beta[c]
        for j in range(a, e):
            if code == 3:  # eq. (hfunc)
                hj = w[j] / nrm if nrm > 0 else 0.0
            elif bc * nrm > eps:  # eq. (hepsfunc), outside the boundary layer
                hj = w[j] / (nrm if nrm > 0 else 1.0)
            else:
                hj = bc * w[j] / eps
            u[j] -= bc * hj
        if code == 4:  # eq. (adlawbeta), exact leakage step for the held argument
            beta[c] = decay * bc + gain * phi_beta * nrm
