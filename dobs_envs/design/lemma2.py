r"""Strong detectability decomposition: the Appendix algorithm of Lemma 2 (FUIO).

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

from ..linalg.subspaces import (
    IllConditionedError,
    annihilator,
    classify_stable_eigenvalues,
    is_hurwitz,
    null_space,
    numerical_rank,
    observability_staircase,
    orth,
    rank_tol,
    scaled_rank,
)
from ..linalg.validation import as_float, as_matrix, as_square, check_tol

__all__ = [
    "StrongDetectability",
    "strong_detectability",
    "lemma2_residuals",
    "DEFAULT_MARGIN",
    "IllConditionedError",
]

#: Default stability margin (in the time unit of ``A``) requested from the
#: shifted ARE that gives ``J_2`` (Appendix step 7): the assignable
#: eigenvalues of ``E`` satisfy ``Re < -margin``. 0.2 is the shift the paper
#: itself uses in the ARE of Section V-B (NE2).
DEFAULT_MARGIN = 0.2

#: Consistency threshold: the result is re-checked against the defining
#: equations of Lemma 2 on the caller's (unscaled) data and
#: :class:`~dobs_envs.linalg.subspaces.IllConditionedError` is raised if a
#: relative residual (:func:`lemma2_residuals`) exceeds this. It is ~1e-15 on
#: well-posed systems; rank decisions neglect singular values up to
#: ``DEFAULT_RTOL = 1e-9`` (relative), which can leave residuals of that order
#: times the conditioning of the transformations, so 1e-7 separates "round-off
#: plus neglected near-rank-deficiency" from a wrong decomposition.
_CHECK_TOL = 1e-7

#: Balancing (``_balancing_exponents``): a state coordinate is rescaled by
#: ``2^k`` only when that lowers the sum of its off-diagonal row and column
#: 1-norms in the system matrix ``[[A, B], [C, 0]]`` below this fraction
#: (LAPACK ``dgebal``'s 0.95) ...
_BALANCE_FACTOR = 0.95
#: ... and when those norms differ by more than ``2^_BALANCE_DEADBAND`` (~1e6).
#: Rank decisions are made at ``DEFAULT_RTOL = 1e-9`` relative: a spread of
#: scales below 1e6 leaves them three decades of room, while any rescaling
#: changes the free choice of ``J_2`` (the ARE of step 7 is posed in the
#: working coordinates), hence ``E``. So ordinarily scaled systems (the paper's,
#: the random scenarios') keep their design exactly and only badly scaled
#: ones are balanced. (A dead band of 2^4 still rescaled ~1 in 20 random
#: 2-state systems of the test-suite.)
_BALANCE_DEADBAND = 20.0
#: Bound on the balancing exponents (``|k_i| <= 500``): keeps ``D`` and
#: ``D^{-1}`` far from overflow and underflow.
_BALANCE_MAX_EXP = 500


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


def _schur_unstable_first(M: np.ndarray, scale: float):
    """Ordered real Schur vectors of ``M`` with its not-stable eigenvalues first.

    Returns ``(Z, k)``: ``Z`` orthogonal, ``Z[:, :k]`` spans the invariant
    subspace of the eigenvalues that are not stable (``Re >= -STABILITY_TOL *
    scale``, marginal included, classified per pseudospectral cluster by
    :func:`~dobs_envs.linalg.subspaces.classify_stable_eigenvalues`), and
    ``Z[:, k:]^T M Z[:, k:]`` (upper quasi-triangular) carries the stable ones.
    """
    k = M.shape[0]
    if k == 0:
        return np.eye(0), 0
    ev, stable, _ = classify_stable_eigenvalues(M, scale)
    n_unstable = int(np.sum(~stable))
    if n_unstable in (0, k):
        return np.eye(k), n_unstable

    def unstable_first(re, im):
        j = int(np.argmin(np.abs(ev - (re + 1j * im))))
        return not stable[j]

    _, Z, sdim = sla.schur(M, output="real", sort=unstable_first)
    if sdim != n_unstable:
        raise IllConditionedError(
            "Lemma 2 (FUIO), step 6: the ordered Schur form could not separate the stable and "
            f"marginal/unstable unobservable modes of the step-6 pair (expected {n_unstable}, "
            f"got {sdim}): eigenvalues too close to the imaginary axis or to each other"
        )
    return Z, sdim


def _are_injection(Ao: np.ndarray, Co: np.ndarray, alpha: float):
    """``J = -X Co^T`` from ``(Ao + a I) X + X (Ao + a I)^T - X Co^T Co X + I = 0``
    (``a = alpha``), or ``None`` when the solver fails or ``Ao + J Co`` is not Hurwitz."""
    ro = Ao.shape[0]
    try:
        X = sla.solve_continuous_are((Ao + alpha * np.eye(ro)).T, Co.T, np.eye(ro), np.eye(Co.shape[0]))
    except (np.linalg.LinAlgError, ValueError):
        return None
    J = -X @ Co.T
    if not (np.all(np.isfinite(J)) and is_hurwitz(Ao + J @ Co)):
        return None
    return J


def _stabilising_injection(Ao: np.ndarray, Co: np.ndarray, alpha: float, ratio: float) -> np.ndarray:
    """``J_o`` with ``Ao + J_o Co`` Hurwitz, assignable eigenvalues ``Re < -alpha``
    (Appendix step 7, on the *observable* part ``(Ao, Co)`` of the detectable
    step-6 pair; the fixed modes are handled by the caller).

    First the dual shifted ARE on the whole pair
    ``(Ao + a I) X + X (Ao + a I)^T - X Co^T Co X + I = 0``, ``J_o = -X Co^T``
    (``a = alpha <= 1`` in the caller's time unit, so the shift never dwarfs
    ``Ao``). When that has no finite stabilising solution in double precision
    (a large pair observed through few relations: the solution grows like the
    inverse distance to unobservability of *all* its modes), only the modes
    with ``Re >= -alpha`` are moved: with the ordered real Schur form
    ``Ao^T = Z [[S_11, S_12], [0, S_22]] Z^T`` (``S_22``: those modes),
    ``J_o = Z_2 J_2`` from the same ARE on ``(S_22^T, Co Z_2)`` makes
    ``Z^T (Ao + J_o Co) Z`` block lower triangular with diagonal blocks
    ``S_11^T`` (already ``Re < -alpha``) and ``S_22^T + J_2 Co Z_2``.

    ``ratio`` (``margin / ||A||``) only enters the error message.

    Raises
    ------
    IllConditionedError
        Neither ARE has a finite stabilising solution: modes that must be
        moved are numerically unobservable from the relations, or (``ratio``
        >> 1) the system is so slow next to the margin that the gains needed
        (of order ``ratio^k`` for a chain of ``k`` integrators) are out of reach.
    """
    ro = Ao.shape[0]
    J = _are_injection(Ao, Co, alpha)
    if J is not None:
        return J
    T, Z, sdim = sla.schur(Ao.T, output="real", sort=lambda re, im: re < -alpha)
    Z2 = Z[:, sdim:]
    if Z2.shape[1]:
        J2 = _are_injection(T[sdim:, sdim:].T, Co @ Z2, alpha)
        if J2 is not None:
            J = Z2 @ J2
            if is_hurwitz(Ao + J @ Co):
                return J
    raise IllConditionedError(
        "Lemma 2 (FUIO), Appendix step 7: no stabilising J_2 for the observable part of the "
        f"step-6 pair (dimension {ro}, {ro - sdim} mode(s) with Re >= -margin to move): these "
        "modes are numerically unobservable from the relations Pi_4 (the shifted ARE has no "
        f"finite stabilising solution in double precision; margin / ||A|| = {ratio:.3g}). The "
        "system is too close to losing strong detectability for this tolerance, or too slow for "
        "this margin: a larger tol (treating these modes as unobservable) or a smaller margin "
        "may help"
    )


def _pow2_exponent(M: np.ndarray) -> int:
    """``k`` with ``2^(k-1) <= max |M| < 2^k`` (0 for an empty or zero ``M``), so that
    ``np.ldexp(M, -k)`` has entries of modulus below 1, the largest at least 1/2 (exact)."""
    if M.size == 0:
        return 0
    mx = float(np.max(np.abs(M)))
    return int(np.frexp(mx)[1]) if mx > 0 else 0


def _pow2_exponents(M: np.ndarray, axis: int) -> np.ndarray:
    """:func:`_pow2_exponent` of every column (``axis=0``) or row (``axis=1``) of ``M``."""
    if M.size == 0:
        return np.zeros(M.shape[1 - axis], dtype=int)
    mx = np.max(np.abs(M), axis=axis)
    return np.where(mx > 0, np.frexp(mx)[1], 0).astype(int)


def _balancing_exponents(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Integer ``k`` such that ``D = diag(2^k)`` balances the system matrix
    ``[[A, B], [C, 0]]`` by a state-coordinate change ``x = D x_b``
    (``A_b = D^{-1} A D``, ``B_b = D^{-1} B``, ``C_b = C D``).

    The scaling loop of LAPACK ``dgebal`` restricted to the state coordinates
    (the rows of ``B`` and columns of ``C`` take part in the norms, the input
    and output coordinates are not scaled): coordinate ``i`` with
    off-diagonal column and row 1-norms ``c`` and ``r`` is scaled by the power
    of two nearest ``sqrt(r / c)`` when ``r / c`` is outside
    ``2^(+-_BALANCE_DEADBAND)`` and the scaling lowers ``c + r`` by at least
    ``1 - _BALANCE_FACTOR``; sweeps repeat until nothing changes (at most 100). Powers of
    two make the scaling and its inverse exact. ``A``, ``B``, ``C`` are
    expected prescaled to entries of modulus ``<= 1`` (so the sums do not
    overflow). All-zero exponents (the paper's systems) leave the data alone.
    """
    n = A.shape[0]
    k = np.zeros(n, dtype=int)
    if n < 2 and B.size == 0 and C.size == 0:
        return k
    Aa, Ba, Ca = np.abs(A), np.abs(B), np.abs(C)
    diag = np.diag(Aa).copy()
    for _ in range(100):
        changed = False
        for i in range(n):
            c = float(Aa[:, i].sum() - diag[i] + Ca[:, i].sum())
            r = float(Aa[i, :].sum() - diag[i] + Ba[i, :].sum())
            if c == 0.0 or r == 0.0:
                continue
            ratio = float(np.log2(r) - np.log2(c))
            if abs(ratio) <= _BALANCE_DEADBAND:
                continue
            step = int(np.round(0.5 * ratio))
            step = int(np.clip(step, -_BALANCE_MAX_EXP - k[i], _BALANCE_MAX_EXP - k[i]))
            if step == 0:
                continue
            f = np.ldexp(1.0, step)
            if c * f + r / f >= _BALANCE_FACTOR * (c + r):
                continue
            Aa[:, i] *= f
            Ca[:, i] *= f
            Aa[i, :] /= f
            Ba[i, :] /= f
            diag[i] = Aa[i, i]
            k[i] += step
            changed = True
        if not changed:
            break
    return k


