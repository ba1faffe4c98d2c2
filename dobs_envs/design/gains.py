"""Controller and observer gains of the paper's numerical examples.

* :func:`shifted_are_feedback` -- NE2: ``(A + sI)^T X + X (A + sI) - X B R^{-1} B^T X + Q = 0``,
  ``K = -R^{-1} B^T X``; with ``R = I`` the rows of channel ``k`` are
  ``K^k = -(B^k)^T X`` (eq. ``linearfeedback``). All closed-loop eigenvalues of
  ``A + B K`` then have ``Re < -s``.
* :func:`lyapunov_P` -- NE3: ``A_cl^T P + P A_cl = -Q`` (``A_cl = A + B K``), the
  sliding-mode gain ``P`` of eqs. ``centralsliding``/``slidingfeedback``;
  :func:`sliding_mode_P` forms ``A_cl`` from ``(A, B, K)``.
* :func:`observer_are_gain` -- NE1: ``(A + sI) X + X (A + sI)^T - X C^T C X + I = 0``,
  ``L = -X C^T`` (the ``breve L_i`` of eq. ``obidynamicMAS``); ``A + L C`` has
  eigenvalues with ``Re < -s``.

* :func:`stabilising_are` -- the one call of the ARE solver behind all of them (and the
  rendezvous LQR of :mod:`dobs_envs.scenarios.mas_tasks`): the stabilising ``X``,
  symmetrised, or a ``ValueError`` naming the equation.

Solvers: :func:`scipy.linalg.solve_continuous_are` and
:func:`scipy.linalg.solve_continuous_lyapunov`; nothing is inverted.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from .. import assumptions as _asm
from ..linalg.subspaces import is_hurwitz
from ..linalg.validation import as_float, as_matrix, as_square, as_symmetric

__all__ = ["stabilising_are", "shifted_are_feedback", "lyapunov_P", "sliding_mode_P", "observer_are_gain",
           "split_gain"]


def _shift(shift) -> float:
    return as_float(shift, "shift", minimum=0.0)


def stabilising_are(A, B, Q, R, *, what: str = "the ARE", hint: str = "") -> np.ndarray:
    """Stabilising solution of ``A^T X + X A - X B R^{-1} B^T X + Q = 0``, symmetrised exactly.

    :func:`scipy.linalg.solve_continuous_are` (Schur method, no inverse), then
    ``X = (X + X^T) / 2``. Shapes are checked here (values pass unchanged); symmetry of
    ``Q`` and ``R`` and the existence of the solution are the solver's, reported as below.
    The weights' definiteness and the stabilisability margin are the caller's boundary
    checks (:func:`shifted_are_feedback`, :func:`observer_are_gain`).

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q : array_like, shape (n, n)
    R : array_like, shape (m, m)
    what : str
        The equation's name in the error message (e.g. the caller and its ARE).
    hint : str
        Appended to "has no stabilising solution" (e.g. which pair must be detectable).

    Returns
    -------
    X : ndarray, shape (n, n), symmetric.

    Raises
    ------
    ValueError
        Bad shapes (naming the argument), or ``"{what} has no stabilising solution{hint}: ..."``
        with the solver's reason.
    """
    A = as_square(A, "A")
    n = A.shape[0]
    B = as_matrix(B, "B", rows=n)
    m = B.shape[1]
    Q = as_matrix(Q, "Q", rows=n, cols=n)
    R = as_matrix(R, "R", rows=m, cols=m)
    try:
        X = sla.solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(f"{what} has no stabilising solution{hint}: {exc}") from None
    return 0.5 * (X + X.T)


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
    X = stabilising_are(As, B, Q, R, what="shifted_are_feedback: the ARE (A + sI)^T X + X (A + sI) - X B R^-1 B^T X "
                        "+ Q = 0", hint=f" (is (Q, A + {s:g} I) detectable?)")
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


def sliding_mode_P(A, B, K, Q=None) -> np.ndarray:
    """The gain ``P`` of the sliding-mode law ``u = K x - beta h(B^T P x)`` (eq. ``centralsliding``).

    Section NE3: ``P`` is the positive definite solution of
    ``(A + B K)^T P + P (A + B K) = -Q`` (NE3: ``Q = I``), i.e.
    :func:`lyapunov_P` of ``A_cl = A + B K``.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
        Stacked channels ``[B^1 ... B^K]`` (eq. ``Busplit``).
    K : array_like, shape (m, n)
        Stacked feedback ``col(K^k)`` with ``A + B K`` Hurwitz (e.g. from :func:`shifted_are_feedback`).
    Q : array_like, shape (n, n), optional
        As for :func:`lyapunov_P` (default ``I``).

    Returns ``P (n, n)`` and raises as :func:`lyapunov_P` does; a ``ValueError`` names a
    badly shaped ``A``, ``B`` or ``K``.
    """
    A = as_square(A, "A")
    n = A.shape[0]
    B = as_matrix(B, "B", rows=n, vector_as="col")
    K = as_matrix(K, "K", rows=B.shape[1], cols=n, vector_as="row")
    return lyapunov_P(A + B @ K, Q)


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
    X = stabilising_are(As.T, C.T, np.eye(n), np.eye(p), what=f"observer_are_gain: filter ARE for {name}")
    return -X @ C.T
