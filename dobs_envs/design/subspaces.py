"""Subspace arithmetic with SVD rank decisions and an explicit tolerance.

Every rank decided in the design layer goes through :func:`rank_tol` /
:func:`numerical_rank`: a singular value ``s`` counts as nonzero when
``s > tol`` with ``tol = max(shape) * eps * max(1, s_max) * RTOL_FACTOR``
unless the caller passes an absolute ``tol``. Bases returned here have
orthonormal columns, so that ``Q @ Q.T`` is the orthogonal projector onto the
subspace.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "DEFAULT_RTOL",
    "rank_tol",
    "numerical_rank",
    "orth",
    "null_space",
    "left_null_space",
    "annihilator",
    "subspace_sum",
    "subspace_intersection",
    "orth_complement",
    "projector",
    "projector_distance",
    "contains",
    "STABILITY_TOL",
    "stable_mask",
    "is_hurwitz",
]

#: Relative tolerance used for rank decisions when none is given. Chosen well
#: above double-precision round-off of the products formed in the design
#: (a few hundred flops per entry) and well below the smallest singular value
#: of any well-posed example (~1e-3 for the paper's systems).
DEFAULT_RTOL = 1e-9


def rank_tol(s: np.ndarray, shape: tuple[int, ...], tol: float | None = None) -> float:
    """Absolute threshold on singular values ``s`` of a matrix of ``shape``."""
    if tol is not None:
        return float(tol)
    smax = float(s[0]) if s.size else 0.0
    return max(DEFAULT_RTOL * max(1.0, smax), max(shape, default=1) * np.finfo(float).eps * smax)


def _svd(M: np.ndarray):
    M = np.asarray(M, dtype=float)
    if M.size == 0:
        return (
            np.zeros((M.shape[0], 0)),
            np.zeros(0),
            np.zeros((0, M.shape[1] if M.ndim == 2 else 0)),
        )
    return np.linalg.svd(M, full_matrices=True)


def numerical_rank(M: np.ndarray, tol: float | None = None) -> int:
    """Rank of ``M`` decided by SVD with threshold :func:`rank_tol`."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.size == 0:
        return 0
    s = np.linalg.svd(M, compute_uv=False)
    return int(np.sum(s > rank_tol(s, M.shape, tol)))


def orth(M: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis (columns) of ``Im M``; shape ``(rows, rank)``."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.size == 0:
        return np.zeros((M.shape[0], 0))
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    r = int(np.sum(s > rank_tol(s, M.shape, tol)))
    return U[:, :r].copy()


def null_space(M: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis (columns) of ``ker M``; shape ``(cols, cols - rank)``."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    ncols = M.shape[1]
    if M.size == 0:
        return np.eye(ncols)
    _, s, Vt = np.linalg.svd(M, full_matrices=True)
    r = int(np.sum(s > rank_tol(s, M.shape, tol)))
    return Vt[r:].T.copy()


def left_null_space(M: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis (columns) of the left null space ``{w : w^T M = 0}``."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    return null_space(M.T, tol)


def annihilator(M: np.ndarray, tol: float | None = None) -> np.ndarray:
    """The paper's annihilator of ``M``: rows form an orthonormal basis of the
    left null space, so ``annihilator(M) @ M == 0``. Shape ``(rows - rank, rows)``.
    """
    return left_null_space(M, tol).T


def subspace_sum(*bases: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis of ``Im X1 + Im X2 + ...`` (all with the same row count)."""
    n = bases[0].shape[0]
    stacked = np.hstack([np.asarray(b, dtype=float).reshape(n, -1) for b in bases])
    return orth(stacked, tol)


def orth_complement(Q: np.ndarray, n: int | None = None, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis of ``(Im Q)^perp`` in ``R^n``."""
    Q = np.asarray(Q, dtype=float)
    if n is None:
        n = Q.shape[0]
    if Q.size == 0:
        return np.eye(n)
    return left_null_space(Q.reshape(n, -1), tol)


def subspace_intersection(X: np.ndarray, Y: np.ndarray, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis of ``Im X ∩ Im Y`` via ``(X^perp + Y^perp)^perp``."""
    n = X.shape[0]
    Xc = orth_complement(orth(X, tol), n, tol)
    Yc = orth_complement(orth(Y, tol), n, tol)
    return orth_complement(subspace_sum(Xc, Yc, tol=tol), n, tol)


def projector(Q: np.ndarray) -> np.ndarray:
    """Orthogonal projector onto ``Im Q`` (``Q`` need not be orthonormal)."""
    B = orth(Q)
    return B @ B.T


def projector_distance(X: np.ndarray, Y: np.ndarray) -> float:
    """Spectral-norm distance ``||P_X - P_Y||_2`` between the orthogonal projectors
    onto ``Im X`` and ``Im Y`` (the sine of the largest principal angle when the
    dimensions agree, 1 when they differ)."""
    n = X.shape[0]
    PX = projector(X) if X.size else np.zeros((n, n))
    PY = projector(Y) if Y.size else np.zeros((n, n))
    return float(np.linalg.norm(PX - PY, 2))


def contains(X: np.ndarray, Y: np.ndarray, tol: float = 1e-8) -> bool:
    """True when ``Im Y ⊆ Im X`` (relative residual of projecting Y below ``tol``)."""
    Y = np.asarray(Y, dtype=float)
    if Y.size == 0:
        return True
    Q = orth(X)
    res = Y - Q @ (Q.T @ Y)
    return bool(np.linalg.norm(res) <= tol * max(1.0, np.linalg.norm(Y)))


#: An eigenvalue counts as stable only when ``Re(lambda) < -STABILITY_TOL * max(1, |A|)``.
#: Marginal modes (integrators, imaginary-axis pairs) are therefore *not* stable,
#: as Lemma 2 / Table I require for (strong) detectability.
STABILITY_TOL = 1e-8


def stable_mask(eigenvalues: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Boolean mask of eigenvalues that are strictly stable (see :data:`STABILITY_TOL`)."""
    ev = np.asarray(eigenvalues)
    return ev.real < -STABILITY_TOL * max(1.0, float(scale))


def is_hurwitz(M: np.ndarray) -> bool:
    """True when every eigenvalue of the square matrix ``M`` is strictly stable."""
    M = np.asarray(M, dtype=float)
    if M.size == 0:
        return True
    return bool(np.all(stable_mask(np.linalg.eigvals(M), np.linalg.norm(M, 2))))
