r"""Geometric characterisation of the strongly detectable subspace (Lemma 2).

This module is an *independent* second route to the subspace ``Im T_d`` of
Lemma 2 (``FUIO``) in the paper: it never calls :mod:`dobs_envs.design.lemma2`
(the Appendix algorithm), so comparing the two is a meaningful test.

Problem
-------
System ``x' = A x + B u`` with unknown input ``u`` (``B = B_{-i}``), output
``y = C x``. A functional observer ``z' = E z + F y``, ``w = z + G y`` with
``E`` Hurwitz estimates ``T^T x`` asymptotically for every ``u`` and every
initial condition iff (Lemma 2, set ``Omega``)::

    G C B = T^T B,    E T^T + (G C - T^T) A + (F - E G) C = 0.

(The error ``e = T^T x - z - G y`` then obeys ``e' = E e``.) We want the
largest row space ``Im T`` of such a ``T``.

Derivation (summary; the full argument is in the docstring of
:func:`reconstructibility_decomposition`)
-------------------------------------------------------------------------
Put ``H = T^T - G C``. The conditions become ``H B = 0`` and
``H A = E H + F C``; writing ``F = -H L`` (possible for any ``F`` because
``H`` may be taken of full row rank) this is ``H (A + L C) = E H``: the kernel
``K = ker H`` contains ``Im B`` and is ``(A + L C)``-invariant, i.e. ``K`` is a
``(C, A)``-conditioned invariant subspace containing ``Im B`` whose quotient
map ``E`` is Hurwitz ("outer stabilisable"), and ``Im T = K^perp + Im C^T``.

1. Every conditioned invariant containing ``Im B`` contains the *minimal* one,
   ``S* = lim S_k``, ``S_0 = Im B``, ``S_{k+1} = Im B + A (S_k ∩ ker C)``.
2. Modulo ``S*`` (coordinates ``xi = W^T x``, ``W`` an orthonormal basis of
   ``S*^perp``) the output injections keeping ``S*`` invariant act on the
   quotient pair ``(A_q, C_q)``; the unobservable modes of that pair are
   *fixed* (no injection moves them) and every other mode is assignable.
3. Hence the minimal outer-stabilisable conditioned invariant containing
   ``Im B`` is ``S_stab = S* + W U_q`` with ``U_q`` the undetectable subspace
   of ``(A_q, C_q)``, and the reconstructible functionals are
   ``Im T_d = S_stab^perp + Im C^T = (S_stab ∩ ker C)^perp``.

Special cases: ``B = 0`` gives ``S* = {0}``, ``(A_q, C_q) = (A, C)`` and
``Im T_d = (undetectable subspace of (A, C))^perp`` -- the detectable subspace
of Table I. The double integrator ``x1' = x2, x2' = u, y = x1`` has
``S* = R^2`` and ``S* ∩ ker C = span e2`` so only ``x1`` is reconstructible
(an observer without output derivatives cannot recover ``x2 = y'``).

Stability classification
------------------------
Marginal modes (``Re = 0``: integrators, imaginary-axis pairs) count as *not*
stable (:func:`~dobs_envs.linalg.subspaces.stable_mask`). Eigenvalues of
defective (Jordan) blocks are ill-conditioned: a nilpotent block of size
``k`` perturbed by round-off ``~1e-16`` has computed eigenvalues spread on a
circle of radius ``~1e-16^(1/k)`` (``~5e-4`` for the paper's 5-chain of
integrators after an orthogonal change of basis), some with ``Re < -1e-8``.
Classifying such eigenvalues one by one would call part of an integrator chain
stable. We therefore cluster the computed eigenvalues and classify each
cluster by its *mean*, which is well conditioned
(:func:`~dobs_envs.linalg.subspaces.classify_stable_eigenvalues`); the
invariant subspace is then taken from an ordered real Schur form.

A cluster is a set of computed eigenvalues that a perturbation of the size of
the eigensolver's backward error could merge (a connected component of that
pseudospectrum), *not* every eigenvalue within a radius ``~||M|| eps^(1/k)``:
such a radius is of order one for a quotient map with one large eigenvalue
(an invariant zero near ``-222`` when ``C B`` is small) or with several
defective eigenvalues ``-1, 0, 1``, and lumped stable and unstable modes into
one cluster classified by its mean -- an unstable unobserved mode was then
called reconstructible.

All rank decisions go through the SVD helpers of
:mod:`dobs_envs.linalg.subspaces` with the optional absolute tolerance ``tol``
(``None``: the helpers' relative default).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..linalg.subspaces import (
    DEFAULT_RTOL,
    annihilator,
    classify_stable_eigenvalues,
    null_space,
    orth,
    orth_complement,
    rank_tol,
    subspace_intersection,
    subspace_sum,
)
from ..linalg.validation import as_matrix, as_square, check_tol

__all__ = [
    "minimal_conditioned_invariant",
    "unobservable_subspace",
    "unstable_subspace",
    "undetectable_subspace",
    "ReconstructibilityDecomposition",
    "reconstructibility_decomposition",
    "reconstructible_subspace",
    "unreconstructible_directions",
]


# ----------------------------------------------------------------------------
# input validation
# ----------------------------------------------------------------------------
def _check_B(B, n: int, name: str = "B_unknown") -> np.ndarray:
    """``None`` (no unknown input) -> ``(n, 0)``; else a finite ``(n, m)`` matrix."""
    return np.zeros((n, 0)) if B is None else as_matrix(B, name, rows=n)


# ----------------------------------------------------------------------------
# conditioned invariants and (un)observable / (un)stable subspaces
# ----------------------------------------------------------------------------
def _min_cond_inv(A: np.ndarray, B: np.ndarray, C: np.ndarray, tol) -> np.ndarray:
    n = A.shape[0]
    V = orth(B, tol) if B.shape[1] else np.zeros((n, 0))
    for _ in range(n + 1):
        if V.shape[1] == n:
            break
        # S_k ∩ ker C = V ker(C V)
        X = V @ null_space(C @ V, tol) if V.shape[1] else np.zeros((n, 0))
        Vn = subspace_sum(V, B, A @ X, tol=tol) if (B.shape[1] or X.shape[1] or V.shape[1]) else V
        if Vn.shape[1] == V.shape[1]:
            return Vn
        V = Vn
    return V


def minimal_conditioned_invariant(A, B, C, tol: float | None = None) -> np.ndarray:
    """Minimal ``(C, A)``-conditioned invariant subspace containing ``Im B``.

    ``S*`` is the limit of the non-decreasing sequence ::

        S_0 = Im B,   S_{k+1} = Im B + A (S_k ∩ ker C),

    which stops growing after at most ``n`` steps. It is conditioned invariant
    (``A (S* ∩ ker C) ⊆ S*``), contains ``Im B``, and is contained in every
    conditioned invariant subspace containing ``Im B`` (induction: if
    ``S_k ⊆ S`` then ``A (S_k ∩ ker C) ⊆ A (S ∩ ker C) ⊆ S``).

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like or None
        ``m = 0`` or ``None`` gives ``S* = {0}``.
    C : (p, n) array_like
        ``p = 0`` is allowed (then ``S*`` is the reachable subspace ``<A | B>``).
    tol : float, optional
        Absolute singular-value threshold for every rank decision (``None``:
        relative default of :func:`~dobs_envs.linalg.subspaces.rank_tol`).

    Returns
    -------
    ndarray, shape (n, k)
        Orthonormal basis of ``S*`` (``k = dim S*``, possibly 0).

    Raises
    ------
    ValueError
        On bad shapes, NaN/inf entries or a non-positive ``tol``.
    """
    A = as_square(A, "A", nonempty=True)
    n = A.shape[0]
    B = _check_B(B, n, "B")
    C = as_matrix(C, "C", cols=n)
    return _min_cond_inv(A, B, C, check_tol(tol))


def _unobservable(A: np.ndarray, C: np.ndarray, tol) -> np.ndarray:
    n = A.shape[0]
    Z = null_space(C, tol) if C.shape[0] else np.eye(n)
    # N_0 = ker C, N_{k+1} = {x in N_k : A x in N_k}; decreasing, at most n steps.
    for _ in range(n + 1):
        if Z.shape[1] == 0:
            return Z
        R = A @ Z - Z @ (Z.T @ (A @ Z))  # (I - Z Z^T) A Z
        c = null_space(R, tol)
        if c.shape[1] == Z.shape[1]:
            return Z
        Z = orth(Z @ c, tol) if c.shape[1] else np.zeros((n, 0))
    return Z


def unobservable_subspace(A, C, tol: float | None = None) -> np.ndarray:
    """Unobservable subspace of ``(A, C)``: the largest ``A``-invariant subspace
    of ``ker C``.

    Computed as the limit of ``N_0 = ker C``, ``N_{k+1} = N_k ∩ A^{-1} N_k``.

    Parameters
    ----------
    A : (n, n) array_like
    C : (p, n) array_like (``p = 0`` allowed: everything is unobservable)
    tol : float, optional
        Absolute rank threshold (see :func:`minimal_conditioned_invariant`).

    Returns
    -------
    ndarray, shape (n, k)
        Orthonormal basis.
    """
    A = as_square(A, "A", nonempty=True)
    C = as_matrix(C, "C", cols=A.shape[0])
    return _unobservable(A, C, check_tol(tol))


def _unstable_subspace(M: np.ndarray) -> np.ndarray:
    k = M.shape[0]
    if k == 0:
        return np.zeros((0, 0))
    ev, stable, _ = classify_stable_eigenvalues(M)
    unstable = ~stable
    n_unst = int(unstable.sum())
    if n_unst == 0:
        return np.zeros((k, 0))
    if n_unst == k:
        return np.eye(k)

    def is_unstable(lam: complex) -> bool:
        return bool(unstable[int(np.argmin(np.abs(ev - lam)))])

    try:
        _, Z, sdim = sla.schur(M, output="real", sort=lambda re, im: is_unstable(re + 1j * im))
        if sdim == n_unst:
            return Z[:, :sdim].copy()
    except np.linalg.LinAlgError:
        pass
    # Fallback: complex ordered Schur; the selected set is closed under
    # conjugation (clusters are), so the real and imaginary parts of the
    # leading Schur vectors span a real subspace of the same dimension.
    _, Zc, sdim = sla.schur(M.astype(complex), output="complex", sort=is_unstable)
    if sdim != n_unst:
        raise np.linalg.LinAlgError(
            "ordered Schur form could not separate the stable and unstable eigenvalues"
        )
    Zr = orth(np.hstack([Zc[:, :sdim].real, Zc[:, :sdim].imag]))
    if Zr.shape[1] != n_unst:
        raise np.linalg.LinAlgError("unstable invariant subspace is not conjugation-closed")
    return Zr


def unstable_subspace(M) -> np.ndarray:
    """Generalised eigenspace of ``M`` for the eigenvalues that are not strictly
    stable (``Re >= -STABILITY_TOL * max(1, |M|_2)``, marginal modes included).

    Eigenvalues are classified per cluster (see
    :func:`~dobs_envs.linalg.subspaces.eigenvalue_clusters`) by the cluster mean, so perturbed Jordan blocks of integrators stay
    unstable as a whole; the subspace is read off an ordered real Schur form.

    Parameters
    ----------
    M : (k, k) array_like

    Returns
    -------
    ndarray, shape (k, r)
        Orthonormal basis (``r`` = number of non-stable eigenvalues with
        algebraic multiplicity).
    """
    M = as_square(M, "M")
    return _unstable_subspace(M)


def _undetectable(A: np.ndarray, C: np.ndarray, tol) -> np.ndarray:
    n = A.shape[0]
    Z = _unobservable(A, C, tol)
    if Z.shape[1] == 0:
        return np.zeros((n, 0))
    AN = Z.T @ A @ Z  # exact restriction: Im Z is A-invariant
    U = _unstable_subspace(AN)
    if U.shape[1] == 0:
        return np.zeros((n, 0))
    return orth(Z @ U, tol)


def undetectable_subspace(A, C, tol: float | None = None) -> np.ndarray:
    """Undetectable subspace of ``(A, C)``.

    The unobservable subspace ``N`` intersected with the generalised
    eigenspace of the non-stable eigenvalues of ``A``
    (``N ∩ X^+(A) = X^+(A|_N)`` because ``N`` is ``A``-invariant). Integrators
    and imaginary-axis modes are not stable. ``(A, C)`` is detectable iff the
    result is ``{0}``; its orthogonal complement is the detectable subspace of
    Table I (the ``B_{-i} = 0`` column).

    Parameters
    ----------
    A : (n, n) array_like
    C : (p, n) array_like
    tol : float, optional
        Absolute rank threshold for the unobservable subspace.

    Returns
    -------
    ndarray, shape (n, k)
        Orthonormal basis (``k = 0`` when ``(A, C)`` is detectable).
    """
    A = as_square(A, "A", nonempty=True)
    C = as_matrix(C, "C", cols=A.shape[0])
    return _undetectable(A, C, check_tol(tol))


# ----------------------------------------------------------------------------
# the reconstructible subspace
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class ReconstructibilityDecomposition:
    """Intermediate objects of :func:`reconstructibility_decomposition`.

    Attributes
    ----------
    S_star : (n, k) ndarray
        Orthonormal basis ``V`` of the minimal conditioned invariant ``S*``.
    W : (n, n - k) ndarray
        Orthonormal basis of ``S*^perp`` (quotient coordinates ``xi = W^T x``).
    L0 : (n, p) ndarray
        Output injection with ``W^T (A + L0 C) V = 0`` (keeps ``S*`` invariant).
    Q : (q, p) ndarray
        Annihilator of ``C V`` (rows span its left null space).
    A_q : (n - k, n - k) ndarray
        ``W^T (A + L0 C) W``.
    C_q : (q, n - k) ndarray
        ``Q C W``.
    U_q : (n - k, r) ndarray
        Undetectable subspace of ``(A_q, C_q)``: the fixed non-stable modes.
    S_stab : (n, k + r) ndarray
        ``S* + W U_q``: minimal outer-stabilisable conditioned invariant
        containing ``Im B``.
    reconstructible : (n, delta) ndarray
        Orthonormal basis of ``(S_stab ∩ ker C)^perp`` (= ``Im T_d``).
    unreconstructible : (n, n - delta) ndarray
        Orthonormal basis of ``S_stab ∩ ker C``.
    """

    S_star: np.ndarray
    W: np.ndarray
    L0: np.ndarray
    Q: np.ndarray
    A_q: np.ndarray
    C_q: np.ndarray
    U_q: np.ndarray
    S_stab: np.ndarray
    reconstructible: np.ndarray
    unreconstructible: np.ndarray

    @property
    def delta(self) -> int:
        """Dimension of the reconstructible subspace (``delta_i`` of Lemma 2)."""
        return int(self.reconstructible.shape[1])


def _pinv(M: np.ndarray, tol) -> np.ndarray:
    """Truncated pseudo-inverse with the same rank decision as the helpers."""
    if M.size == 0:
        return np.zeros((M.shape[1], M.shape[0]))
    U, s, Vt = np.linalg.svd(M, full_matrices=False)
    r = int(np.sum(s > rank_tol(s, M.shape, tol)))
    return (Vt[:r].T / s[:r]) @ U[:, :r].T


def reconstructibility_decomposition(
    A, B_unknown, C, tol: float | None = None
) -> ReconstructibilityDecomposition:
    r"""Geometric decomposition behind :func:`reconstructible_subspace`.

    Reasoning
    ---------
    *Reformulation.* With ``H = T^T - G C`` the conditions of Lemma 2 read
    ``H B = 0`` and ``H A = E H + F C`` (expand ``E T^T = E H + E G C``).
    Conversely any ``(H, E, F)`` with these properties gives admissible
    functionals ``T^T`` with rows spanning ``row H + row C``: stack
    ``[H; C]`` with ``E' = diag(E, -I)``, ``F' = [F; 0]``, ``G' = [0; I]``
    and orthonormalise (a change of basis ``T^T -> R T^T`` maps
    ``(E, F, G) -> (R E R^-1, R F, R G)``). So
    ``max Im T = max (row H) + Im C^T``.

    *Upper bound.* Let ``(H, E, F)`` be admissible with ``E`` Hurwitz. Then
    ``K = ker H`` satisfies ``A (K ∩ ker C) ⊆ K`` and ``K ⊇ Im B``, hence
    ``K ⊇ S*`` (``H V = 0``, ``H = H W W^T``). Let ``xi`` be a (generalised)
    eigenvector of ``A_q`` in the unobservable subspace of ``(A_q, C_q)``
    with eigenvalue ``lambda``, ``Re lambda >= 0``. Since ``C_q xi = 0``,
    ``C W xi ∈ Im C V`` and ``x = V a + W xi`` with ``C V a = -C W xi`` has
    ``C x = 0``. Using ``W^T A V a = -M0 C V a = M0 C W xi``::

        H A x = H W (W^T A V a + W^T A W xi) = H W A_q xi = lambda H W xi
              (+ H W xi_prev for a Jordan chain),

    while ``H A x = E H x + F C x = E H W xi``. So
    ``(lambda I - E) H W xi = H W xi_prev`` and, ``lambda`` not being an
    eigenvalue of the Hurwitz ``E``, induction along the chain gives
    ``H W xi = 0``: ``K ⊇ S* + W U_q = S_stab``, i.e.
    ``Im T ⊆ S_stab^perp + Im C^T``.

    *Achievability.* For ``L = L0 + W N Q`` (any ``N``),
    ``W^T (A + L C) V = W^T A V + M0 C V = 0`` so ``S*`` is
    ``(A + L C)``-invariant and the quotient map is ``A_q + N C_q``. Choose
    ``N`` so that the observable part of ``(A_q, C_q)`` is Hurwitz; the
    unobservable part is untouched and ``U_q`` stays invariant. Then
    ``S_stab`` is ``(A + L C)``-invariant with Hurwitz quotient map ``E``;
    ``H`` = orthonormal rows of ``S_stab^perp`` and ``F = -H L`` are
    admissible. Hence the bound is attained:
    ``Im T_d = S_stab^perp + Im C^T = (S_stab ∩ ker C)^perp``.

    The choice of the particular solution ``M0`` does not matter: another one
    changes ``A_q`` by an output injection ``N' C_q``, which leaves the
    unobservable subspace and its spectrum unchanged.

    Parameters
    ----------
    A : (n, n) array_like
    B_unknown : (n, m) array_like or None
        Unknown-input matrix ``B_{-i}``; ``m = 0`` / ``None`` for no unknown
        input. Redundant (linearly dependent) columns are allowed.
    C : (p, n) array_like
        Output matrix ``C_i``; rank deficiency and ``p = 0`` are allowed.
    tol : float, optional
        Absolute singular-value threshold for every rank decision.

    Returns
    -------
    ReconstructibilityDecomposition

    Raises
    ------
    ValueError
        Bad shapes, NaN/inf, or non-positive ``tol``.
    numpy.linalg.LinAlgError
        If ``S*`` is numerically not conditioned invariant at the given
        tolerance (inconsistent rank decisions), or the ordered Schur form
        fails.
    """
    A = as_square(A, "A", nonempty=True)
    n = A.shape[0]
    B = _check_B(B_unknown, n)
    C = as_matrix(C, "C", cols=n)
    tol = check_tol(tol)
    p = C.shape[0]

    V = _min_cond_inv(A, B, C, tol)
    W = orth_complement(V, n, tol)
    CV = C @ V
    WAV = W.T @ A @ V
    # Solve M CV = -W^T A V. Solvable because ker(CV) ⊆ ker(W^T A V), which is
    # A (S* ∩ ker C) ⊆ S*.
    M0 = -WAV @ _pinv(CV, tol)
    resid = float(np.linalg.norm(M0 @ CV + WAV)) if WAV.size else 0.0
    thr = max(1e-6, 100.0 * (tol if tol is not None else DEFAULT_RTOL)) * max(
        1.0, float(np.linalg.norm(A, 2)), float(np.linalg.norm(C, 2)) if C.size else 0.0
    )
    if resid > thr:
        raise np.linalg.LinAlgError(
            f"S* is not conditioned invariant at this tolerance (residual {resid:.3e})"
        )
    L0 = W @ M0  # W^T L0 = M0
    Q = annihilator(CV, tol) if p else np.zeros((0, 0))
    A_q = W.T @ A @ W + M0 @ (C @ W)
    C_q = Q @ C @ W if p else np.zeros((0, W.shape[1]))
    if W.shape[1]:
        U_q = _undetectable(A_q, C_q, tol)
    else:
        U_q = np.zeros((0, 0))
    S_stab = subspace_sum(V, W @ U_q, tol=tol) if (V.shape[1] + U_q.shape[1]) else np.zeros((n, 0))
    kerC = null_space(C, tol) if p else np.eye(n)
    unrec = (
        subspace_intersection(S_stab, kerC, tol)
        if (S_stab.shape[1] and kerC.shape[1])
        else np.zeros((n, 0))
    )
    rec = orth_complement(unrec, n, tol)
    return ReconstructibilityDecomposition(
        S_star=V, W=W, L0=L0, Q=Q, A_q=A_q, C_q=C_q, U_q=U_q, S_stab=S_stab,
        reconstructible=rec, unreconstructible=unrec,
    )


def reconstructible_subspace(A, B_unknown, C, tol: float | None = None) -> np.ndarray:
    """Largest subspace ``Im T_d`` of functionals reconstructible from ``y = C x``
    with unknown input ``B_unknown u`` (the strongly detectable subspace of
    Lemma 2 / Table I).

    ``Im T_d = (S_stab ∩ ker C)^perp = S_stab^perp + Im C^T`` with
    ``S_stab = S* + W U_q`` (see :func:`reconstructibility_decomposition` for
    the derivation).

    Parameters
    ----------
    A : (n, n) array_like
    B_unknown : (n, m) array_like or None
    C : (p, n) array_like
    tol : float, optional
        Absolute singular-value threshold for every rank decision.

    Returns
    -------
    ndarray, shape (n, delta)
        Orthonormal columns spanning ``Im T_d``.
    """
    return reconstructibility_decomposition(A, B_unknown, C, tol).reconstructible


def unreconstructible_directions(A, B_unknown, C, tol: float | None = None) -> np.ndarray:
    """Orthonormal basis of ``(Im T_d)^perp = S_stab ∩ ker C``.

    These are the state directions whose component no functional observer
    of node ``(A, B_unknown, C)`` can reconstruct; for the collective
    assumption (Assumption 6) a direction lying in this subspace for *every*
    node is a direction no node can reconstruct.

    Parameters
    ----------
    A : (n, n) array_like
    B_unknown : (n, m) array_like or None
    C : (p, n) array_like
    tol : float, optional

    Returns
    -------
    ndarray, shape (n, n - delta)
    """
    return reconstructibility_decomposition(A, B_unknown, C, tol).unreconstructible
