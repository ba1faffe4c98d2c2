"""Subspace arithmetic with SVD rank decisions and an explicit tolerance.

Every rank decided in the design layer and in :mod:`dobs_envs.assumptions`
goes through :func:`rank_tol` / :func:`numerical_rank`: a singular value ``s``
counts as nonzero when ``s > tol`` with
``tol = max(DEFAULT_RTOL * max(1, s_max), max(shape) * eps * s_max)`` unless
the caller passes an absolute ``tol``. Bases returned here have orthonormal
columns, so that ``Q @ Q.T`` is the orthogonal projector onto the subspace.
Stability is classified with :data:`STABILITY_TOL` (marginal = not stable).
A decision that double precision cannot make reliably raises
:class:`IllConditionedError` (a ``ValueError``) saying which.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy.linalg import lapack as _lapack

__all__ = [
    "IllConditionedError",
    "DEFAULT_RTOL",
    "rank_tol",
    "numerical_rank",
    "scaled_rank",
    "orth",
    "null_space",
    "left_null_space",
    "annihilator",
    "subspace_sum",
    "observability_staircase",
    "subspace_intersection",
    "orth_complement",
    "projector",
    "projector_distance",
    "contains",
    "STABILITY_TOL",
    "stable_mask",
    "is_hurwitz",
    "EIG_CLUSTER_SAFETY",
    "eigenvalue_clusters",
    "classify_stable_eigenvalues",
]

class IllConditionedError(np.linalg.LinAlgError):
    """A rank or stability decision, or a result, that double precision cannot
    deliver reliably for the given data (the message says which and why).

    Subclass of :class:`numpy.linalg.LinAlgError`, hence of ``ValueError``:
    it is a property of the input (too close to a rank or stability boundary,
    or too badly scaled even after balancing), not an internal error.
    """


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


def scaled_rank(M: np.ndarray, tol: float | None = None) -> int:
    """Rank of ``M / ||M||_2`` (:func:`numerical_rank` of the normalised matrix): the
    decision does not depend on the units of ``M``. The scaling goes through
    ``max |M_ij|`` first, so entries near the overflow threshold are harmless."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.size == 0:
        return 0
    mx = float(np.max(np.abs(M)))
    if mx == 0.0:
        return 0
    Ms = M / mx
    return numerical_rank(Ms / np.linalg.norm(Ms, 2), tol)


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


def observability_staircase(M: np.ndarray, H: np.ndarray, tol: float | None = None):
    r"""Orthogonal observability staircase of the pair ``(M, H)`` in ``O(r^3)`` flops.

    Returns an orthogonal ``U = [W_o, V_o]`` (``r x r``) and ``r_o`` with::

        U^T M U = [[M_o, 0], [M_21, M_u]],    H U = [H_o, 0],

    ``(M_o, H_o)`` observable (``r_o x r_o``) and ``Im V_o`` the unobservable
    subspace (the largest ``M``-invariant subspace in ``ker H``).

    Algorithm: the controllability staircase of the dual pair ``(M^T, H^T)``
    (Van Dooren; SLICOT ``TB01UD``). Step ``k`` compresses the block ``X_k``
    that couples the part found so far into the remaining ``s_k`` coordinates
    (``X_1 = H^T``): a Householder QR ``X_k = Q_k [R_k; 0]`` (LAPACK
    ``dgeqrf``), then an SVD of the small triangular factor,
    ``R_k = U_k S_k V_k^T``; ``rank X_k`` is decided on the singular values
    ``S_k`` (those of ``X_k``) against one absolute threshold. ``Q_k`` is
    applied as reflectors (``dormqr``, ``O(r s_k c_k)`` flops for ``c_k``
    columns) and ``U_k`` on its ``c_k`` rows, so the whole reduction costs
    ``O(r^3)``, against ``O(r^4)`` for recomputing the kernel of
    ``[H; V_k^perp M]`` by a full SVD at each of up to ``r`` steps.

    Parameters
    ----------
    M : (r, r) ndarray
    H : (q, r) ndarray
    tol : float, optional
        Absolute threshold on the singular values of every block. Default:
        :func:`rank_tol` of the stacked ``[H; M]`` (``DEFAULT_RTOL * max(1,
        ||[H; M]||_2)``), the scale of the data every block is made of.

    Returns
    -------
    U : ndarray (r, r), orthogonal
    r_o : int
        Dimension of the observable part.
    """
    M = np.asarray(M, dtype=float)
    H = np.asarray(H, dtype=float)
    r = M.shape[0]
    if r == 0:
        return np.eye(0), 0
    if tol is None:
        S = np.vstack([H, M])
        tol = rank_tol(np.array([np.linalg.norm(S, 2)]), S.shape)
    T = np.array(M.T, order="F")  # the dual state matrix (a copy), transformed in place
    U = np.asfortranarray(np.eye(r))
    X = np.array(H.T, order="F")  # the dual input (r x q), a copy
    k0 = 0
    while k0 < r and X.shape[1] > 0:
        s, c = X.shape
        qr, tau, _, info = _lapack.dgeqrf(X)
        if info != 0:  # pragma: no cover - LAPACK argument error
            raise np.linalg.LinAlgError(f"dgeqrf failed (info={info})")
        k = min(s, c)
        R = np.triu(qr[:k, :])
        Ur, sv, _ = np.linalg.svd(R, full_matrices=True)
        rho = int(np.sum(sv > tol))
        if rho == 0:
            break
        refl = qr[:, :k]
        lw = 64 * max(r, 1)
        T[k0:, :], _, info1 = _lapack.dormqr("L", "T", refl, tau, T[k0:, :], lw)
        T[:, k0:], _, info2 = _lapack.dormqr("R", "N", refl, tau, T[:, k0:], lw)
        U[:, k0:], _, info3 = _lapack.dormqr("R", "N", refl, tau, U[:, k0:], lw)
        if info1 or info2 or info3:  # pragma: no cover - LAPACK argument error
            raise np.linalg.LinAlgError("dormqr failed")
        T[k0:k0 + k, :] = Ur.T @ T[k0:k0 + k, :]
        T[:, k0:k0 + k] = T[:, k0:k0 + k] @ Ur
        U[:, k0:k0 + k] = U[:, k0:k0 + k] @ Ur
        X = np.asfortranarray(T[k0 + rho:, k0:k0 + rho])
        k0 += rho
    return np.ascontiguousarray(U), k0


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


