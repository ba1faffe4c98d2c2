"""Tests of the geometric characterisation of the strongly detectable subspace.

Ground truths are derived by hand (docstrings of each test) or by an
independent computation (PBH rank test, the dual maximal controlled invariant,
an explicitly constructed functional observer).

Tolerances: the systems are O(1) with exact small-integer or orthogonal data,
so subspaces computed by SVD carry errors of a few 1e-15; projector distances
are compared against 1e-8 (orders of magnitude above round-off, orders below
any genuine difference, which is >= ~1e-3 for these examples). Rotated
nilpotent chains go through ordered Schur forms of matrices whose computed
eigenvalues are perturbed by ~1e-3, but the invariant subspaces themselves are
well conditioned, so 1e-8 still applies.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from hypothesis import given, settings
from hypothesis import strategies as st

from dobs_envs.design.geometric import (
    minimal_conditioned_invariant,
    reconstructibility_decomposition,
    reconstructible_subspace,
    undetectable_subspace,
    unobservable_subspace,
    unreconstructible_directions,
    unstable_subspace,
)
from dobs_envs.design.subspaces import (
    classify_stable_eigenvalues,
    contains,
    eigenvalue_clusters,
    is_hurwitz,
    null_space,
    orth,
    orth_complement,
    projector_distance,
    subspace_intersection,
    subspace_sum,
)

import paper_ne2 as NE2  # the tests' transcription of NE2 (tests/paper_ne2.py)

TOL = 1e-8


def e(n, *idx):
    return np.eye(n)[:, list(idx)]


def same(X, Y, tol=TOL):
    return projector_distance(np.asarray(X, float), np.asarray(Y, float)) <= tol


# ---------------------------------------------------------------------------
# the paper's NE2 / NE3 systems (section NE2 of the paper)
# ---------------------------------------------------------------------------
def ne2():
    """NE2 (tests/paper_ne2.py): A, channels, outputs, each node's unknown input, the printed T_id."""
    nodes = range(NE2.N_NODES)
    return NE2.A(), NE2.channels(), NE2.outputs(), [NE2.b_unknown(i) for i in nodes], [NE2.t_d(i) for i in nodes]


@pytest.mark.parametrize("node", range(6))
def test_ne2_matches_paper(node):
    """The paper prints T_1d..T_6d for NE2 (4 decimals; tests/paper_ne2.py holds the exact values)."""
    A, _, Cs, Bu, paper_T = ne2()
    T = reconstructible_subspace(A, Bu[node], Cs[node])
    assert T.shape == paper_T[node].shape
    assert np.allclose(T.T @ T, np.eye(T.shape[1]), atol=1e-12)
    assert same(T, paper_T[node])


@pytest.mark.parametrize("node", range(6))
def test_ne3_matches_paper(node):
    """NE3 adds B_v = [B^1 B^2] to every node's unknown input; the paper gives
    T_2d = e3 and the other T_id unchanged from NE2."""
    A, _, Cs, Bu, _ = ne2()
    T = reconstructible_subspace(A, np.hstack([Bu[node], NE2.b_v()]), Cs[node])
    assert same(T, NE2.t_d(node, ne3=True))


def test_ne2_collectively_strongly_detectable():
    A, _, Cs, Bu, _ = ne2()
    total = subspace_sum(*[reconstructible_subspace(A, Bu[i], Cs[i]) for i in range(6)])
    assert total.shape[1] == 9
    # and no direction is unreconstructible for all nodes at once
    common = unreconstructible_directions(A, Bu[0], Cs[0])
    for i in range(1, 6):
        common = subspace_intersection(common, unreconstructible_directions(A, Bu[i], Cs[i]))
    assert common.shape[1] == 0