# ---------------------------------------------------------------------------
# the algorithm
# ---------------------------------------------------------------------------
def strong_detectability(
    A, B_unknown, C, *, tol: float | None = None, margin: float = DEFAULT_MARGIN, poles=None
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
        unit-free. ``None`` (default: :func:`~dobs_envs.linalg.subspaces.rank_tol`)
        or a positive finite number; anything else is a ``ValueError`` naming ``tol``.
    margin : float, optional
        Requested stability margin of the assignable part of ``E`` (in the time
        unit of ``A``): the ARE that gives ``J_2`` (posed on the observable
        part of the step-6 pair, :func:`_stabilising_injection`) is shifted by
        ``margin``; the fixed (unobservable, stable) modes keep their values.
    poles : array_like, optional
        Pin the assignable eigenvalues of ``E`` instead of the ARE's choice:
        one value per mode of the observable part of the step-6 pair (complex
        values in conjugate pairs, every ``Re < 0``, in the time unit of ``A``),
        placed with :func:`scipy.signal.place_poles` on ``(A_o, C_o)``. The
        other eigenvalues of ``E`` are not free: the fixed (stable,
        unobservable) modes of the pair and ``-margin`` for each row of ``C``
        outside ``Im T_d`` (those functionals are measured). A wrong count
        raises ``ValueError`` stating how many are assignable; nodes with
        ``E = 0`` have none.

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
        rank; a ``margin`` so large next to ``||A||`` (subnormal ``A``) that
        ``margin / ||A||`` or the gains overflow double precision.
    IllConditionedError
        (a ``ValueError``) The data are too badly scaled, or too close to a
        rank or stability boundary, for a reliable result in double
        precision, even after balancing; the message says which check failed
        (e.g. residuals of the defining equations above ``1e-7`` on the
        caller's data, no stabilising ``J_2``). Never an internal
        ``RuntimeError``.

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
    4. Scaling (issue 12). Exact powers of two first: ``A`` to entries below
       1, every column of ``B_unknown`` and every row of ``C`` likewise (the
       unknown inputs and the outputs have arbitrary units). Then a diagonal
       state-coordinate balancing ``x = D x_b``, ``D = diag(2^k)``, of the
       system matrix ``[[A, B], [C, 0]]`` (:func:`_balancing_exponents`,
       LAPACK ``dgebal``'s scaling loop, with a dead band so ordinarily scaled
       systems are left exactly as given); the result is mapped back with
       ``T_id^T = R^{-T} T_b^T D^{-1}`` (QR of ``D^{-1} T_b``), ``E = R^{-T}
       E_b R^T``, ``F = R^{-T} F_b``, ``G = R^{-T} G_b``. If that result
       fails the checks, the unbalanced data are tried (a smaller subspace
       from them is refused: it would not be maximal). Steps 6-8 run in the
       time unit ``max(||A||, margin)``: the ARE shift and the ``E``-block of
       the rows of ``C`` are then at most 1 however slow ``A`` is (before,
       ``A * 1e-20`` gave a shift of ``2e19`` and the ARE failed); only the
       derivative columns of the known-term matrices change. The result is
       re-checked on the caller's data (:func:`lemma2_residuals` <= 1e-7,
       ``T_d^T = G C`` in the ``E = 0`` branch, ``Re lambda(E) < 0``).
    5. Cost ``O(n^3)``. Step 6 computes the unobservable subspace of
       ``(Pi_3, Pi_4)`` with one observability staircase
       (:func:`~dobs_envs.linalg.subspaces.observability_staircase`:
       Householder reflections and SVDs of the small triangular factors,
       ranks decided on singular values against one explicit threshold,
       ``DEFAULT_RTOL * max(1, ||[Pi_4; Pi_3]||_2)`` by default), and the
       Wonham split ``P_d = [W_o, V_o Z_s]`` (``Z_s``: ordered Schur vectors
       of the stable unobservable modes) already separates the observable
       part ``(A_o, C_o)`` from the fixed modes of the detectable pair, so
       ``J_2`` needs no second unobservable-subspace computation. (Before:
       ``ker [Pi_4; V_k^perp Pi_3]`` by a full SVD at each of up to ``r + 1``
       steps, twice: ``O(n^4)``.) ``J_2``: the shifted ARE on ``(A_o, C_o)``;
       if it has no finite stabilising solution (many modes, few relations),
       the ARE on the modes with ``Re >= -margin`` only
       (:func:`_stabilising_injection`).
    """
    A0, B0, C0 = _validate(A, B_unknown, C)
    tol = check_tol(tol)  # before any rank decision: a bad tol is the caller's, not the system's scaling
    n = A0.shape[0]
    p = C0.shape[0]
    margin = as_float(margin, "margin", positive=True)

    # ---- exact scaling (implementation choice 4) -----------------------------
    # powers of two: A = 2^ka A1, every column of B and every row of C scaled to entries of
    # modulus in [1/2, 1) (the unknown inputs and the outputs have arbitrary units) ...
    ka = _pow2_exponent(A0)
    kb, kc = _pow2_exponents(B0, 0), _pow2_exponents(C0, 1)
    A1, B1, C1 = np.ldexp(A0, -ka), np.ldexp(B0, -kb[None, :]), np.ldexp(C0, -kc[:, None])
    if p:
        rank_c = scaled_rank(C0, tol)
        if rank_c < p:
            raise ValueError(
                f"C must have full row rank (the paper requires C_i to have full row rank); "
                f"got shape {C0.shape} with numerical rank {rank_c}"
            )
    with np.errstate(over="ignore"):
        margin1 = float(np.ldexp(margin, -ka))  # the margin in the time unit of A1
    if not (np.isfinite(margin1) and margin1 > 0):
        raise ValueError(
            f"margin = {margin:g} is out of range for this A (max |A_ij| ~ 2^{ka}): "
            "margin / ||A|| is not representable in double precision, and so would the observer "
            "gains be; rescale time (A -> A / s, margin -> margin / s)"
        )
    poles1 = None if poles is None else _check_poles(poles) * np.ldexp(1.0, -ka)  # in the time unit of A1 (exact)
    # ... then a diagonal state-coordinate balancing x = D x_b, D = diag(2^kd); when it
    # changes anything and its result fails the checks, the unbalanced data are tried
    # (a smaller subspace from the unbalanced data is not accepted: it would not be maximal)
    kd = _balancing_exponents(A1, B1, C1)
    attempts = [kd, None] if np.any(kd) else [None]
    first_exc = None
    for k_bal in attempts:
        try:
            T_d, E, F, G, in_rowC = _attempt(A0, B0, C0, A1, B1, C1, k_bal, ka, kc, tol, margin, margin1,
                                             poles1)
        except IllConditionedError as exc:
            first_exc = first_exc or exc
            continue
        if first_exc is not None and (getattr(first_exc, "delta", None) or 0) > T_d.shape[1]:
            raise first_exc
        break
    else:
        raise first_exc
    delta = T_d.shape[1]
    T_u = null_space(T_d.T) if delta else np.eye(n)
    out = StrongDetectability(T_d=T_d, T_u=T_u, E=E, F=F, G=G)
    for arr in (out.T_d, out.T_u, out.E, out.F, out.G):
        arr.setflags(write=False)
    return out


def _attempt(A0, B0, C0, A1, B1, C1, kd, ka, kc, tol, margin, margin1, poles1=None):
    """One design of the prescaled data ``(A1, B1, C1)``, balanced by ``D = diag(2^kd)``
    unless ``kd`` is None, mapped back to the caller's coordinates and checked there.

    Raises :class:`IllConditionedError` (numerical failure, failed checks) or ``ValueError``.
    """
    if kd is not None:
        A1 = np.ldexp(A1, kd[None, :] - kd[:, None])  # D^-1 A D
        B1 = np.ldexp(B1, -kd[:, None])  # D^-1 B
        C1 = np.ldexp(C1, kd[None, :])  # C D
    delta = None
    try:
        # overflow / NaN are not trapped here (scipy relies on IEEE semantics internally):
        # they end in a LinAlgError below or in the finiteness and residual checks
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            T_d, E, F, G, in_rowC = _fuio(A1, B1, C1, tol, margin1, poles1)
            delta = T_d.shape[1]
            # ---- undo the balancing: T_b^T x_b = T_b^T D^-1 x, re-orthonormalised ----
            if kd is not None and delta:
                Qd, Rd = np.linalg.qr(np.ldexp(T_d, -kd[:, None]))
                RdT = Rd.T  # T_d^T (new) = Rd^-T T_b^T D^-1
                T_d = Qd
                G = sla.solve_triangular(RdT, G, lower=True, check_finite=False)
                if not in_rowC:
                    E = sla.solve_triangular(RdT, E @ RdT, lower=True, check_finite=False)
                    F = sla.solve_triangular(RdT, F, lower=True, check_finite=False)
    except np.linalg.LinAlgError as exc:
        if not isinstance(exc, IllConditionedError):
            exc = IllConditionedError(
                f"Lemma 2 (FUIO): a LAPACK routine failed ({exc}); the system is too badly scaled "
                "or too close to a rank boundary for double precision"
            )
        exc.delta = delta
        raise exc
    try:
        return _finish(A0, B0, C0, T_d, E, F, G, in_rowC, ka, kc, margin)
    except IllConditionedError as exc:
        exc.delta = delta  # the dimension found before the failing check
        raise


def _finish(A0, B0, C0, T_d, E, F, G, in_rowC, ka, kc, margin):
    """Undo the powers of two and check the result on the caller's data."""
    p = C0.shape[0]
    delta = T_d.shape[1]
    # ---- undo the powers of two: time unit 2^-ka, outputs y = diag(2^kc) y_1 ---------
    with np.errstate(over="ignore"):
        E = np.ldexp(E, ka)
        F = np.ldexp(F, ka - kc[None, :])
        G = np.ldexp(G, -kc[None, :])
    if not (np.all(np.isfinite(T_d)) and np.all(np.isfinite(E)) and np.all(np.isfinite(F))
            and np.all(np.isfinite(G))):
        if not np.all(np.isfinite(T_d)):
            raise IllConditionedError(
                "Lemma 2 (FUIO): overflow or an invalid operation in the design; the system is too "
                "badly scaled for double precision"
            )
        raise ValueError(
            f"the observer gains of Lemma 2 overflow double precision for margin = {margin:g} "
            f"and this A, C (G grows like margin / ||A||, F like margin^2 / ||A|| per unit of C); "
            "rescale time or the outputs"
        )
    if in_rowC:
        E = np.zeros((delta, delta))
        F = np.zeros((delta, p))
    _self_check(A0, B0, C0, T_d, E, F, G, margin)
    if delta and not in_rowC:
        ev = np.linalg.eigvals(E)  # LAPACK dgeev balances E first
        if not np.all(ev.real < 0):
            raise IllConditionedError(
                "Lemma 2 (FUIO): the observer matrix E mapped back to the given coordinates has "
                f"an eigenvalue with Re = {ev.real.max():.3g} >= 0 (||E|| = {np.linalg.norm(E, 2):.3g}); "
                "the change of coordinates is too ill-conditioned for double precision"
            )
    return T_d, E, F, G, in_rowC


def _check_poles(poles) -> np.ndarray:
    """``poles`` as a 1-D complex array: finite, ``Re < 0``, closed under conjugation."""
    try:
        P = np.asarray(poles, dtype=complex).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"poles must be an array of numbers, got {poles!r}") from None
    if not np.all(np.isfinite(P)) or np.any(P.real >= 0):
        raise ValueError(f"poles must be finite with negative real parts (E Hurwitz), got {P.tolist()}")
    if not np.allclose(np.sort_complex(P), np.sort_complex(P.conj()), rtol=1e-12, atol=0.0):
        raise ValueError(f"poles must come in complex-conjugate pairs (E is real), got {P.tolist()}")
    return P


