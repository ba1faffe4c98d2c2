"""The package's single set of matrix validators (dobs_envs.linalg.validation)."""
import numpy as np
import pytest

from dobs_envs.linalg import as_array, as_matrix, as_square, as_symmetric, check_tol


def test_as_matrix_copies_and_converts():
    a = [[1, 2], [3, 4]]
    M = as_matrix(a, "M")
    assert M.dtype == np.float64 and M.shape == (2, 2)
    src = np.eye(2)
    out = as_matrix(src, "M")
    out[0, 0] = 5.0
    assert src[0, 0] == 1.0  # a copy, the input is never modified


@pytest.mark.parametrize("bad, match", [
    (np.eye(2) * 1j, "X must be real"),
    ([["a", "b"]], "X must be a real numeric array"),
    (np.zeros(3), "X must be a 2-D array"),
    (np.zeros((2, 2, 2)), "X must be a 2-D array"),
    (np.array([[np.nan, 0.0]]), "X contains NaN or inf"),
    (np.array([[np.inf, 0.0]]), "X contains NaN or inf"),
])
def test_as_matrix_errors_name_the_argument(bad, match):
    with pytest.raises(ValueError, match=match):
        as_matrix(bad, "X")


def test_rows_cols_and_vectors():
    with pytest.raises(ValueError, match=r"B must have shape \(3, \*\) \(3 rows\)"):
        as_matrix(np.zeros((2, 1)), "B", rows=3)
    with pytest.raises(ValueError, match=r"C must have shape \(\*, 3\) \(3 columns\)"):
        as_matrix(np.zeros((1, 2)), "C", cols=3)
    assert as_matrix(np.ones(3), "b", rows=3, vector_as="col").shape == (3, 1)
    assert as_matrix(np.ones(3), "c", cols=3, vector_as="row").shape == (1, 3)
    assert as_matrix(2.0, "s", vector_as="col").shape == (1, 1)
    with pytest.raises(ValueError, match="vector_as"):
        as_matrix(np.ones(3), "b", vector_as="column")


def test_as_square():
    assert as_square(np.eye(3)).shape == (3, 3)
    assert as_square(np.zeros((0, 0))).shape == (0, 0)
    with pytest.raises(ValueError, match=r"A must be a square \(n, n\) matrix"):
        as_square(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="S must be a non-empty square"):
        as_square(np.zeros((0, 0)), "S", nonempty=True)


def test_as_symmetric():
    np.testing.assert_array_equal(as_symmetric(None, 3, "Q", definite=False), np.eye(3))
    assert as_symmetric(2.0, 1, "R", definite=True).shape == (1, 1)
    with pytest.raises(ValueError, match=r"Q must have shape \(2, 2\)"):
        as_symmetric(np.eye(3), 2, "Q", definite=False)
    with pytest.raises(ValueError, match="Q must be symmetric"):
        as_symmetric(np.array([[1.0, 1.0], [0.0, 1.0]]), 2, "Q", definite=False)
    with pytest.raises(ValueError, match="R must be symmetric positive definite"):
        as_symmetric(np.diag([1.0, 0.0]), 2, "R", definite=True)
    with pytest.raises(ValueError, match="Q must be symmetric positive semidefinite"):
        as_symmetric(np.diag([1.0, -1.0]), 2, "Q", definite=False)
    as_symmetric(np.diag([1.0, 0.0]), 2, "Q", definite=False)


def test_as_array_and_tol():
    np.testing.assert_array_equal(as_array([1, 2], "v", shape=(2,)), [1.0, 2.0])
    with pytest.raises(ValueError, match=r"v must have shape \(3,\)"):
        as_array([1, 2], "v", shape=(3,))
    with pytest.raises(ValueError, match="v must be 1-D"):
        as_array(np.eye(2), "v", ndim=1)
    assert check_tol(None) is None and check_tol(1e-9) == 1e-9
    for bad in (-1.0, 0.0, float("nan"), "x"):
        with pytest.raises(ValueError, match="tol"):
            check_tol(bad)


def test_as_numeric_refuses_bool_complex_and_strings_without_copying_numbers():
    from dobs_envs.linalg import as_numeric

    a = np.arange(3.0)
    assert as_numeric(a, "u") is a  # float arrays pass through untouched (the step path)
    assert as_numeric([1, 2], "u").dtype.kind == "i"
    for bad, dtype in [(np.ones(2, bool), "bool"), ([True], "bool"), (np.ones(2, complex), "complex128"),
                       (["a"], "str")]:
        with pytest.raises(ValueError, match=f"^u must be real numbers \\(float or integer\\), got dtype {dtype}"):
            as_numeric(bad, "u")
    with pytest.raises(ValueError, match="^u must be real numbers"):
        as_numeric([[1.0], [1.0, 2.0]], "u")  # ragged