@pytest.mark.parametrize("seed", range(4))
def test_rotated_ne2_integrator_chains(seed):
    """Coordinate invariance: Im T_d(Q^T A Q, Q^T B, C Q) = Q^T Im T_d(A, B, C).
    In rotated coordinates the 9 zero eigenvalues of the nilpotent A (chain of
    length 5) are computed with errors ~1e-3, some with Re < -1e-8; a per
    eigenvalue classification would declare parts of the chain stable."""
    A, _, Cs, Bu, paper_T = ne2()
    Q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((9, 9)))
    for i in range(6):
        T = reconstructible_subspace(Q.T @ A @ Q, Q.T @ Bu[i], Cs[i] @ Q)
        assert same(T, Q.T @ paper_T[i])
    # without outputs everything is undetectable (all modes are integrators)
    assert undetectable_subspace(Q.T @ A @ Q, np.zeros((0, 9))).shape[1] == 9


# ---------------------------------------------------------------------------
# hand-derived special cases
# ---------------------------------------------------------------------------
def test_double_integrator():
    """x1' = x2, x2' = u, y = x1: S_0 = span e2, S_0 ∩ ker C = span e2,
    A e2 = e1, so S* = R^2 and S* ∩ ker C = span e2: only x1 (= y) is
    reconstructible (x2 = y' would need a derivative)."""
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    B = e(2, 1)
    C = np.array([[1.0, 0.0]])
    assert minimal_conditioned_invariant(A, B, C).shape[1] == 2
    assert same(reconstructible_subspace(A, B, C), e(2, 0))
    assert same(unreconstructible_directions(A, B, C), e(2, 1))


def test_triple_integrator_relative_degree_three():
    A = np.diag([1.0, 1.0], 1)
    B = e(3, 2)
    C = np.array([[1.0, 0, 0]])
    assert same(reconstructible_subspace(A, B, C), e(3, 0))


def test_double_integrator_with_velocity_measurement():
    """y = x2 with u on x2: S* = span e2 (S* ∩ ker C = 0); the quotient is
    x1' = x2 = y -> xi' = 0 * xi with no usable output: an integrator, fixed
    and marginal, so x1 is lost: only x2 reconstructible."""
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    T = reconstructible_subspace(A, e(2, 1), np.array([[0.0, 1.0]]))
    assert same(T, e(2, 1))


@pytest.mark.parametrize(
    "a22, full",
    [(-1.0, True), (1.0, False), (0.0, False), (-1e-3, True)],
)
def test_invariant_zero(a22, full):
    """A = [[0, 1], [1, a22]], B = e1, y = x1. C B = 1 so S* = span e1 and
    S* ∩ ker C = 0. Quotient xi = x2: x2' = x1 + a22 x2 = y + a22 x2, i.e.
    A_q = a22 with no output left (C V = 1 has trivial left null space):
    a22 is the invariant zero of (A, B, C). Stable zero -> full state via
    z' = a22 z + y; unstable or marginal zero -> only x1."""
    A = np.array([[0.0, 1.0], [1.0, a22]])
    B = e(2, 0)
    C = np.array([[1.0, 0.0]])
    dec = reconstructibility_decomposition(A, B, C)
    assert same(dec.S_star, e(2, 0))
    assert np.allclose(dec.A_q, [[a22]], atol=1e-12)
    assert dec.C_q.shape == (0, 1)
    T = dec.reconstructible
    assert same(T, np.eye(2) if full else e(2, 0))


def test_unstable_zero_hides_only_its_direction():
    """Two copies: x = (x1, x2, x3, x4) with blocks [[0,1],[1,-2]] (zero -2) and
    [[0,1],[1,+3]] (zero +3), unknown inputs on x1 and x3, outputs x1, x3.
    Only x4 is unreconstructible."""
    A = sla.block_diag([[0, 1], [1, -2.0]], [[0, 1], [1, 3.0]])
    B = e(4, 0, 2)
    C = np.eye(4)[[0, 2]]
    assert same(unreconstructible_directions(A, B, C), e(4, 3))


def test_imaginary_axis_pair_is_not_stable():
    """Unobserved oscillator x3, x4 (eigenvalues +-2i) plus observed stable
    x1, x2; B = 0. The oscillator is undetectable (marginal is not stable);
    with damping -0.1 it becomes detectable."""
    for damp, expect in [(0.0, e(4, 0, 1)), (-0.1, np.eye(4))]:
        A = sla.block_diag([[-1.0, 1.0], [0.0, -2.0]], [[damp, 2.0], [-2.0, damp]])
        C = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
        assert same(reconstructible_subspace(A, np.zeros((4, 0)), C), expect)
        assert same(undetectable_subspace(A, C), orth_complement(expect, 4))


