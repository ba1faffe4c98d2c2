"""Assumption checks: each failure raises its numbered error with the missing data."""
import numpy as np
import pytest

from dobs_envs.assumptions import (
    AssumptionError,
    CollectiveDetectabilityError,
    DetectabilityError,
    GraphNotConnectedError,
    MatchingConditionError,
    StabilizabilityError,
    UnboundedExosystemError,
    check_collective_detectability,
    check_connected,
    check_detectable,
    check_exosystem_bounded,
    check_matching,
    check_stabilizable,
    pbh_rank,
    uncontrollable_eigenvalues,
)
from dobs_envs.graphs import Graph, path_graph

import paper_ne2 as NE2  # the tests' transcription of NE2 (tests/paper_ne2.py)


def _rot(n, seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((n, n)))
    return q


def test_errors_are_value_errors_with_number():
    for cls, k in [
        (UnboundedExosystemError, 1),
        (StabilizabilityError, 3),
        (MatchingConditionError, 4),
        (GraphNotConnectedError, 5),
        (CollectiveDetectabilityError, 6),
    ]:
        assert issubclass(cls, AssumptionError) and issubclass(cls, ValueError)
        assert cls.assumption == k


# ---------------------------------------------------------------- Assumption 3
def test_stabilizable_pass_double_integrator():
    check_stabilizable([[0, 1], [0, 0]], [[0], [1]])


def test_stabilizable_allows_stable_uncontrollable_mode():
    A = np.diag([1.0, -2.0])
    B = np.array([[1.0], [0.0]])
    check_stabilizable(A, B)  # -2 uncontrollable but stable
    with pytest.raises(StabilizabilityError, match="Assumption 3 .* holds, but") as ei:
        check_stabilizable(A, B, margin=3.0)  # shifted ARE with s = 3 needs Re < -3
    assert ei.value.margin_only


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_stabilizability_failure_lists_unstable_uncontrollable(seed):
    # uncontrollable: +1 and a Jordan block at 0 (defective), controllable: +2; stable uncontrollable -3
    A0 = np.zeros((5, 5))
    A0[0, 0] = 2.0
    A0[1, 1] = 1.0
    A0[2, 3] = 1.0
    A0[4, 4] = -3.0
    B0 = np.array([[1.0], [0], [0], [0], [0]])
    T = _rot(5, seed)  # hide the structure behind an orthogonal change of basis
    A, B = T @ A0 @ T.T, T @ B0
    with pytest.raises(StabilizabilityError) as ei:
        check_stabilizable(A, B)
    e = ei.value
    assert e.assumption == 3 and not e.margin_only
    assert "Assumption 3" in str(e) and "Cao & Yin fails" in str(e)
    ev = np.sort(e.eigenvalues.real)
    np.testing.assert_allclose(ev, [0.0, 0.0, 1.0], atol=1e-6)
    assert "1" in str(e)
    np.testing.assert_allclose(
        np.sort(uncontrollable_eigenvalues(A, B).real), [-3.0, 0.0, 0.0, 1.0], atol=1e-6
    )
    # independent PBH rank test at the (simple) eigenvalues: +1, -3 lose rank, +2 does not
    assert pbh_rank(A, B, 1.0) == 4 and pbh_rank(A, B, -3.0) == 4
    assert pbh_rank(A, B, 2.0) == 5


def test_imaginary_axis_uncontrollable_mode_not_stabilizable():
    A = np.zeros((3, 3))
    A[0, 1], A[1, 0] = 1.0, -1.0  # oscillator, uncontrollable
    A[2, 2] = 1.0
    B = np.array([[0.0], [0.0], [1.0]])
    with pytest.raises(StabilizabilityError) as ei:
        check_stabilizable(A, B)
    np.testing.assert_allclose(np.sort(np.abs(ei.value.eigenvalues.imag)), [1.0, 1.0], atol=1e-10)


def test_detectable_dual():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    check_detectable(A, [[1.0, 0.0]])
    with pytest.raises(DetectabilityError, match="agent 3") as ei:
        check_detectable(A, [[0.0, 1.0]], name="agent 3")
    assert ei.value.assumption == 6


# ---------------------------------------------------------------- Assumption 4
def test_matching_pass_returns_solution():
    rng = np.random.default_rng(0)
    B = rng.standard_normal((6, 3))
    Xv_true = rng.standard_normal((3, 2))
    Xv = check_matching(B, B @ Xv_true)
    np.testing.assert_allclose(B @ Xv, B @ Xv_true, atol=1e-12)
    assert check_matching(B, np.zeros((6, 0))).shape == (3, 0)


def test_matching_ne3_holds():
    # NE3: B_v = [B^1 B^2] with B = [B^1 ... B^5]
    check_matching(np.hstack(NE2.channels()), NE2.b_v())