#: Safety factor on the backward error ``k * eps * ||M||_2`` of the eigenvalue
#: solver used by :func:`eigenvalue_clusters`.
EIG_CLUSTER_SAFETY = 1e3


def eigenvalue_clusters(M: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    r"""Computed eigenvalues of ``M`` and their grouping into clusters that may
    come from one (defective) eigenvalue.

    A backward-stable eigensolver returns the exact eigenvalues of ``M + dM``
    with ``||dM||_2 <= delta = EIG_CLUSTER_SAFETY * k * eps * ||M||_2``.
    Computed eigenvalues are put in one cluster when they lie in the same
    connected component of the ``delta``-pseudospectrum
    ``{z : sigma_min(M - z I) <= delta}``, i.e. when a perturbation of the
    size of the backward error could merge them. Connectivity is tested along
    the edges of the Gabriel graph of the computed eigenvalues (``i -- j``
    when no other eigenvalue lies inside the disk with diameter
    ``[lambda_i, lambda_j]``; it contains the Euclidean minimum spanning tree,
    and a segment passing next to a third eigenvalue would see *its*
    pseudospectrum): an edge joins ``i`` and ``j`` when ``sigma_min(M - z I)
    <= delta`` at ``z`` = 1/2, 1/4 and 3/4 of the way. Clusters are the
    connected components of the joined edges.

    Only edges that first-order perturbation theory cannot resolve are tested
    (``|lambda_i - lambda_j| <= 10 delta (kappa_i + kappa_j)``, ``kappa`` the
    eigenvalue condition number from the left and right eigenvectors,
    infinite for computed exactly defective eigenvalues), so well-conditioned,
    distinct eigenvalues are never lumped together, however large ``||M||``
    is. (A cluster radius ``~||M|| eps^(1/k)`` relative to the matrix norm is
    of order one for a matrix with one large eigenvalue and lumped distinct
    stable and unstable eigenvalues.) The computed members of a perturbed
    Jordan block (spread ``~(eps ||M||)^(1/m)`` around the exact value, inside
    the ``delta``-pseudospectrum) are joined. Genuinely distinct eigenvalues
    that a perturbation of size ``delta`` merges are lumped: double precision
    cannot tell them apart for this matrix.

    Parameters
    ----------
    M : (k, k) array_like
        Real square matrix.

    Returns
    -------
    ev : ndarray, shape (k,), complex
        Computed eigenvalues (``scipy.linalg.eig``).
    clusters : list of ndarray of int
        Index sets partitioning ``range(k)``; the partition is closed under
        complex conjugation (``M`` real).
    """
    M = np.asarray(M, dtype=float)
    k = M.shape[0]
    if k == 0:
        return np.zeros(0, dtype=complex), []
    ev, vl, vr = sla.eig(M, left=True, right=True)
    norm = float(np.linalg.norm(M, 2))
    delta = EIG_CLUSTER_SAFETY * k * np.finfo(float).eps * max(norm, np.finfo(float).tiny)
    yx = np.abs(np.sum(vl.conj() * vr, axis=0))
    nx = np.linalg.norm(vr, axis=0) * np.linalg.norm(vl, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(yx > 0, nx / yx, np.inf)
    parent = list(range(k))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    eye = np.eye(k)
    for i in range(k):
        for j in range(i + 1, k):
            gap = abs(ev[i] - ev[j])
            if gap > 10.0 * delta * (kappa[i] + kappa[j]) or find(i) == find(j):
                continue
            # Gabriel edge: no third eigenvalue strictly inside the diametral disk
            # (copies of an end point, e.g. repeated eigenvalues computed exactly,
            # do not count: with rounding they may sit "inside" each other's disks)
            centre = 0.5 * (ev[i] + ev[j])
            inside = np.abs(ev - centre) < 0.5 * gap * (1.0 - 1e-6)
            inside &= np.minimum(np.abs(ev - ev[i]), np.abs(ev - ev[j])) > 1e-6 * gap
            inside[[i, j]] = False
            if np.any(inside):
                continue
            merge = True
            for t in (0.5, 0.25, 0.75):
                z = ev[i] + t * (ev[j] - ev[i])
                if np.linalg.svd(M - z * eye, compute_uv=False)[-1] > delta:
                    merge = False
                    break
            if merge:
                parent[find(j)] = find(i)
    roots = np.array([find(i) for i in range(k)])
    clusters = [np.flatnonzero(roots == r) for r in dict.fromkeys(roots.tolist())]
    return ev, clusters


def classify_stable_eigenvalues(M: np.ndarray, scale: float | None = None):
    """Stability of the computed eigenvalues of ``M``, decided per cluster.

    The clusters of :func:`eigenvalue_clusters` are classified by their mean
    (a trace, well conditioned even for a perturbed Jordan block, whose
    members straddle the imaginary axis when the exact eigenvalue is 0) with
    :func:`stable_mask` (marginal counts as not stable). A cluster with a
    stable mean but a member that is not stable (a perturbed defective
    eigenvalue closer to the axis than its computed spread, or distinct
    eigenvalues double precision cannot separate) is not classified: calling
    a possibly unstable mode stable would claim too much, so an error is
    raised instead.

    Parameters
    ----------
    M : (k, k) array_like
    scale : float, optional
        Scale of :func:`stable_mask`; default ``||M||_2``.

    Returns
    -------
    ev : ndarray (k,), complex
        Computed eigenvalues.
    stable : ndarray (k,), bool
        Per-eigenvalue flag (constant on each cluster).
    means : ndarray (k,), complex
        Mean of the cluster of each eigenvalue.

    Raises
    ------
    IllConditionedError
        A cluster straddles the stability boundary with a stable mean
        (a :class:`numpy.linalg.LinAlgError`).
    """
    M = np.asarray(M, dtype=float)
    ev, clusters = eigenvalue_clusters(M)
    if scale is None:
        scale = float(np.linalg.norm(M, 2)) if M.size else 1.0
    stable = np.zeros(ev.size, dtype=bool)
    means = np.empty(ev.size, dtype=complex)
    for idx in clusters:
        mean = ev[idx].mean()
        means[idx] = mean
        stable[idx] = bool(stable_mask(np.array([mean]), scale)[0])
        if stable[idx[0]] and not np.all(stable_mask(ev[idx], scale)):
            raise IllConditionedError(
                f"cannot decide the stability of {idx.size} eigenvalues in double precision: "
                f"they form one pseudospectral cluster (mean {mean:.3g}) straddling the "
                f"stability boundary, with real parts in [{ev[idx].real.min():.3g}, "
                f"{ev[idx].real.max():.3g}] (matrix norm {scale:.3g}); the system is too "
                "ill-conditioned to classify these modes"
            )
    return ev, stable, means