def _placed_injection(Ao: np.ndarray, Co: np.ndarray, poles: np.ndarray, n_fixed: int, kc: int) -> np.ndarray:
    """``J_o`` with ``eig(Ao + J_o Co) = poles`` (:func:`scipy.signal.place_poles` on the dual pair)."""
    from scipy.signal import place_poles

    ro = Ao.shape[0]
    if poles.size != ro:
        raise ValueError(
            f"poles: this node's E has {ro} assignable eigenvalue(s) (the observable part of the "
            f"step-6 pair), besides {n_fixed} fixed unobservable mode(s) and up to {kc} at -margin for "
            f"the measured rows of C; got {poles.size} pole(s)"
        )
    try:
        K = place_poles(Ao.T, Co.T, poles).gain_matrix
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise ValueError(f"poles: cannot place {poles.tolist()} on this node's observable pair ({exc})") from None
    return -K.T


def _fuio(A0, B0, C0, tol, margin, poles=None):
    """Steps 1-8 on prescaled, balanced data; returns ``(T_d, E, F, G, in_rowC)``
    in the data's units (``in_rowC``: the ``E = 0`` branch)."""
    n = A0.shape[0]
    p = C0.shape[0]

    # ---- normalisation (implementation choice 2) -------------------------------------
    a_scale = float(np.linalg.norm(A0, 2))
    if a_scale == 0.0:
        a_scale = 1.0
    As = A0 / a_scale
    c_norm = float(np.linalg.norm(C0, 2)) if C0.size else 0.0
    if p:
        Uc, sc, Vct = np.linalg.svd(C0 / c_norm if c_norm else C0, full_matrices=False)
        rank_c = int(np.sum(sc > rank_tol(sc, C0.shape, tol))) if c_norm else 0
        if rank_c < p:  # C itself has full row rank (checked by the caller): the balancing lost it
            raise IllConditionedError(
                f"C D (C in balanced coordinates) has numerical rank {rank_c} < {p}"
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
    # Time unit of steps 6-8 (implementation choice 4): that of As while the margin is
    # not faster than ||A|| (alpha <= 1), else 1/margin, so that the ARE shift and the
    # E-block of the rows of C are <= 1 whatever margin / ||A|| is. With
    # s = a_scale / t_unit <= 1 the step-6 identities in the new unit read
    #   rho' = s Pi3 rho + [s Kt_y, Kt_d] Y',   0 = Pi4 rho + [Kb_y, Kb_d / s] Y'
    # (Y' = [y_q; dy_q/dt'], t' = t_unit t): only the derivative columns change.
    t_unit = max(a_scale, margin)
    s_t = a_scale / t_unit
    alpha = margin / t_unit  # the margin in that unit (<= 1)
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
        # observability staircase of (Pi3, Q4): [Wo Vo], Im Vo unobservable (one O(r^3) pass)
        stair_tol = tol
        if stair_tol is None:
            stack = np.vstack([Q4, Pi3])
            stair_tol = rank_tol(np.array([np.linalg.norm(stack, 2)]), stack.shape)
        U_obs, r_o = observability_staircase(Pi3, Q4, stair_tol)
        Wo, Vo = U_obs[:, :r_o], U_obs[:, r_o:]
        scale3 = max(1.0, float(np.linalg.norm(Pi3, 2)))
        # Wonham: undetectable = unstable part of the unobservable subspace. With the
        # ordered Schur vectors [Z_u, Z_s] of Vo^T Pi3 Vo, P_u = Vo Z_u and the detectable
        # quotient has the orthonormal basis P_d = [Wo, Vo Z_s], in which
        #   P_d^T Pi3 P_d = [[A_o, 0], [*, A_f]],   Q4 P_d = [C_o, 0]
        # (A_f: the stable fixed modes, (A_o, C_o) observable).
        Zu, k_u = _schur_unstable_first(Vo.T @ Pi3 @ Vo, scale3)
        P_d = np.hstack([Wo, Vo @ Zu[:, k_u:]])
        r_d = P_d.shape[1]
        if r_d:
            Pi3d = s_t * (P_d.T @ Pi3 @ P_d)
            Pi4d = Q4 @ P_d  # orthonormal rows since Q4 P_u = 0
            J2 = np.zeros((r_d, Pi4d.shape[0]))
            if poles is not None:  # pinned eigenvalues, in the working time unit
                if r_o and Pi4d.shape[0]:
                    J2[:r_o] = _placed_injection(Pi3d[:r_o, :r_o], Pi4d[:, :r_o], poles / t_unit, r_d - r_o, p)
                elif poles.size:
                    _placed_injection(np.zeros((0, 0)), np.zeros((0, 0)), poles, r_d - r_o, p)
            elif Pi4d.shape[0] and r_o:
                J2[:r_o] = _stabilising_injection(Pi3d[:r_o, :r_o], Pi4d[:, :r_o], alpha, margin / a_scale)
            E_dyn = Pi3d + J2 @ Pi4d
            Kt = np.hstack([s_t * Kt[:, :p], Kt[:, p:]])
            Kb = np.hstack([Kb[:, :p], Kb[:, p:] / s_t])
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

    if in_rowC and poles is not None and poles.size:
        raise ValueError(
            f"poles: this node's reconstructible functionals are all measured (E = 0 branch, "
            f"T_id^T = G C): E has no assignable eigenvalues; got {poles.size} pole(s)"
        )
    if in_rowC:
        # E = 0 branch: T_id^T = G C (the step-6 functionals are measured)
        T_d = Cq.T.copy()
        E_s = np.zeros((p, p))
        F_s = np.zeros((p, p))
        G_s = np.eye(p)
    else:
        Rc = Vxt[:kc] / sx[:kc, None]  # (kc, p): c_rows = Rc Cq
        T0 = np.vstack([T_dyn, Rc @ Cq])  # T_id0^T
        E_blk = sla.block_diag(E_dyn, -alpha * np.eye(kc))
        F_blk = np.vstack([F_dyn, np.zeros((kc, p))])
        G_blk = np.vstack([G_dyn, Rc])
        # ---- step 8: Gram-Schmidt T0^T = Qr Rq -> T_d^T = Rq^{-T} T0 ---------
        Qr, Rq = np.linalg.qr(T0.T)
        T_d = Qr
        RqT = Rq.T
        E_s = np.linalg.solve(RqT, E_blk @ RqT)
        F_s = np.linalg.solve(RqT, F_blk)
        G_s = np.linalg.solve(RqT, G_blk)

    # E_s is block triangular: the ARE-placed block (checked in _stabilising_injection),
    # the fixed modes (classified stable in step 6, relative to ||Pi_3||) and -alpha I; only
    # the sign is re-checked here, since the fixed modes may be tiny next to the margin.
    if not in_rowC and E_s.size:
        ev_s = np.linalg.eigvals(E_s)
        if not np.all(ev_s.real < 0):
            raise IllConditionedError(
                "Lemma 2 (FUIO): the observer matrix E has an eigenvalue with Re = "
                f"{ev_s.real.max():.3g} >= 0 in the working coordinates (||E|| = "
                f"{np.linalg.norm(E_s, 2):.3g}); eigenvalues of the step-6 pair are too close "
                "to the imaginary axis to be classified"
            )
    # ---- undo the normalisation (time unit t_unit, outputs y_q = L y) -------
    E = t_unit * E_s
    F = t_unit * F_s @ L
    G = G_s @ L
    return T_d, E, F, G, in_rowC


def lemma2_residuals(A, B_unknown, C, res: StrongDetectability) -> tuple[float, float]:
    """Relative residuals of the two equalities of Lemma 2 (FUIO).

    Returns ``(rB, rA)`` with
    ``rB = ||G C B - T_d^T B|| / ((||G|| ||C|| + 1) ||B||)`` and
    ``rA = ||E T_d^T + (G C - T_d^T) A + (F - E G) C|| /
    (||E|| + (||G|| ||C|| + 1) ||A|| + (||F|| + ||E|| ||G||) ||C||)``
    (2-norms; the denominators bound the norms of the summands, so the
    residual is measured against the size of the terms that cancel).

    Both ratios are evaluated in the units in which every column of ``B``
    and every row of ``C`` has largest entry in ``[1/2, 1)`` (``B -> B diag(b)``,
    ``C -> diag(c) C``, ``G -> G diag(1/c)``, ``F -> F diag(1/c)``: only
    ``Im B`` matters and the outputs have arbitrary units, so a column of
    ``B`` is not negligible because it is small) and ``A, E -> a A, a E``
    (time unit), all powers of two; entries near the overflow or underflow
    thresholds then do not spoil them. A ratio that still cannot be formed is
    returned as ``inf``.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B_unknown, dtype=float)
    C = np.asarray(C, dtype=float)
    T = np.asarray(res.T_d, dtype=float)
    ka, kb, kc = _pow2_exponent(A), _pow2_exponents(B, 0), _pow2_exponents(C, 1)
    with np.errstate(all="ignore"):
        A, B, C = np.ldexp(A, -ka), np.ldexp(B, -kb[None, :]), np.ldexp(C, -kc[:, None])
        E = np.ldexp(np.asarray(res.E, dtype=float), -ka)
        F = np.ldexp(np.asarray(res.F, dtype=float), kc[None, :] - ka)
        G = np.ldexp(np.asarray(res.G, dtype=float), kc[None, :])

        def nrm(M):
            return float(np.linalg.norm(M, 2)) if M.size else 0.0

        try:
            nC = nrm(C)
            if B.size:
                rB = nrm(G @ C @ B - T.T @ B) / max((nrm(G) * nC + 1.0) * nrm(B), np.finfo(float).tiny)
            else:
                rB = 0.0
            lhs = E @ T.T + (G @ C - T.T) @ A + (F - E @ G) @ C
            den = nrm(E) + (nrm(G) * nC + 1.0) * nrm(A) + (nrm(F) + nrm(E) * nrm(G)) * nC
            rA = nrm(lhs) / max(den, np.finfo(float).tiny) if lhs.size else 0.0
        except np.linalg.LinAlgError:  # non-finite products (overflow)
            return float("inf"), float("inf")
    rB = rB if np.isfinite(rB) else float("inf")
    rA = rA if np.isfinite(rA) else float("inf")
    return rB, rA


def _self_check(A, B, C, T_d, E, F, G, margin) -> None:
    tmp = StrongDetectability(T_d=T_d, T_u=np.zeros((A.shape[0], 0)), E=E, F=F, G=G)
    rB, rA = lemma2_residuals(A, B, C, tmp)
    if T_d.shape[1] and not np.any(E):  # E = 0 branch: also T_d^T = G C (and F = 0)
        kc = _pow2_exponents(C, 1)
        C1, G1 = np.ldexp(C, -kc[:, None]), np.ldexp(G, kc[None, :])
        r0 = float(np.linalg.norm(G1 @ C1 - T_d.T, 2)) / (float(np.linalg.norm(G1, 2))
                                                          * float(np.linalg.norm(C1, 2)) + 1.0)
        if not (r0 <= _CHECK_TOL and not np.any(F)):
            raise IllConditionedError(
                f"Lemma 2 (FUIO): the E = 0 result fails T_d^T = G C (relative residual {r0:.2e}); "
                "the change of coordinates is too ill-conditioned for double precision"
            )
    if C.size:  # Im C^T in Im T_d: the rows of C always satisfy Lemma 2 (E = 0, T_d^T = C), so the
        # maximal T_d holds them; missing one means a rank decision neglected it at the data's scale
        kc = _pow2_exponents(C, 1)
        C1 = np.ldexp(C, -kc[:, None])  # rows to unit scale (powers of two: exact)
        miss = float(np.linalg.norm(C1.T - T_d @ (T_d.T @ C1.T), 2)) / float(np.linalg.norm(C1, 2))
        if not miss <= _CHECK_TOL:
            raise IllConditionedError(
                f"Lemma 2 (FUIO): the computed subspace Im T_d misses a measured direction (Im C^T; "
                f"relative residual {miss:.2e} > {_CHECK_TOL:g}): a rank decision at the tolerance "
                "neglected it at the scale of the data, so the result would not be maximal; the system "
                "is too badly scaled for double precision"
            )
    if not (rB <= _CHECK_TOL and rA <= _CHECK_TOL):
        ka = _pow2_exponent(A)
        a_norm = float(np.linalg.norm(np.ldexp(A, -ka), 2))
        ratio = float(np.ldexp(margin / a_norm, -ka)) if a_norm else float("inf")
        raise IllConditionedError(
            f"Lemma 2 (FUIO): the result fails its defining equations on the given data (relative "
            f"residuals {rB:.2e}, {rA:.2e} > {_CHECK_TOL:g}): rank decisions at the tolerance "
            "neglected terms that matter at the scale of the data, or round-off was amplified by "
            f"gains of order margin / ||A||_2 = {ratio:.3g}; the system is numerically ill-posed "
            "(badly scaled, too close to a rank boundary, or too slow for this margin) for double "
            "precision"
        )
