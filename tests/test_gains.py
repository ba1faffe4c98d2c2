"""NE1/NE2/NE3 gains satisfy their equations."""
import numpy as np
import pytest
import scipy.linalg as sla

from dobs_envs.assumptions import DetectabilityError, StabilizabilityError
from dobs_envs.design.gains import (
    lyapunov_P,
    observer_are_gain,
    shifted_are_feedback,
    sliding_mode_P,
    split_gain,
    stabilising_are,
)

import paper_ne2 as NE2  # the tests' transcription of NE2 (tests/paper_ne2.py)


def ne2_system():
    return NE2.A(), NE2.channels()


def _are_residual(A, B, X, shift, Q, Rinv):
    As = A + shift * np.eye(A.shape[0])
    return As.T @ X + X @ As - X @ B @ Rinv @ B.T @ X + Q


def test_ne2_shifted_are_and_channel_gains():
    A, chans = ne2_system()
    B = np.hstack(chans)
    X, K = shifted_are_feedback(A, B, shift=0.2)
    n = 9
    res = _are_residual(A, B, X, 0.2, np.eye(n), np.eye(5))
    # ARE residual relative to the size of its terms; round-off of a 9x9 Schur solve
    assert np.linalg.norm(res) <= 1e-9 * max(1.0, np.linalg.norm(X) ** 2)
    np.testing.assert_allclose(X, X.T, atol=0)
    assert np.linalg.eigvalsh(X).min() > 0
    ev = np.linalg.eigvals(A + B @ K)
    assert ev.real.max() < -0.2  # closed loop decays faster than e^{-0.2 t}
    slices = [slice(k, k + 1) for k in range(5)]
    for k, Kk in enumerate(split_gain(K, slices)):
        np.testing.assert_allclose(Kk, -chans[k].T @ X, atol=1e-12)  # K^k = -(B^k)^T X


def test_shifted_are_with_weights():
    rng = np.random.default_rng(1)
    n, m = 6, 2
    A = rng.standard_normal((n, n))
    B = rng.standard_normal((n, m))
    Q = np.diag(rng.uniform(0.5, 2.0, n))
    R = np.array([[2.0, 0.3], [0.3, 1.0]])
    X, K = shifted_are_feedback(A, B, shift=0.5, Q=Q, R=R)
    res = _are_residual(A, B, X, 0.5, Q, np.linalg.inv(R))  # inv only in the test oracle
    assert np.linalg.norm(res) <= 1e-8 * max(1.0, np.linalg.norm(X) ** 2)
    np.testing.assert_allclose(R @ K, -B.T @ X, atol=1e-10)
    assert np.linalg.eigvals(A + B @ K).real.max() < -0.5


def test_shifted_are_not_stabilizable():
    A = np.diag([1.0, 2.0])
    B = np.array([[1.0], [0.0]])
    with pytest.raises(StabilizabilityError, match="Assumption 3"):
        shifted_are_feedback(A, B)
    # stable uncontrollable mode at -0.1 is too slow for the 0.2 margin
    with pytest.raises(StabilizabilityError, match="holds, but the stronger") as ei:
        shifted_are_feedback(np.diag([1.0, -0.1]), B, shift=0.2)
    assert ei.value.margin_only and "-0.2" in str(ei.value)
    shifted_are_feedback(np.diag([1.0, -0.1]), B, shift=0.05)


def test_shifted_are_bad_weights():
    A, B = np.zeros((2, 2)), np.eye(2)
    with pytest.raises(ValueError, match="R must be symmetric positive definite"):
        shifted_are_feedback(A, B, R=np.diag([1.0, 0.0]))
    with pytest.raises(ValueError, match="Q must have shape"):
        shifted_are_feedback(A, B, Q=np.eye(3))
    with pytest.raises(ValueError, match="shift"):
        shifted_are_feedback(A, B, shift=-1.0)


def test_ne3_lyapunov_P():
    A, chans = ne2_system()
    B = np.hstack(chans)
    _, K = shifted_are_feedback(A, B)
    A_cl = A + B @ K
    P = lyapunov_P(A_cl)
    res = A_cl.T @ P + P @ A_cl + np.eye(9)
    assert np.linalg.norm(res) <= 1e-10 * max(1.0, np.linalg.norm(P) * np.linalg.norm(A_cl))
    np.testing.assert_allclose(P, P.T, atol=0)
    assert np.linalg.eigvalsh(P).min() > 0