def test_matching_failure_reports_residual_and_directions():
    B = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0], [0.0, 0.0]])
    B_v = np.array([[1.0], [0.0], [3.0], [4.0]])
    with pytest.raises(MatchingConditionError, match="Assumption 4") as ei:
        check_matching(B, B_v)
    e = ei.value
    # residual of the best X_v is the part of B_v outside Im B: ||(0,0,3,4)|| / ||B_v||
    assert e.residual == pytest.approx(5.0 / np.sqrt(26.0), rel=1e-12)
    d = e.unmatched_directions
    assert d.shape == (4, 1)
    np.testing.assert_allclose(np.abs(d[:, 0]), [0, 0, 0.6, 0.8], atol=1e-12)
    assert f"{e.residual:.3g}" in str(e)


# ---------------------------------------------------------------- Assumption 5
def test_connected_pass_and_adjacency_input():
    assert check_connected(path_graph(4)).is_connected()
    check_connected(np.array([[0, 1.0], [1.0, 0]]))


def test_not_connected_lists_components():
    g = Graph.from_edges(6, [(0, 1), (1, 2), (3, 4)])
    with pytest.raises(GraphNotConnectedError, match="Assumption 5") as ei:
        check_connected(g)
    assert ei.value.components == [[0, 1, 2], [3, 4], [5]]
    assert "[[0, 1, 2], [3, 4], [5]]" in str(ei.value)


# ---------------------------------------------------------------- Assumption 6
def test_collective_detectability_pass():
    n = 4
    S = check_collective_detectability([np.eye(n)[:, :2], np.eye(n)[:, 1:3], np.eye(n)[:, 3:]], n)
    assert S.shape == (n, n)


def test_collective_detectability_failure_dimension_and_missing():
    n = 5
    rng = np.random.default_rng(3)
    Q = _rot(n, 4)
    # nodes see span(Q0, Q1) and span(Q1 + Q2) (redundant overlap), plus an empty node
    T1 = Q[:, :2]
    T2 = (Q[:, 1:2] + Q[:, 2:3]) / np.sqrt(2)
    T3 = np.zeros((n, 0))
    with pytest.raises(CollectiveDetectabilityError, match="Assumption 6") as ei:
        check_collective_detectability([T1, T2, T3], n)
    e = ei.value
    assert e.dimension == 3 and e.n == n
    assert "3" in str(e) and f"n = {n}" in str(e)
    M = e.missing_directions
    assert M.shape == (n, 2)
    np.testing.assert_allclose(M.T @ M, np.eye(2), atol=1e-12)
    # the missing subspace is exactly span(Q3, Q4)
    P_expected = Q[:, 3:] @ Q[:, 3:].T
    np.testing.assert_allclose(M @ M.T, P_expected, atol=1e-10)
    del rng


def test_collective_detectability_bad_shape():
    with pytest.raises(ValueError, match=r"T_d_list\[1\]"):
        check_collective_detectability([np.eye(3), np.eye(2)], 3)


# ---------------------------------------------------------------- Assumption 1
def test_exosystem_ne3_bounded():
    check_exosystem_bounded([[0.0, 0.5], [-0.5, 0.0]])
    check_exosystem_bounded(np.zeros((3, 3)))  # constant v: semisimple zero eigenvalue
    check_exosystem_bounded([[-1.0]])
    check_exosystem_bounded(np.zeros((0, 0)))


def test_exosystem_unstable():
    with pytest.raises(UnboundedExosystemError, match="Assumption 1") as ei:
        check_exosystem_bounded([[0.1, 1.0], [-1.0, 0.1]])
    np.testing.assert_allclose(ei.value.eigenvalues.real, [0.1, 0.1])


@pytest.mark.parametrize("seed", [0, 1])
def test_exosystem_jordan_block_on_axis(seed):
    T = _rot(4, seed)
    # double eigenvalue pair +-i with a nontrivial Jordan block (resonance)
    S0 = np.array(
        [[0, 1, 1, 0], [-1, 0, 0, 1], [0, 0, 0, 1], [0, 0, -1, 0]], dtype=float
    )
    with pytest.raises(UnboundedExosystemError, match="Jordan") as ei:
        check_exosystem_bounded(T @ S0 @ T.T)
    np.testing.assert_allclose(np.sort(np.abs(ei.value.eigenvalues.imag)), [1.0, 1.0], atol=1e-5)
    # the same spectrum, semisimple: bounded
    S1 = S0.copy()
    S1[0, 2] = S1[1, 3] = 0.0
    check_exosystem_bounded(T @ S1 @ T.T)


def test_checks_do_not_mutate_inputs():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    B = np.array([[0.0], [1.0]])
    A0, B0 = A.copy(), B.copy()
    check_stabilizable(A, B)
    check_matching(B, B)
    np.testing.assert_array_equal(A, A0)
    np.testing.assert_array_equal(B, B0)


def test_shape_errors():
    with pytest.raises(ValueError, match="square"):
        check_stabilizable(np.zeros((2, 3)), np.zeros((2, 1)))
    with pytest.raises(ValueError, match="rows"):
        check_stabilizable(np.zeros((2, 2)), np.zeros((3, 1)))
