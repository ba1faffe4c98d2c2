"""Controller and observer gains of the paper's numerical examples.

* :func:`shifted_are_feedback` -- NE2: ``(A + sI)^T X + X (A + sI) - X B R^{-1} B^T X + Q = 0``,
  ``K = -R^{-1} B^T X``; with ``R = I`` the rows of channel ``k`` are
  ``K^k = -(B^k)^T X`` (eq. ``linearfeedback``). All closed-loop eigenvalues of
  ``A + B K`` then have ``Re < -s``.
* :func:`lyapunov_P` -- NE3: ``A_cl^T P + P A_cl = -Q`` (``A_cl = A + B K``), the
  sliding-mode gain ``P`` of eqs. ``centralsliding``/``slidingfeedback``.
* :func:`observer_are_gain` -- NE1: ``(A + sI) X + X (A + sI)^T - X C^T C X + I = 0``,
  ``L = -X C^T`` (the ``breve L_i`` of eq. ``obidynamicMAS``); ``A + L C`` has
  eigenvalues with ``Re < -s``.

Solvers: :func:`scipy.linalg.solve_continuous_are` and
:func:`scipy.linalg.solve_continuous_lyapunov`; nothing is inverted.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from .. import assumptions as _asm
from ..linalg.subspaces import is_hurwitz
from ..linalg.validation import as_float, as_matrix, as_square, as_symmetric

__all__ = ["shifted_are_feedback", "lyapunov_P", "observer_are_gain", "split_gain"]


def _shift(shift) -> float:
    return as_float(shift, "shift", minimum=0.0)


def shifted_are_feedback(A, B, shift: float = 0.2, Q=None, R=None) -> tuple[np.ndarray, np.ndarray]:
    """State feedback from the shifted ARE of Section NE2.

    Solves ``(A + sI)^T X + X (A + sI) - X B R^{-1} B^T X + Q = 0`` for the
    stabilising ``X = X^T >= 0`` and returns ``K = -R^{-1} B^T X``.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
        Stacked input channels ``[B^1 ... B^K]`` (eq. ``Busplit``).
    shift : float, default 0.2
        Decay-rate margin ``s >= 0``: ``eig(A + B K)`` has ``Re < -s``.
    Q : array_like, shape (n, n), optional
        Symmetric PSD state weight (default ``I``; ``(Q, A + sI)`` must be detectable).
    R : array_like, shape (m, m), optional
        Symmetric PD input weight (default ``I``).

    Returns
    -------
    X : ndarray, shape (n, n)
    K : ndarray, shape (m, n)
        With ``R = I``, rows of channel ``k`` are ``K^k = -(B^k)^T X`` (use
        :func:`split_gain` to cut ``K`` per channel).

    Raises
    ------
    StabilizabilityError
        If some uncontrollable eigenvalue has ``Re >= -shift`` (Assumption 3,
        with the margin the shifted ARE needs).
    ValueError
        Bad shapes/weights, or no stabilising solution exists (e.g. ``Q`` not
        detecting an unstable mode).
    """
    A = as_square(A, "A")
    n = A.shape[0]
    B = as_matrix(B, "B", rows=n, vector_as="col")
    m = B.shape[1]
    s = _shift(shift)
    Q = as_symmetric(Q, n, "Q", definite=False)
    R = as_symmetric(R, m, "R", definite=True)
    _asm.check_stabilizable(A, B, margin=s)
    As = A + s * np.eye(n)
    try:
        X = sla.solve_continuous_are(As, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(
            "shifted_are_feedback: the ARE (A + sI)^T X + X (A + sI) - X B R^-1 B^T X + Q = 0 "
            f"has no stabilising solution (is (Q, A + {s:g} I) detectable?): {exc}"
        ) from None
    X = 0.5 * (X + X.T)
    K = -np.linalg.solve(R, B.T @ X)
    return X, K


def split_gain(K: np.ndarray, channel_slices) -> tuple[np.ndarray, ...]:
    """Cut ``K (m, n)`` into per-channel rows ``K^k = K[channel_slices[k]]``."""
    K = np.asarray(K)
    return tuple(K[sl].copy() for sl in channel_slices)


def lyapunov_P(A_cl, Q=None) -> np.ndarray:
    """Solve ``A_cl^T P + P A_cl = -Q`` (Section NE3, ``A_cl = A + B K``).

    Parameters
    ----------
    A_cl : array_like, shape (n, n)
        Must be Hurwitz (every ``Re lambda < 0``).
    Q : array_like, shape (n, n), optional
        Symmetric positive definite (default ``I``), so ``P = P^T > 0``.

    Returns
    -------
    P : ndarray, shape (n, n), symmetric positive definite.

    Raises
    ------
    ValueError
        If ``A_cl`` is not Hurwitz (then no positive definite ``P`` exists)
        or ``Q`` is not symmetric positive definite.
    """
    A_cl = as_square(A_cl, "A_cl")
    n = A_cl.shape[0]
    Q = as_symmetric(Q, n, "Q", definite=True)
    if not is_hurwitz(A_cl):
        ev = np.linalg.eigvals(A_cl)
        worst = ev[np.argmax(ev.real)]
        raise ValueError(
            "lyapunov_P: A_cl is not Hurwitz (largest real part of an eigenvalue "
            f"{worst.real:.6g}); A_cl^T P + P A_cl = -Q has no positive definite solution"
        )
    P = sla.solve_continuous_lyapunov(A_cl.T, -Q)
    return 0.5 * (P + P.T)


def observer_are_gain(A, C, shift: float = 0.2, *, name: str = "(A, C)") -> np.ndarray:
    """Observer gain of Section NE1 from the shifted filter ARE.

    Solves ``(A + sI) X + X (A + sI)^T - X C^T C X + I = 0`` and returns
    ``L = -X C^T``, so ``A + L C`` has eigenvalues with ``Re < -s``
    (the ``breve L_i`` of eq. ``obidynamicMAS``).

    Parameters
    ----------
    A : array_like, shape (n, n)
    C : array_like, shape (p, n)
    shift : float, default 0.2
    name : str
        Label of the pair in error messages (e.g. ``"agent 3"``).

    Returns
    -------
    L : ndarray, shape (n, p)

    Raises
    ------
    DetectabilityError
        If an unobservable eigenvalue has ``Re >= -shift``.
    """
    A = as_square(A, "A")
    n = A.shape[0]
    C = as_matrix(C, "C", cols=n)
    p = C.shape[0]
    s = _shift(shift)
    _asm.check_detectable(A, C, margin=s, name=name)
    As = A + s * np.eye(n)
    try:
        X = sla.solve_continuous_are(As.T, C.T, np.eye(n), np.eye(p))
    except (np.linalg.LinAlgError, ValueError) as exc:  # pragma: no cover - guarded above
        raise ValueError(f"observer_are_gain: filter ARE for {name} has no stabilising solution: {exc}") from None
    X = 0.5 * (X + X.T)
    return -X @ C.T