def test_integrator_driven_by_unknown_input():
    """x1' = u, x2' = -x2 + x1, y = x2. S_0 = e1, e1 ∈ ker C, A e1 = e2, so
    S* = R^2: nothing but y is reconstructible, even though (A, C) is
    observable."""
    A = np.array([[0.0, 0.0], [1.0, -1.0]])
    assert same(reconstructible_subspace(A, e(2, 0), np.array([[0.0, 1.0]])), e(2, 1))
    assert same(reconstructible_subspace(A, None, np.array([[0.0, 1.0]])), np.eye(2))


def test_no_output():
    """p = 0: reconstructible = complement of (reachable from B + undetectable)."""
    A = np.diag([-1.0, -2.0, 0.5])
    T = reconstructible_subspace(A, e(3, 0), np.zeros((0, 3)))
    assert same(T, e(3, 1))


def test_redundant_columns_and_rank_deficient_C():
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -2.0, -3.0]])
    B = e(3, 2)
    C = np.array([[1.0, 0, 0], [2.0, 0, 0]])
    T1 = reconstructible_subspace(A, B, C)
    T2 = reconstructible_subspace(A, np.hstack([B, 2 * B, np.zeros((3, 1))]), C[:1])
    assert same(T1, T2)


# ---------------------------------------------------------------------------
# B = 0: Table I, detectable subspace, against PBH
# ---------------------------------------------------------------------------
def _pbh_undetectable(A, C, eigs_unstable):
    """Independent PBH computation for a diagonalisable A: for every non-stable
    eigenvalue s (given exactly), the right null space of [sI - A; C]; real
    and imaginary parts span the undetectable subspace."""
    n = A.shape[0]
    vecs = [np.zeros((n, 0))]
    for s in eigs_unstable:
        M = np.vstack([s * np.eye(n) - A, C.astype(complex)])
        _, sv, Vh = np.linalg.svd(M)
        r = int(np.sum(sv > 1e-9 * max(1.0, sv[0])))
        N = Vh[r:].conj().T
        vecs += [N.real, N.imag]
    return orth(np.hstack(vecs))


