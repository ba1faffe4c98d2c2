"""Pinning the assignable eigenvalues of E_i (design option ``poles``; issue 10, item 4).

The paper leaves E_i free beyond Hurwitz; by default the project takes the shifted ARE of
Appendix step 7. With ``poles`` the observable part of the step-6 pair gets exactly those
eigenvalues (pole placement), the fixed unobservable modes keep theirs, and the defining
equations of Lemma 2 still hold (the design's own self-check, and lemma2_residuals here).
Tolerances: place_poles on these 2-3 dimensional, well-conditioned pairs returns eigenvalues
accurate to ~1e-13; 1e-8 leaves room for the back-transformation of the scaling.
"""
import numpy as np
import pytest

from dobs_envs.design.lemma2 import lemma2_residuals, strong_detectability
from dobs_envs.design.observer import design_distributed_observer
from dobs_envs.scenarios.paper import ne2


@pytest.fixture(scope="module")
def sc():
    return ne2()


def _node_data(sc, i):
    known = set(sc.known[i])
    unknown = [b for k, b in enumerate(sc.channels) if k not in known]
    B_minus = np.hstack(unknown) if unknown else np.zeros((sc.A.shape[0], 0))
    return sc.A, B_minus, np.atleast_2d(sc.C[i])


def _design(sc, poles=None):
    return design_distributed_observer(sc.A, sc.channels, sc.C, sc.known, sc.graph, poles=poles)


@pytest.mark.parametrize("node, poles", [(2, [-2 + 1j, -2 - 1j]), (3, [-1.0, -2.0, -3.0]), (3, [-5.0, -0.5 + 2j, -0.5 - 2j])])
def test_pinned_eigenvalues_are_exact_and_the_subspace_unchanged(sc, node, poles):
    d0, d = _design(sc), _design(sc, {node: poles})
    ev = np.sort_complex(np.linalg.eigvals(d.lemma2[node].E))
    np.testing.assert_allclose(ev, np.sort_complex(np.asarray(poles, dtype=complex)), atol=1e-8)
    P0, P1 = (x.lemma2[node].T_d @ x.lemma2[node].T_d.T for x in (d0, d))
    np.testing.assert_allclose(P1, P0, atol=1e-10)  # the same maximal subspace Im T_id
    r = strong_detectability(*_node_data(sc, node), poles=poles)
    assert max(lemma2_residuals(*_node_data(sc, node), r)) < 1e-10
    for i in set(range(len(sc.C))) - {node}:  # the other nodes keep the default E_i
        np.testing.assert_array_equal(d.lemma2[i].E, d0.lemma2[i].E)


def test_fixed_modes_keep_their_values(sc):
    """NE2 node 1: one assignable mode, two fixed unobservable ones (-0.707 +- 0.707j)."""
    ev0 = np.linalg.eigvals(_design(sc).lemma2[1].E)
    fixed = ev0[np.abs(ev0.imag) > 0.1]
    ev = np.linalg.eigvals(_design(sc, {1: [-4.0]}).lemma2[1].E)
    np.testing.assert_allclose(np.sort_complex(ev), np.sort_complex(np.r_[fixed, -4.0]), atol=1e-8)


@pytest.mark.parametrize("poles, match", [
    ({1: [-3.0, -4.0, -5.0]}, "node 1: .*1 assignable eigenvalue.*2 fixed unobservable.*got 3"),
    ({0: [-1.0]}, "node 0: .*E = 0 branch.*no assignable eigenvalues"),
    ({2: [1.0, -2.0]}, "negative real parts"),
    ({2: [-1 + 1j, -2.0]}, "complex-conjugate pairs"),
    ({2: ["a", "b"]}, "poles must be an array of numbers"),
    ({9: [-1.0]}, r"keys must be node indices 0\.\.5"),
])
def test_bad_poles_are_named(sc, poles, match):
    with pytest.raises(ValueError, match=match):
        _design(sc, poles)