def test_sliding_mode_P_is_lyapunov_P_of_the_closed_loop():
    """NE3: P of eq. (centralsliding) solves (A + BK)^T P + P (A + BK) = -Q; the same array as lyapunov_P(A + B K)."""
    A, chans = ne2_system()
    B = np.hstack(chans)
    _, K = shifted_are_feedback(A, B)
    P = sliding_mode_P(A, B, K)
    np.testing.assert_array_equal(P, lyapunov_P(A + B @ K))  # one formula: bit for bit
    Q = np.diag(np.arange(1.0, 10.0))
    P2 = sliding_mode_P(A, B, K, Q=Q)
    A_cl = A + B @ K
    res = A_cl.T @ P2 + P2 @ A_cl + Q
    assert np.linalg.norm(res) <= 1e-10 * max(1.0, np.linalg.norm(P2) * np.linalg.norm(A_cl))


def test_sliding_mode_P_names_bad_arguments():
    A, chans = ne2_system()
    B = np.hstack(chans)
    with pytest.raises(ValueError, match=r"^K must have shape \(5, 9\)"):
        sliding_mode_P(A, B, np.zeros((9, 5)))
    with pytest.raises(ValueError, match=r"^B must have shape \(9, \*\)"):
        sliding_mode_P(A, B[:4], np.zeros((5, 9)))
    with pytest.raises(ValueError, match="not Hurwitz"):  # K = 0 leaves NE2's integrators
        sliding_mode_P(A, B, np.zeros((5, 9)))


def test_stabilising_are_solves_and_symmetrises():
    """The one ARE solve: A^T X + X A - X B R^-1 B^T X + Q = 0, X exactly symmetric; the gains use it."""
    rng = np.random.default_rng(3)
    A, B = rng.standard_normal((5, 5)), rng.standard_normal((5, 2))
    Q, R = np.eye(5), np.array([[2.0, 0.5], [0.5, 1.0]])
    X = stabilising_are(A, B, Q, R)
    np.testing.assert_array_equal(X, X.T)
    res = A.T @ X + X @ A - X @ B @ np.linalg.solve(R, B.T @ X) + Q
    assert np.linalg.norm(res) <= 1e-9 * max(1.0, np.linalg.norm(X) ** 2)
    X2, _ = shifted_are_feedback(A, B, shift=0.0, Q=Q, R=R)
    np.testing.assert_array_equal(X2, X)


def test_stabilising_are_errors_name_the_equation():
    with pytest.raises(ValueError, match=r"^my ARE has no stabilising solution \(hint\): "):
        stabilising_are(np.eye(1), np.zeros((1, 1)), np.eye(1), np.eye(1), what="my ARE", hint=" (hint)")
    with pytest.raises(ValueError, match=r"^the ARE has no stabilising solution: .*symmetric"):
        stabilising_are(np.eye(2), np.eye(2), np.array([[1.0, 1.0], [0.0, 1.0]]), np.eye(2))
    with pytest.raises(ValueError, match=r"^R must have shape \(2, 2\)"):
        stabilising_are(np.eye(2), np.eye(2), np.eye(2), np.eye(3))


def test_lyapunov_rejects_non_hurwitz():
    with pytest.raises(ValueError, match="not Hurwitz"):
        lyapunov_P(np.array([[0.0, 1.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="not Hurwitz"):
        lyapunov_P(np.array([[0.1]]))


MAS_AGENTS = [
    (np.zeros((1, 1)), np.ones((1, 1))),
    (np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[1.0, 0.0]])),
    (np.diag([1.0, 1.0], 1), np.array([[1.0, 0.0, 0.0]])),
]


@pytest.mark.parametrize("A,C", MAS_AGENTS)
def test_ne1_observer_are(A, C):
    n = A.shape[0]
    L = observer_are_gain(A, C, shift=0.2)
    assert L.shape == (n, C.shape[0])
    ev = np.linalg.eigvals(A + L @ C)
    assert ev.real.max() < -0.2
    # residual of (A + sI) X + X (A + sI)^T - X C^T C X + I = 0 with X re-solved by scipy
    As = A + 0.2 * np.eye(n)
    X = sla.solve_continuous_are(As.T, C.T, np.eye(n), np.eye(C.shape[0]))
    res = As @ X + X @ As.T - X @ C.T @ C @ X + np.eye(n)
    assert np.linalg.norm(res) <= 1e-9 * max(1.0, np.linalg.norm(X) ** 2)
    np.testing.assert_allclose(L, -X @ C.T, atol=1e-10)


def test_ne1_scalar_closed_form():
    # A = 0, C = 1: 0.4 X - X^2 + 1 = 0 -> X = 0.2 + sqrt(1.04)
    L = observer_are_gain(np.zeros((1, 1)), np.ones((1, 1)))
    assert L[0, 0] == pytest.approx(-(0.2 + np.sqrt(1.04)), rel=1e-12)


def test_observer_are_not_detectable():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    with pytest.raises(DetectabilityError, match="agent 2"):
        observer_are_gain(A, np.array([[0.0, 1.0]]), name="agent 2")
