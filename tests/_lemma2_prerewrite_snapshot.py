r"""Pre-rewrite regression snapshot: ``dobs_envs/design/lemma2.py`` as of commit ecaeb14 (before issue 12).

A snapshot, not a reference that proves anything: about two thirds of its lines are still the
package's, so a bug in the shared lines passes every comparison with it. What it is for:

- a regression check of the O(n^3) rewrite (``tests/test_lemma2_staircase.py``: same ``delta``,
  subspace and observer blocks as before the rewrite), next to the independent checks those tests
  compute themselves (the residuals ``N B`` and ``N A - E N - F C`` with ``N = T_d^T - G C``,
  ``E`` Hurwitz or zero, ``T_d`` orthonormal) and the geometric maximality test
  (``tests/test_maximality.py``);
- the inputs that made the old code fail (``tests/test_design_scaling.py``);
- timing the old O(n^4) algorithm (``_unobservable_subspace``: up to r + 1 full SVDs) next to the new
  one in ``benchmarks/bench_design.py``.

Kept verbatim apart from this docstring and absolute imports. Not part of the package; do not
import it from ``dobs_envs``.

Original module docstring follows.

Strong detectability decomposition: the Appendix algorithm of Lemma 2 (FUIO).

The paper's Lemma 2 (label ``FUIO``) states that for the triplet
``(A, B_{-i}, C_i)`` of system (``LTIsys``), (``localmeasure``), (``splitinput``)
there is a largest integer ``delta_i`` for which the set ``Omega(delta_i)`` of
quadruplets ``(T_id, E_i, F_i, G_i)`` with::

    T_id^T T_id = I,       G_i C_i B_{-i} = T_id^T B_{-i},
    E_i T_id^T + (G_i C_i - T_id^T) A + (F_i - E_i G_i) C_i = 0,
    Re lambda(E_i) < 0   or   E_i = 0   (and then T_id^T = G_i C_i, F_i = 0)

is non-empty. With ``N = T_id^T - G_i C_i`` these are the conditions
``N B_{-i} = 0`` and ``N A = E_i N + F_i C_i`` of a functional unknown-input
observer ``z' = E_i z + F_i y_i``, ``T_id^T x ~ z + G_i y_i``, whose error
``e = z + G_i y_i - T_id^T x`` obeys ``e' = E_i e`` whatever ``u_{-i}`` does.
``Im T_id`` is the *strongly detectable subspace* of Table I; the observer
design of Section IV (eqs. ``obidynamic``, ``barEFGB``, ``TidTiu``) uses
``T_id``, ``T_iu``, ``E_i``, ``F_i``, ``G_i``.

:func:`strong_detectability` implements the Appendix "Algorithm Associated with
Lemma 2" (steps 1-8) with SVD rank-revealing factorisations; its docstring
explains why the printed step 7 is maximal and lists the implementation
choices the paper leaves open.

Reading of the algorithm (used in the comments below)
-----------------------------------------------------
Stack ``Y = [y; y']`` (``y' = C A x + C B u``). Step 1 row-compresses
``[0; C B]`` so that the part ``w_1`` of the unknown input seen in ``y'`` can be
written as ``w_1 = Y_1 - Pi_1 x``; the rest ``w_2`` enters through
``Lambda_12`` and is removed by its annihilator ``Xi_1`` (step 2); the rows
``Pi_2 x = Y_2`` are algebraic *relations* (known from ``y`` and ``y'``).
From then on we carry an identity::

    X zeta' = M zeta + K Y,        zeta = Z x   (Z: orthonormal rows)

valid for every trajectory and every unknown input. Coordinates of ``zeta``
whose derivative is not determined by ``X zeta'`` become unknown and are
annihilated (steps 3-5, iterated; the dimension strictly decreases so at most
``n`` iterations). When ``X`` has full column rank (step 6) the identity
splits into dynamics ``rho' = Pi_3 rho + K_t Y`` and relations
``0 = Pi_4 rho + K_b Y``: ``(Pi_3, Pi_4)`` is an autonomous system with an
"output", and its detectable part (Wonham's detectability decomposition)
carries the functionals that an observer ``rho_d' = (Pi_3d + J_2 Pi_4d) rho_d
+ ...`` reconstructs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from dobs_envs.linalg.subspaces import (
    annihilator,
    classify_stable_eigenvalues,
    is_hurwitz,
    null_space,
    numerical_rank,
    orth,
    rank_tol,
)
from dobs_envs.linalg.validation import as_matrix, as_square

__all__ = ["StrongDetectability", "strong_detectability", "lemma2_residuals", "DEFAULT_MARGIN"]

#: Default stability margin (in the time unit of ``A``) requested from the
#: shifted ARE that gives ``J_2`` (Appendix step 7): the assignable
#: eigenvalues of ``E`` satisfy ``Re < -margin``. 0.2 is the shift the paper
#: itself uses in the ARE of Section V-B (NE2).
DEFAULT_MARGIN = 0.2

#: Internal consistency threshold: the algorithm's result is re-checked
#: against the defining equations of Lemma 2 and a RuntimeError is raised if
#: the relative residual exceeds this (it is ~1e-14 on well-posed systems).
_CHECK_TOL = 1e-7


@dataclass(frozen=True)
class StrongDetectability:
    """Result of :func:`strong_detectability` (Lemma 2 (FUIO), eq. ``TidTiu``).

    Attributes
    ----------
    T_d : ndarray, shape (n, delta)
        Orthonormal basis of the strongly detectable subspace ``Im T_id``.
    T_u : ndarray, shape (n, n - delta)
        Orthonormal complement, eq. (``TidTiu``): ``T_d^T T_u = 0``,
        ``T_u^T T_u = I``, ``T_u T_u^T = I - T_d T_d^T``.
    E : ndarray, shape (delta, delta)
        Hurwitz, or exactly zero (then ``T_d^T = G C`` and ``F = 0``).
    F : ndarray, shape (delta, p)
    G : ndarray, shape (delta, p)
        ``G C B_unknown = T_d^T B_unknown`` and
        ``E T_d^T + (G C - T_d^T) A + (F - E G) C = 0``.

    All arrays are read-only copies.
    """

    T_d: np.ndarray
    T_u: np.ndarray
    E: np.ndarray
    F: np.ndarray
    G: np.ndarray

    @property
    def delta(self) -> int:
        """``delta_i = rank T_id`` (dimension of the strongly detectable subspace)."""
        return int(self.T_d.shape[1])


# ---------------------------------------------------------------------------
# validation
# ---------------------------------------------------------------------------
def _validate(A, B_unknown, C):
    A = as_square(A, "A", nonempty=True)
    n = A.shape[0]
    return A, as_matrix(B_unknown, "B_unknown", rows=n), as_matrix(C, "C", cols=n)


# ---------------------------------------------------------------------------
# numerical building blocks
# ---------------------------------------------------------------------------
def _rank_factor(M: np.ndarray, tol: float | None):
    """Nonsingular ``Phi``, orthogonal ``Psi`` with ``Phi M Psi = [[I_r, 0], [0, 0]]``.

    From the full SVD ``M = U S V^T``: ``Phi = diag(1/s_1..1/s_r, I) U^T``,
    ``Psi = V`` (the Appendix's Phi_0 / Psi_0 of step 1 and Phi_j / Psi_j of
    step 5). Only a diagonal scaling is "inverted".
    """
    rows, cols = M.shape
    if M.size == 0:
        return np.eye(rows), np.eye(cols), 0
    U, s, Vt = np.linalg.svd(M, full_matrices=True)
    r = int(np.sum(s > rank_tol(s, M.shape, tol)))
    Phi = U.T.copy()
    Phi[:r] /= s[:r, None]
    return Phi, Vt.T.copy(), r


def _unstable_invariant_subspace(M: np.ndarray, scale: float):
    """Orthonormal basis of the invariant subspace of ``M`` for its not-stable
    eigenvalues (Re >= -STABILITY_TOL*scale, marginal included), and the
    cluster means of the stable remainder (all with Re < -STABILITY_TOL*scale)."""
    k = M.shape[0]
    if k == 0:
        return np.zeros((0, 0)), np.zeros(0, dtype=complex)
    ev, stable, means = classify_stable_eigenvalues(M, scale)
    n_unstable = int(np.sum(~stable))
    if n_unstable == 0:
        return np.zeros((k, 0)), means
    if n_unstable == k:
        return np.eye(k), np.zeros(0, dtype=complex)

    def unstable_first(re, im):
        j = int(np.argmin(np.abs(ev - (re + 1j * im))))
        return not stable[j]

    T, Zs, sdim = sla.schur(M, output="real", sort=unstable_first)
    if sdim != n_unstable:
        raise RuntimeError(
            "ordered Schur form failed to separate the stable and marginal/unstable "
            f"eigenvalues of the step-6 pair (expected {n_unstable}, got {sdim}); "
            "the system has eigenvalues too close to the imaginary axis"
        )
    return Zs[:, :sdim].copy(), means[stable]


def _unobservable_subspace(Pi3: np.ndarray, Pi4: np.ndarray, tol: float | None) -> np.ndarray:
    """Largest ``Pi3``-invariant subspace in ``ker Pi4`` (orthonormal columns):
    ``V_0 = ker Pi4``, ``V_{k+1} = ker [Pi4; V_k^perp Pi3]``."""
    r = Pi3.shape[0]
    V = null_space(Pi4, tol) if Pi4.shape[0] else np.eye(r)
    for _ in range(r + 1):
        W = annihilator(V, tol)  # rows: orthonormal basis of V^perp
        V_new = null_space(np.vstack([Pi4, W @ Pi3]), tol) if (Pi4.shape[0] or W.shape[0]) else np.eye(r)
        if V_new.shape[1] == V.shape[1]:
            return V_new
        V = V_new
    return V


def _stabilising_injection(Pi3d: np.ndarray, Pi4d: np.ndarray, alpha: float, tol: float | None) -> np.ndarray:
    """``J_2`` with ``Pi3d + J_2 Pi4d`` Hurwitz (Appendix step 7).

    The pair is split with an orthogonal observability decomposition (the
    unobservable subspace ``V_o`` from SVD null spaces,
    :func:`_unobservable_subspace`, ``W_o`` its orthonormal complement)::

        [W_o V_o]^T Pi3d [W_o V_o] = [[A_o, 0], [A_21, A_f]],   Pi4d [W_o V_o] = [C_o, 0].

    The fixed modes ``A_f`` (no ``J_2`` moves them) must be stable -- they are
    the stable unobservable modes kept by the detectability decomposition of
    step 6 -- and are checked. ``J_2 = W_o J_o`` with ``J_o`` from the dual
    shifted ARE of the *observable* pair
    ``(A_o + a I) X + X (A_o + a I)^T - X C_o^T C_o X + I = 0``,
    ``J_o = -X C_o^T``, so the assignable eigenvalues have ``Re < -a`` and
    ``E = Pi3d + J_2 Pi4d`` is block lower triangular with diagonal blocks
    ``A_o + J_o C_o`` and ``A_f``. Working on the observable part keeps the
    ARE well posed whatever the fixed modes are (an ARE on the whole pair
    needs ``a`` below their decay rate and fails when they are nearly
    unstable or the pair is nearly undetectable); ``a`` is halved only if the
    ARE solver fails numerically.
    """
    r = Pi3d.shape[0]
    Vo = _unobservable_subspace(Pi3d, Pi4d, tol)
    Wo = null_space(Vo.T) if Vo.shape[1] else np.eye(r)
    if Vo.shape[1]:
        Af = Vo.T @ Pi3d @ Vo
        _, fixed_stable, fixed_means = classify_stable_eigenvalues(Af, max(1.0, float(np.linalg.norm(Pi3d, 2))))
        if not np.all(fixed_stable):
            raise RuntimeError(
                "Lemma 2 (FUIO): the unobservable modes of the detectable part of the step-6 pair "
                f"are not all stable (cluster means {np.unique(np.round(fixed_means, 12))}); the "
                "stable/unstable classification of the step-6 pair is numerically ill-conditioned"
            )
    ro = Wo.shape[1]
    if ro == 0:
        return np.zeros((r, Pi4d.shape[0]))
    Ao = Wo.T @ Pi3d @ Wo
    Co = Pi4d @ Wo
    last_exc = None
    a = alpha
    for _ in range(8):
        try:
            X = sla.solve_continuous_are(
                (Ao + a * np.eye(ro)).T, Co.T, np.eye(ro), np.eye(Co.shape[0])
            )
            Jo = -X @ Co.T
            if np.all(np.isfinite(Jo)) and is_hurwitz(Ao + Jo @ Co):
                return Wo @ Jo
        except (np.linalg.LinAlgError, ValueError) as exc:  # pragma: no cover - rare
            last_exc = exc
        a *= 0.5
    raise RuntimeError(  # pragma: no cover - an observable pair always has a solution
        "could not find a stabilising J_2 for the observable part of the step-6 pair "
        f"(Appendix step 7; observable dimension {ro}, numerically nearly unobservable): {last_exc}"
    )


# ---------------------------------------------------------------------------
# the algorithm
# ---------------------------------------------------------------------------
def strong_detectability(
    A, B_unknown, C, *, tol: float | None = None, margin: float = DEFAULT_MARGIN
) -> StrongDetectability:
    r"""Lemma 2 (FUIO): maximal functional unknown-input observer of ``(A, B_unknown, C)``.

    Implements the Appendix "Algorithm Associated with Lemma 2" (steps 1-8)
    and returns ``(T_id, E_i, F_i, G_i) in Omega(delta_i)`` together with
    ``T_iu`` of eq. (``TidTiu``), for use in eqs. (``obidynamic``), (``barEFGB``).

    Parameters
    ----------
    A : array_like, shape (n, n)
        System matrix of (``LTIsys``).
    B_unknown : array_like, shape (n, m)
        Input directions unknown to the node, ``B_{-i}`` of (``splitinput``)
        (for NE3 also ``B_v``). ``m = 0`` (no unknown input) and redundant
        columns are allowed: the algorithm works with an orthonormal basis of
        ``Im B_unknown`` (the paper assumes full column rank).
    C : array_like, shape (p, n)
        Output matrix ``C_i`` of (``localmeasure``); must have full row rank,
        as the paper requires. ``p = 0`` (no output) is accepted: then only
        functionals with stable dynamics unaffected by the unknown input are
        reconstructible.
    tol : float, optional
        Absolute singular-value threshold for every rank decision. It is
        applied to the internally normalised data (``A / ||A||_2``, orthonormal
        bases of ``Im B_unknown`` and of the row space of ``C``), so it is
        unit-free. Default: :func:`~dobs_envs.linalg.subspaces.rank_tol`.
    margin : float, optional
        Requested stability margin of the assignable part of ``E`` (in the time
        unit of ``A``): the ARE that gives ``J_2`` (posed on the observable
        part of the step-6 pair, :func:`_stabilising_injection`) is shifted by
        ``margin``; the fixed (unobservable, stable) modes keep their values.

    Returns
    -------
    StrongDetectability
        ``T_d`` (n, delta) orthonormal, ``T_u`` (n, n-delta), ``E`` (delta,
        delta), ``F`` (delta, p), ``G`` (delta, p) with
        ``G C B_unknown = T_d^T B_unknown`` and
        ``E T_d^T + (G C - T_d^T) A + (F - E G) C = 0``;
        ``E`` is Hurwitz, or ``E = 0`` and then ``T_d^T = G C``, ``F = 0``.
        ``Im T_d`` is the largest subspace with this property (Remark after
        Lemma 2).

    Raises
    ------
    ValueError
        Non-2-D, non-finite or mismatched arguments; ``C`` without full row
        rank.

    Notes
    -----
    Steps 1-6 follow the Appendix, with ``Phi_j, Psi_j`` from SVDs
    (:func:`_rank_factor`, ``Psi_j`` orthogonal) and every ``Xi_j`` an
    orthonormal annihilator (:func:`~dobs_envs.linalg.subspaces.annihilator`).
    Step 6 (Wonham's detectability decomposition of ``(Pi_3, Pi_4)``): the
    undetectable subspace is the part of the unobservable subspace of
    ``(Pi_3, Pi_4)`` belonging to eigenvalues with ``Re >= 0`` (marginal modes
    count as *not* stable, :func:`~dobs_envs.linalg.subspaces.stable_mask`;
    eigenvalues of defective blocks are classified by cluster mean); ``P_Pi``
    is orthogonal, ``r_d`` is the dimension of the detectable quotient.
    Step 8 uses a QR factorisation (Gram-Schmidt) and triangular solves.

    Step 7 and maximality (is the printed algorithm maximal? yes)
    ---------------------------------------------------------------
    The printed step 7 has two branches, ``T_id0^T = J Phi Xi_21 Xi_1`` when
    ``r_d > p_i`` and ``T_id0^T = C_i`` (``E_i = 0``) when ``r_d <= p_i``. Either
    would lose reconstructible functionals if the step-6 functionals
    ``T_dyn = J_1 (rho)`` did not contain the row space of ``C_i``. They always
    do (``p_i >= 1``, exact arithmetic): for a row ``c`` of ``C_i``,
    ``c Lambda_12 = 0`` by the construction of ``Psi_0`` (so ``c`` is in the
    row space of ``Xi_1``), its derivative ``c x' = y_c'`` is known and its
    value ``c x = y_c`` is a relation, and both identities are free of the
    eliminated coordinates at every stage, so ``c`` survives every iteration
    of steps 4-5 and is an *observed* direction of ``(Pi_3, Pi_4)``. Hence
    ``r_d >= p_i``, the branch ``r_d <= p_i`` means ``Im T_dyn = Im C_i^T``,
    and ``delta_i = max(r_d, p_i) = r_d``. We implement step 7 as the union
    ``T_id0^T = [T_dyn ; R_c C_i]`` with ``R_c C_i`` the rows of ``C_i`` not
    (numerically) in ``Im T_dyn^T`` (observed through ``G`` with a zero
    ``N``-block and an ``E``-block ``-margin * I``); in exact arithmetic
    ``R_c`` is empty and this *is* the printed algorithm, numerically it
    guards against a rank decision at the tolerance boundary. The ``E = 0``
    branch (``T_id^T = G_i C_i``, ``F_i = 0``) is taken when ``Im T_dyn``
    lies in the row space of ``C_i`` (this covers ``r_d = p_i``, ``r_d = 0``).

    Maximality (Remark after Lemma 2): if ``(T, E', F', G')`` is any valid
    quadruplet, ``N' = T^T - G' C`` has a kernel that is a
    ``(C, A)``-conditioned invariant subspace containing ``Im B``; writing
    ``N' = Q N`` in the step-6 functionals, ``Q Pi_3 = E' Q + L Pi_4`` forces
    ``Q`` to vanish on the undetectable subspace (Sylvester equation with
    disjoint spectra when ``E'`` is Hurwitz; ``N' = 0`` when ``E' = 0``). The
    test-suite checks ``Im T_d`` against an independent geometric
    characterisation (minimal conditioned invariant subspace and fixed
    unstable modes) on random systems.

    Implementation choices not fixed by the paper
    ----------------------------------------------
    1. The rows of ``Pi_4`` (relations) are row-compressed to an orthonormal
       basis before step 6 (a change of basis of the relations, carried into
       the known-term matrix), and ``J_2`` comes from a shifted ARE
       (:func:`_stabilising_injection`); the paper leaves ``J_2`` free.
    2. The data are normalised first (``A/||A||``, orthonormal basis of
       ``Im B_unknown``, orthonormal rows spanning the row space of ``C``) so
       rank decisions are unit-free and redundant ``B_unknown`` columns are
       harmless; ``E, F, G`` are mapped back exactly.
    3. Marginal eigenvalues of ``Pi_3`` on its unobservable subspace count as
       undetectable; defective eigenvalues are classified by cluster mean
       (:func:`~dobs_envs.linalg.subspaces.classify_stable_eigenvalues`),
       since e.g. the NE2 integrator chains give computed eigenvalues with
       ``|Re| ~ 1e-3``. Clusters are pseudospectral components (eigenvalues a
       backward error of the eigensolver could merge), not a radius relative
       to ``||Pi_3||``: a large invariant zero (e.g. ``-96`` after
       normalisation when ``C B`` is small) made such a radius lump the
       remaining zeros, stable and unstable, into one "stable" cluster.
    """
    A0, B0, C0 = _validate(A, B_unknown, C)
    n = A0.shape[0]
    p = C0.shape[0]
    if not (np.isfinite(margin) and margin > 0):
        raise ValueError(f"margin must be a positive finite number, got {margin!r}")

    # ---- normalisation (implementation choice 2) -------------------------------------
    a_scale = float(np.linalg.norm(A0, 2))
    if a_scale == 0.0:
        a_scale = 1.0
    As = A0 / a_scale
    c_norm = float(np.linalg.norm(C0, 2)) if C0.size else 0.0
    if p:
        Uc, sc, Vct = np.linalg.svd(C0 / c_norm if c_norm else C0, full_matrices=False)
        rank_c = int(np.sum(sc > rank_tol(sc, C0.shape, tol))) if c_norm else 0
        if rank_c < p:
            raise ValueError(
                f"C must have full row rank (the paper requires C_i to have full row rank); "
                f"got shape {C0.shape} with numerical rank {rank_c}"
            )
        Cq = Vct.copy()  # (p, n) orthonormal rows, Cq = L C
        L = (Uc.T / sc[:, None]) / c_norm  # (p, p); y_q = L y
    else:
        Cq = np.zeros((0, n))
        L = np.zeros((0, 0))
    b_norm = float(np.linalg.norm(B0, 2)) if B0.size else 0.0
    Bq = orth(B0 / b_norm, tol) if b_norm > 0 else np.zeros((n, 0))
    m = Bq.shape[1]

    # ---- step 1: Phi_0 [0; C B] Psi_0 = [[I_r, 0], [0, 0]] ----------------
    Phi0, Psi0, r = _rank_factor(np.vstack([np.zeros((p, m)), Cq @ Bq]), tol)

    # ---- step 2 ------------------------------------------------------------
    BPsi = Bq @ Psi0
    Lam11, Lam12 = BPsi[:, :r], BPsi[:, r:]
    PhiCCA = Phi0 @ np.vstack([Cq, Cq @ As])
    Pi1, Pi2 = PhiCCA[:r], PhiCCA[r:]
    Xi1 = annihilator(Lam12, tol)  # (r1, n), orthonormal rows
    r1 = Xi1.shape[0]
    Psi1 = np.hstack([Xi1.T, null_space(Xi1)]) if r1 else np.eye(n)  # Xi1 Psi1 = [I 0]

    # ---- step 3 ------------------------------------------------------------
    # [xi_1'; 0] = [Xi1 (A - Lam11 Pi1); -Pi2] Psi1 xi + Kstack Y
    Lmat = np.vstack([Xi1 @ (As - Lam11 @ Pi1), -Pi2]) @ Psi1
    Lam21, Lam22 = Lmat[:, :r1], Lmat[:, r1:]
    Kstack = np.vstack([Xi1 @ Lam11 @ Phi0[:r], Phi0[r:]])  # acts on Y = [y_q; y_q']
    Xi2 = annihilator(Lam22, tol)
    X = Xi2[:, :r1]  # Xi_{2,1}
    Mx = Xi2 @ Lam21
    K = Xi2 @ Kstack
    Z = Xi1  # zeta = Z x

    # ---- steps 4-5 (iteration) and 6 ---------------------------------------
    Pi3 = np.zeros((0, 0))
    Pi4 = np.zeros((0, 0))
    Kt = np.zeros((0, 2 * p))
    Kb = np.zeros((0, 2 * p))
    Zrho = np.zeros((0, n))
    for _ in range(n + 2):
        rcur = Z.shape[0]
        if rcur == 0:
            break  # nothing left: r_d = 0
        if X.shape[0] == 0 or numerical_rank(X, tol) == 0:
            break  # step 4: Xi_{j,1} zero / absent -> r_d = 0
        Phi, Psi, rj = _rank_factor(X, tol)
        PM = Phi @ Mx @ Psi
        PK = Phi @ K
        if rj == rcur:  # step 4 -> step 6: Xi_{j,1} full column rank
            Pi3, Pi4 = PM[:rj], PM[rj:]
            Kt, Kb = PK[:rj], PK[rj:]
            Zrho = Psi.T @ Z  # rho = Psi^T zeta
            break
        # step 5: zeta = Psi [zeta_1; zeta_2], zeta_2 becomes unknown
        Lam1, Lam2 = PM[:, :rj], PM[:, rj:]
        Xi = annihilator(Lam2, tol)
        X = Xi[:, :rj]
        Mx = Xi @ Lam1
        K = Xi @ PK
        Z = Psi[:, :rj].T @ Z
    else:  # pragma: no cover - dimension strictly decreases
        raise RuntimeError("Appendix steps 4-5 did not terminate")

    # ---- step 6: detectability decomposition of (Pi_3, Pi_4) -------------
    r_rho = Zrho.shape[0]
    alpha = margin / a_scale  # margin in the normalised time unit
    T_dyn = np.zeros((0, n))
    G_dyn = np.zeros((0, p))
    F_dyn = np.zeros((0, p))
    E_dyn = np.zeros((0, 0))
    if r_rho:
        # implementation choice 1: row-compress the relations 0 = Pi4 rho + Kb Y
        if Pi4.shape[0]:
            U4, s4, V4t = np.linalg.svd(Pi4, full_matrices=False)
            k4 = int(np.sum(s4 > rank_tol(s4, Pi4.shape, tol)))
            Q4 = V4t[:k4]
            Kb = (U4[:, :k4].T / s4[:k4, None]) @ Kb
        else:
            Q4 = np.zeros((0, r_rho))
            Kb = np.zeros((0, 2 * p))
        Vunobs = _unobservable_subspace(Pi3, Q4, tol)
        scale3 = max(1.0, float(np.linalg.norm(Pi3, 2)))
        if Vunobs.shape[1]:
            Au = Vunobs.T @ Pi3 @ Vunobs
            Wu, _ = _unstable_invariant_subspace(Au, scale3)
            P_u = Vunobs @ Wu
        else:
            P_u = np.zeros((r_rho, 0))
        P_d = null_space(P_u.T) if P_u.shape[1] else np.eye(r_rho)
        r_d = P_d.shape[1]
        if r_d:
            Pi3d = P_d.T @ Pi3 @ P_d
            Pi4d = Q4 @ P_d  # orthonormal rows since Q4 P_u = 0
            if Pi4d.shape[0]:
                J2 = _stabilising_injection(Pi3d, Pi4d, alpha, tol)
            else:
                J2 = np.zeros((r_d, 0))
            E_dyn = Pi3d + J2 @ Pi4d
            Kd = P_d.T @ Kt + J2 @ Kb  # rho_d' = E_dyn rho_d + Kd [y_q; y_q']
            T_dyn = P_d.T @ Zrho
            G_dyn = Kd[:, p:]
            F_dyn = E_dyn @ G_dyn + Kd[:, :p]

    # ---- step 7 (as the union T_dyn + rows of C; R_c is empty in exact arithmetic) ----------------------------------
    if T_dyn.shape[0]:
        Xc = Cq.T - T_dyn.T @ (T_dyn @ Cq.T)  # row-space part of C outside Im T_dyn
        if Xc.size:
            _, sx, Vxt = np.linalg.svd(Xc, full_matrices=False)
            kc = int(np.sum(sx > rank_tol(sx, Xc.shape, tol)))
        else:
            sx, Vxt, kc = np.zeros(0), np.zeros((0, p)), 0
        in_rowC = numerical_rank(T_dyn.T - Cq.T @ (Cq @ T_dyn.T), tol) == 0 if p else False
    else:
        kc, in_rowC = p, True

    if in_rowC:
        # E = 0 branch: T_id^T = G C (the step-6 functionals are measured)
        T_d = Cq.T.copy()
        E_s = np.zeros((p, p))
        F_s = np.zeros((p, p))
        G_s = np.eye(p)
    else:
        Rc = Vxt[:kc] / sx[:kc, None]  # (kc, p): c_rows = Rc Cq
        T0 = np.vstack([T_dyn, Rc @ Cq])  # T_id0^T
        E_blk = sla.block_diag(E_dyn, -(margin / a_scale) * np.eye(kc))
        F_blk = np.vstack([F_dyn, np.zeros((kc, p))])
        G_blk = np.vstack([G_dyn, Rc])
        # ---- step 8: Gram-Schmidt T0^T = Qr Rq -> T_d^T = Rq^{-T} T0 ---------
        Qr, Rq = np.linalg.qr(T0.T)
        T_d = Qr
        RqT = Rq.T
        E_s = np.linalg.solve(RqT, E_blk @ RqT)
        F_s = np.linalg.solve(RqT, F_blk)
        G_s = np.linalg.solve(RqT, G_blk)

    # ---- undo the normalisation --------------------------------------------
    E = a_scale * E_s
    F = a_scale * F_s @ L
    G = G_s @ L
    delta = T_d.shape[1]
    T_u = null_space(T_d.T) if delta else np.eye(n)
    if in_rowC:
        E = np.zeros((delta, delta))
        F = np.zeros((delta, p))

    _self_check(A0, B0, C0, T_d, E, F, G)
    if delta and not in_rowC and not is_hurwitz(E):  # pragma: no cover - internal error
        raise RuntimeError(
            "Lemma 2 (FUIO): the observer matrix E is not Hurwitz; eigenvalues of the "
            "step-6 pair are too close to the imaginary axis to be classified"
        )
    out = StrongDetectability(T_d=T_d, T_u=T_u, E=E, F=F, G=G)
    for arr in (out.T_d, out.T_u, out.E, out.F, out.G):
        arr.setflags(write=False)
    return out


def lemma2_residuals(A, B_unknown, C, res: StrongDetectability) -> tuple[float, float]:
    """Relative residuals of the two equalities of Lemma 2 (FUIO).

    Returns ``(rB, rA)`` with
    ``rB = ||G C B - T_d^T B|| / ((||G|| ||C|| + 1) ||B||)`` and
    ``rA = ||E T_d^T + (G C - T_d^T) A + (F - E G) C|| /
    (||E|| + (||G|| ||C|| + 1) ||A|| + (||F|| + ||E|| ||G||) ||C||)``
    (2-norms; the denominators bound the norms of the summands, so the
    residual is measured against the size of the terms that cancel).
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B_unknown, dtype=float)
    C = np.asarray(C, dtype=float)
    T, E, F, G = res.T_d, res.E, res.F, res.G

    def nrm(M):
        return float(np.linalg.norm(M, 2)) if M.size else 0.0

    nC = nrm(C)
    if B.size:
        rB = nrm(G @ C @ B - T.T @ B) / max((nrm(G) * nC + 1.0) * nrm(B), np.finfo(float).tiny)
    else:
        rB = 0.0
    lhs = E @ T.T + (G @ C - T.T) @ A + (F - E @ G) @ C
    den = nrm(E) + (nrm(G) * nC + 1.0) * nrm(A) + (nrm(F) + nrm(E) * nrm(G)) * nC
    rA = nrm(lhs) / max(den, np.finfo(float).tiny) if lhs.size else 0.0
    return rB, rA


def _self_check(A, B, C, T_d, E, F, G) -> None:
    tmp = StrongDetectability(T_d=T_d, T_u=np.zeros((A.shape[0], 0)), E=E, F=F, G=G)
    rB, rA = lemma2_residuals(A, B, C, tmp)
    if not (rB <= _CHECK_TOL and rA <= _CHECK_TOL):  # pragma: no cover - internal error
        raise RuntimeError(
            f"Lemma 2 (FUIO) result fails its defining equations (relative residuals "
            f"{rB:.2e}, {rA:.2e}); the system is numerically ill-posed for tol={_CHECK_TOL}"
        )