@st.composite
def diagonalisable_systems(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n_real = draw(st.integers(0, 4))
    n_pair = draw(st.integers(0, 2))
    if n_real + 2 * n_pair == 0:
        n_real = 1
    reals = list(rng.choice([-2.0, -1.0, -0.5, 0.0, 0.7, 1.5], size=n_real, replace=False))
    pairs = [(rng.choice([-0.5, 0.0, 0.4]), rng.choice([1.0, 2.5])) for _ in range(n_pair)]
    blocks = [np.array([[r]]) for r in reals] + [np.array([[a, b], [-b, a]]) for a, b in pairs]
    D = sla.block_diag(*blocks)
    n = D.shape[0]
    P = rng.standard_normal((n, n)) + 2 * np.eye(n)
    A = P @ D @ np.linalg.inv(P)
    # observe a random subset of the (real) modes through the left eigenvectors
    Pinv = np.linalg.inv(P)
    sizes = [b.shape[0] for b in blocks]
    starts = np.cumsum([0] + sizes[:-1])
    observed = rng.random(len(blocks)) < 0.5
    rows = [Pinv[s0:s0 + sz] for s0, sz, o in zip(starts, sizes, observed) if o]
    if rows:
        R = np.vstack(rows)
        C = rng.standard_normal((R.shape[0], R.shape[0])) @ R
    else:
        C = np.zeros((0, n))
    eig_unst = []
    expected = [np.zeros((n, 0))]
    for blk, s0, sz, o in zip(blocks, starts, sizes, observed):
        ev = np.linalg.eigvals(blk)
        if np.all(ev.real >= 0):
            if sz == 1:
                eig_unst.append(float(blk[0, 0]))
            else:
                eig_unst += [blk[0, 0] + 1j * blk[0, 1], blk[0, 0] - 1j * blk[0, 1]]
            if not o:
                expected.append(P[:, s0:s0 + sz])
    return A, C, eig_unst, orth(np.hstack(expected))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(diagonalisable_systems())
def test_B_zero_is_detectable_subspace_pbh(system):
    A, C, eig_unst, expected = system
    n = A.shape[0]
    U = undetectable_subspace(A, C)
    # tolerance: P has condition number <= ~1e2, so subspaces carry ~1e-13 errors
    assert same(U, expected, 1e-7)
    assert same(U, _pbh_undetectable(A, C, eig_unst), 1e-7)
    T = reconstructible_subspace(A, np.zeros((n, 0)), C)
    assert same(T, orth_complement(U, n), 1e-7)
    assert same(reconstructible_subspace(A, None, C), T, 1e-12)


def test_B_zero_jordan_block_hidden():
    """A Jordan block at 0 (x1' = x2, x2' = 0) hidden from y = x3 (x3' = -x3):
    both x1 and x2 undetectable; PBH at s = 0 only finds the eigenvector e1,
    the generalised one e2 comes from the chain."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    C = np.array([[0.0, 0.0, 1.0]])
    assert same(undetectable_subspace(A, C), e(3, 0, 1))
    assert same(_pbh_undetectable(A, C, [0.0]), e(3, 0))
    assert same(reconstructible_subspace(A, None, C), e(3, 2))


# ---------------------------------------------------------------------------
# structural properties on random systems
# ---------------------------------------------------------------------------
@st.composite
def sparse_systems(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(2, 7))
    p = draw(st.integers(0, n - 1))
    m = draw(st.integers(0, 3))
    density = draw(st.sampled_from([0.25, 0.4, 0.7]))
    A = rng.integers(-2, 3, size=(n, n)) * (rng.random((n, n)) < density)
    B = rng.integers(-1, 2, size=(n, m)) * (rng.random((n, m)) < 0.5)
    C = np.eye(n)[rng.choice(n, size=p, replace=False)] if p else np.zeros((0, n))
    return A.astype(float), B.astype(float), C


def _dual_Sstar(A, B, C):
    """S* = (V*)^perp with V* the maximal (A^T, Im C^T)-controlled invariant in
    ker B^T: V_0 = ker B^T, V_{k+1} = ker B^T ∩ (A^T)^{-1}(V_k + Im C^T).
    A different iteration from the one in geometric.py."""
    n = A.shape[0]
    V = null_space(B.T) if B.shape[1] else np.eye(n)
    for _ in range(n + 1):
        R = subspace_sum(V, C.T) if (V.shape[1] or C.shape[0]) else np.zeros((n, 0))
        Rp = orth_complement(R, n)
        pre = null_space(Rp.T @ A.T) if Rp.shape[1] else np.eye(n)
        Vn = subspace_intersection(V, pre) if V.shape[1] and pre.shape[1] else np.zeros((n, 0))
        if Vn.shape[1] == V.shape[1]:
            break
        V = Vn
    return orth_complement(V, n)


def _observer_from_decomposition(A, B, C, dec):
    """Build (H, E, F) with H B = 0, H A = E H + F C, E Hurwitz and
    ker H = S_stab, following the achievability half of the derivation."""
    n = A.shape[0]
    W, Q = dec.W, dec.Q
    A_q, C_q = dec.A_q, dec.C_q
    k = A_q.shape[0]
    Nq = unobservable_subspace(A_q, C_q) if k else np.zeros((0, 0))
    Zo = orth_complement(Nq, k) if k else np.zeros((0, 0))
    Nprime = np.zeros((k, Q.shape[0]))
    if Zo.shape[1] and C_q.shape[0]:
        Ao = Zo.T @ A_q @ Zo
        Co = C_q @ Zo
        X = sla.solve_continuous_are(Ao.T + 0.5 * np.eye(Ao.shape[0]), Co.T,
                                     np.eye(Ao.shape[0]), np.eye(Co.shape[0]))
        Nprime = Zo @ (-X @ Co.T)
    L = dec.L0 + W @ Nprime @ Q if Q.size else dec.L0
    H = orth_complement(dec.S_stab, n).T
    E = H @ (A + L @ C) @ H.T
    F = -H @ L
    return H, E, F, L


@settings(max_examples=60, deadline=None, derandomize=True)
@given(sparse_systems())
def test_invariance_and_achievability(system):
    A, B, C = system
    n = A.shape[0]
    dec = reconstructibility_decomposition(A, B, C)
    V = dec.S_star
    # S* ⊇ Im B and A (S* ∩ ker C) ⊆ S*
    assert contains(V, B)
    kerC = null_space(C) if C.shape[0] else np.eye(n)
    X = subspace_intersection(V, kerC) if V.shape[1] else np.zeros((n, 0))
    assert contains(V, A @ X)
    # equals the dual characterisation (minimality)
    assert same(V, _dual_Sstar(A, B, C))
    # quotient construction
    assert np.allclose(dec.W.T @ (A + dec.L0 @ C) @ V, 0, atol=1e-9)
    # S_stab ⊇ S*, and the returned bases are orthonormal complements
    assert contains(dec.S_stab, V)
    T, U = dec.reconstructible, dec.unreconstructible
    assert T.shape[1] + U.shape[1] == n
    assert np.allclose(T.T @ T, np.eye(T.shape[1]), atol=1e-10)
    assert np.allclose(T.T @ U, 0, atol=1e-10)
    if C.shape[0]:
        assert contains(T, C.T)
    # achievability: an explicit functional observer reconstructs row(H) + row(C)
    H, E, F, L = _observer_from_decomposition(A, B, C, dec)
    assert np.allclose(H @ B, 0, atol=1e-9)
    assert np.allclose(H @ A - E @ H - F @ C, 0, atol=1e-8)
    assert is_hurwitz(E)
    assert same(subspace_sum(H.T, C.T) if (H.size or C.size) else np.zeros((n, 0)), T, 1e-7)
    # Lemma 2's conditions for the stacked functional [H; C] with
    # E' = diag(E, -I), F' = [F; 0], G' = [0; I]
    p = C.shape[0]
    h = H.shape[0]
    Tt = np.vstack([H, C])
    Ep = sla.block_diag(E, -np.eye(p)) if (h + p) else np.zeros((0, 0))
    Fp = np.vstack([F, np.zeros((p, p))])
    Gp = np.vstack([np.zeros((h, p)), np.eye(p)])
    assert np.allclose(Gp @ C @ B, Tt @ B, atol=1e-9)
    assert np.allclose(Ep @ Tt + (Gp @ C - Tt) @ A + (Fp - Ep @ Gp) @ C, 0, atol=1e-8)


def test_unstable_subspace_helper():
    M = np.array([[1.0, 5.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 0.0]])
    U = unstable_subspace(M)
    # generalised eigenspace of {1, 0}: e1 and e3
    assert same(U, e(3, 0, 2))
    assert unstable_subspace(-np.eye(2)).shape == (2, 0)
    assert unstable_subspace(np.zeros((2, 2))).shape == (2, 2)


# ---------------------------------------------------------------------------
# defective eigenvalues -1, 0, 1 (stress systems) and eigenvalue clusters
# ---------------------------------------------------------------------------
#: Permuted upper-triangular systems with eigenvalues -1, 0, 1 of multiplicity
#: 3-5 (Jordan chains), one unknown input, outputs = rows of the identity.
#: (nonzeros of A, B, indices of the measured states, exact delta). The exact
#: deltas were computed with rational arithmetic (sympy: S*, quotient pair
#: (A_q, C_q), unobservable subspace, characteristic polynomial factored over
#: Q, generalised eigenspaces of the roots with Re >= 0).
STRESS_SYSTEMS = [
    (
        [(0, 2, -0.0282), (0, 4, -1.537), (0, 5, 0.7268), (0, 6, -2.0698), (0, 7, -1.2678),
         (1, 1, -1.0), (1, 8, 1.5386), (2, 2, 1.0), (2, 6, 1.2022), (2, 8, -0.738), (3, 3, -1.0),
         (3, 5, 0.4831), (3, 6, -0.9002), (3, 7, -0.7509), (3, 9, 0.7651), (4, 7, 0.8366),
         (4, 8, -0.9429), (5, 5, 1.0), (5, 7, 1.0341), (6, 6, -1.0), (7, 7, 1.0), (7, 8, -1.0804),
         (8, 8, 1.0)],
        [0.5468, 0.0, -1.6005, 0.0, 0.6999, -0.0752, 0.2195, 0.0, 0.0, -2.1658],
        [5, 7], 10, 6,
    ),
    (
        [(0, 1, 2.1065), (0, 2, 2.4836), (0, 6, -0.0139), (0, 7, 0.154), (0, 8, 0.1097),
         (1, 3, 0.8986), (1, 5, -0.3803), (1, 6, -1.283), (2, 2, -1.0), (2, 5, -0.2882),
         (2, 6, -0.4491), (2, 7, 0.4563), (3, 3, 1.0), (3, 4, 0.4184), (3, 7, 0.5137),
         (3, 8, 1.4999), (4, 4, 1.0), (4, 6, 0.2584), (4, 7, 0.4276), (4, 8, 0.7678), (5, 5, 1.0),
         (5, 7, -0.7665), (5, 8, 0.0128), (7, 7, 1.0), (8, 8, 1.0)],
        [0.0, -1.0897, 1.1223, 0.4945, -1.2704, 0.054, 0.0, 0.332, 0.84],
        [5], 9, 2,
    ),
    (
        [(0, 0, -1.0), (0, 2, -0.4553), (0, 8, -0.6544), (1, 1, 1.0), (1, 4, 1.519),
         (1, 6, -0.4775), (2, 2, -1.0), (3, 3, -1.0), (3, 5, -0.678), (3, 6, -0.297), (4, 4, 1.0),
         (5, 5, 1.0), (7, 9, 0.1139), (8, 8, -1.0), (8, 9, 1.0046), (9, 9, -1.0)],
        [0.0, 0.2913, 2.5313, 1.7822, 1.7465, -0.265, -0.3406, 0.0, -0.0802, 0.0],
        [6], 10, 6,
    ),
]


def stress_system(k):
    entries, b, rows, n, delta = STRESS_SYSTEMS[k]
    A = np.zeros((n, n))
    for i, j, v in entries:
        A[i, j] = v
    return A, np.array(b)[:, None], np.eye(n)[rows], delta


@pytest.mark.parametrize("k", range(3))
@pytest.mark.parametrize("rotate", [False, True])
def test_defective_stress_systems(k, rotate):
    """A cluster radius ~||A_q|| eps^(1/k) (of order one here) lumped the
    defective eigenvalues -1, 0, 1 of the quotient map into one cluster
    classified by its mean: delta came out 10, 1, 10 instead of 6, 2, 6 (on
    the third system an unobserved unstable state was called reconstructible)."""
    A, B, C, delta = stress_system(k)
    if rotate:
        Q = np.linalg.qr(np.random.default_rng(k).standard_normal(A.shape))[0]
        A, B, C = Q.T @ A @ Q, Q.T @ B, C @ Q
    dec = reconstructibility_decomposition(A, B, C)
    assert dec.delta == delta
    # consistency of the decomposition: S_stab is conditioned invariant and
    # the unreconstructible directions are unobserved
    assert np.allclose(C @ dec.unreconstructible, 0, atol=1e-10)
    X = dec.unreconstructible
    assert contains(dec.S_stab, A @ X, tol=1e-7)


def test_eigenvalue_clusters_resolve_distinct_eigenvalues():
    """Clusters are pseudospectral components, not a radius relative to ||M||."""
    rng = np.random.default_rng(0)
    # one large eigenvalue does not lump the small, distinct ones
    Q = np.linalg.qr(rng.standard_normal((7, 7)))[0]
    ev0 = np.array([-222.0, 1.25, -1.5, -0.75, 0.17, -0.18, -0.36])
    ev, clusters = eigenvalue_clusters(Q.T @ np.diag(ev0) @ Q)
    assert len(clusters) == 7
    _, stable, _ = classify_stable_eigenvalues(Q.T @ np.diag(ev0) @ Q)
    assert sorted(ev[~stable].real.round(8)) == [0.17, 1.25]
    # rotated Jordan blocks: each block is one cluster, neighbours (0.21 apart) are not joined
    J = sla.block_diag(*[v * np.eye(4) + np.diag(np.ones(3), 1) for v in np.linspace(-1, 1, 6)])
    Q = np.linalg.qr(rng.standard_normal(J.shape))[0]
    ev, clusters = eigenvalue_clusters(Q.T @ J @ Q)
    assert sorted(len(c) for c in clusters) == [4] * 6
    assert np.allclose(sorted(ev[c].mean().real for c in clusters), np.linspace(-1, 1, 6), atol=1e-10)
    # exactly repeated semisimple / defective eigenvalues stay together
    ev, clusters = eigenvalue_clusters(np.diag([-1.0, -1.0, 0.0, 1.0]) + np.diag([0.0, 0.0, 1.0], 1))
    assert sorted(len(c) for c in clusters) == [1, 1, 2]


def test_stability_undecidable_cluster_raises():
    """A 3-Jordan block at -1e-7 (stable) has computed eigenvalues ~5e-6 apart,
    straddling the axis: with a stable mean it is not classified (error)."""
    Q = np.linalg.qr(np.random.default_rng(1).standard_normal((3, 3)))[0]
    M = Q.T @ (-1e-7 * np.eye(3) + np.diag([1.0, 1.0], 1)) @ Q
    with pytest.raises(np.linalg.LinAlgError, match="stability"):
        classify_stable_eigenvalues(M)
    # the same block at 0 is marginal, i.e. not stable (integrator chain)
    _, stable, _ = classify_stable_eigenvalues(Q.T @ np.diag([1.0, 1.0], 1) @ Q)
    assert not np.any(stable)


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "args, name",
    [
        ((np.ones((2, 3)), np.zeros((2, 0)), np.ones((1, 2))), "A"),
        ((np.ones(2), np.zeros((2, 0)), np.ones((1, 2))), "A"),
        ((np.array([[np.nan, 0], [0, 0]]), np.zeros((2, 0)), np.ones((1, 2))), "A"),
        ((np.eye(2), np.zeros((3, 1)), np.ones((1, 2))), "B_unknown"),
        ((np.eye(2), np.array([[np.inf], [0]]), np.ones((1, 2))), "B_unknown"),
        ((np.eye(2), np.ones(2), np.ones((1, 2))), "B_unknown"),
        ((np.eye(2), np.zeros((2, 1)), np.ones((1, 3))), "C"),
        ((np.eye(2), np.zeros((2, 1)), np.ones(2)), "C"),
        ((np.eye(2), np.zeros((2, 1)), np.array([[1.0, np.nan]])), "C"),
    ],
)
def test_bad_input(args, name):
    for fn in (reconstructible_subspace, unreconstructible_directions):
        with pytest.raises(ValueError, match=name):
            fn(*args)


def test_bad_tol_and_names():
    with pytest.raises(ValueError, match="tol"):
        reconstructible_subspace(np.eye(2), None, np.eye(2), tol=-1.0)
    with pytest.raises(ValueError, match="tol"):
        reconstructible_subspace(np.eye(2), None, np.eye(2), tol=float("nan"))
    with pytest.raises(ValueError, match="C"):
        undetectable_subspace(np.eye(2), np.ones((1, 3)))
    with pytest.raises(ValueError, match="B"):
        minimal_conditioned_invariant(np.eye(2), np.ones((3, 1)), np.ones((1, 2)))
    with pytest.raises(ValueError, match="A"):
        minimal_conditioned_invariant(np.zeros((0, 0)), None, np.zeros((0, 0)))
