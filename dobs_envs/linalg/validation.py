"""The matrix validators of the package: one place for shape/finite/real checks.

Every function copies its input to a fresh float64 array and raises
``ValueError`` whose message starts with the argument's name (``name``), so
callers report *which* argument is wrong, e.g. ``"B must have shape (9, *)
(9 rows), got shape (8, 1)"``. Inputs are never modified.
"""
from __future__ import annotations

import numpy as np

__all__ = ["as_array", "as_matrix", "as_square", "as_symmetric", "as_numeric", "check_tol", "as_int", "check_seed",
           "as_flag", "as_float", "NUMERIC_KINDS"]

#: Relative tolerance of :func:`as_symmetric`: ``max |M - M^T| <= SYM_RTOL * max(1, max |M|)``.
SYM_RTOL = 1e-10
#: Definiteness tolerances of :func:`as_symmetric`, relative to ``max(1, max |M|)``:
#: positive definite needs ``lambda_min > PD_RTOL``, semidefinite ``lambda_min >= -PSD_RTOL``.
PD_RTOL = 1e-12
PSD_RTOL = 1e-10
#: ``dtype.kind`` of the arrays :func:`as_numeric` accepts: float, signed and unsigned integer
#: (not bool, complex, strings or objects).
NUMERIC_KINDS = frozenset("fiu")


def _first_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


def _reject_nested_bools(a, name: str) -> None:
    """``[[True, 0.5]]`` becomes a float array with 1.0 in numpy: refuse booleans inside nested lists."""
    stack = [a]
    while stack:
        v = stack.pop()
        if isinstance(v, (list, tuple)):
            stack.extend(v)
        elif isinstance(v, (bool, np.bool_)):
            raise ValueError(f"{name} must be real numbers, got the boolean {v!r} (True/False are not taken as 1/0)")


def as_array(a, name: str, *, shape: tuple | None = None, ndim: int | None = None) -> np.ndarray:
    """Finite real float64 copy of ``a``.

    Parameters
    ----------
    a : array_like
    name : str
        Argument name used in error messages.
    shape : tuple of int, optional
        Required exact shape.
    ndim : int, optional
        Required number of dimensions.

    Returns
    -------
    ndarray, float64 (a copy)

    Raises
    ------
    ValueError
        Complex or boolean entries (never cast), strings or other non-numeric entries, ragged
        nesting, numbers beyond the float range, wrong ``ndim``/``shape``, or NaN/inf entries.
    """
    if isinstance(a, (list, tuple)):
        _reject_nested_bools(a, name)
    try:
        raw = np.asarray(a)
    except (TypeError, ValueError, OverflowError) as exc:  # ragged nesting, unconvertible objects
        raise ValueError(f"{name} must be a real numeric array ({_first_line(exc)})") from None
    kind = raw.dtype.kind
    if kind == "c":
        raise ValueError(f"{name} must be real, got a complex array")
    if kind == "b":
        raise ValueError(f"{name} must be real numbers, got a boolean array (True/False are not taken as 1/0)")
    if kind in "USV":
        raise ValueError(f"{name} must be a real numeric array, got {raw.dtype.name} entries such as {raw.flat[0]!r}"
                         if raw.size else f"{name} must be a real numeric array, got dtype {raw.dtype.name}")
    try:
        arr = np.array(raw, dtype=np.float64, copy=True)
    except OverflowError:
        raise ValueError(f"{name} holds a number too large for a float (|x| > 1.8e308)") from None
    except (TypeError, ValueError) as exc:  # object arrays holding complex numbers, strings, None ...
        raise ValueError(f"{name} must be a real numeric array ({_first_line(exc)})") from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {arr.shape}")
    if shape is not None and arr.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def as_matrix(M, name: str, *, rows: int | None = None, cols: int | None = None,
              vector_as: str | None = None) -> np.ndarray:
    """Finite real float64 2-D copy of ``M`` with optional row/column counts.

    Parameters
    ----------
    M : array_like
    name : str
        Argument name used in error messages.
    rows, cols : int, optional
        Required number of rows / columns.
    vector_as : {None, "col", "row"}
        Accept a 1-D vector as one column (``(k,) -> (k, 1)``) or one row
        (``(k,) -> (1, k)``), and a scalar as ``(1, 1)``; ``None`` rejects them.

    Returns
    -------
    ndarray, shape (rows, cols), float64 (a copy)

    Raises
    ------
    ValueError
        Complex or non-numeric entries, not 2-D, wrong rows/columns, NaN/inf.
    """
    if vector_as not in (None, "col", "row"):
        raise ValueError(f"vector_as must be None, 'col' or 'row', got {vector_as!r}")
    arr = as_array(M, name)
    if vector_as is not None and arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif vector_as == "col" and arr.ndim == 1:
        arr = arr.reshape(-1, 1)
    elif vector_as == "row" and arr.ndim == 1:
        arr = arr.reshape(1, -1)
    exp = f"({'*' if rows is None else rows}, {'*' if cols is None else cols})"
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array of shape {exp}, got shape {arr.shape}")
    if rows is not None and arr.shape[0] != rows:
        raise ValueError(f"{name} must have shape {exp} ({rows} rows), got shape {arr.shape}")
    if cols is not None and arr.shape[1] != cols:
        raise ValueError(f"{name} must have shape {exp} ({cols} columns), got shape {arr.shape}")
    return arr


def as_square(A, name: str = "A", *, nonempty: bool = False, vector_as: str | None = None) -> np.ndarray:
    """Finite real float64 square copy of ``A``, shape (n, n) (``n >= 1`` if ``nonempty``).

    Raises ``ValueError`` naming ``name`` (see :func:`as_matrix`).
    """
    A = as_matrix(A, name, vector_as=vector_as)
    if A.shape[0] != A.shape[1] or (nonempty and A.shape[0] == 0):
        what = "a non-empty square" if nonempty else "a square"
        raise ValueError(f"{name} must be {what} (n, n) matrix, got shape {A.shape}")
    return A


def as_symmetric(M, size: int, name: str, *, definite: bool) -> np.ndarray:
    """Symmetric positive (semi)definite ``(size, size)`` copy of ``M`` (weights Q, R, P).

    ``M = None`` gives the identity; a scalar is accepted when ``size == 1``.
    The result is symmetrised exactly (``(M + M^T) / 2``).

    Parameters
    ----------
    M : array_like or None
    size : int
    name : str
        Argument name used in error messages.
    definite : bool
        Positive definite (True) or semidefinite (False), with the relative
        tolerances :data:`PD_RTOL` / :data:`PSD_RTOL`.

    Raises
    ------
    ValueError
        Wrong shape, NaN/inf, asymmetric (beyond :data:`SYM_RTOL`), or not
        positive (semi)definite.
    """
    if M is None:
        return np.eye(size)
    M = as_array(M, name)
    if M.ndim == 0 and size == 1:
        M = M.reshape(1, 1)
    if M.shape != (size, size):
        raise ValueError(f"{name} must have shape ({size}, {size}), got {M.shape}")
    if not size:
        return M
    scale = max(1.0, float(np.abs(M).max()))
    asym = float(np.abs(M - M.T).max())
    if asym > SYM_RTOL * scale:
        raise ValueError(f"{name} must be symmetric, max |{name} - {name}^T| = {asym:.3g}")
    M = 0.5 * (M + M.T)
    ev = float(np.linalg.eigvalsh(M).min())
    if definite and ev <= PD_RTOL * scale:
        raise ValueError(f"{name} must be symmetric positive definite (min eigenvalue {ev:.3g})")
    if not definite and ev < -PSD_RTOL * scale:
        raise ValueError(f"{name} must be symmetric positive semidefinite (min eigenvalue {ev:.3g})")
    return M


def as_numeric(a, name: str) -> np.ndarray:
    """``a`` as an ndarray of real numbers (float or integer dtype), without copying an array.

    For inputs applied as they are (actions): ``bool`` would silently become 0/1 and complex
    values would lose their imaginary part in a cast to float, so both are refused. No shape
    or finiteness check (the caller does them where it knows the shape).

    Raises
    ------
    ValueError
        Naming ``name`` and the dtype found: bool, complex, string/object or ragged input.
    """
    try:
        arr = np.asarray(a)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be real numbers (float or integer), got {a!r}") from None
    if arr.dtype.kind not in NUMERIC_KINDS:
        raise ValueError(f"{name} must be real numbers (float or integer), got dtype {arr.dtype.name}")
    return arr


def check_tol(tol, name: str = "tol") -> float | None:
    """``None`` or a positive finite float (an absolute SVD threshold)."""
    if tol is None:
        return None
    if isinstance(tol, (bool, np.bool_)) or not isinstance(tol, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be None or a positive finite float, got {tol!r}")
    try:
        t = float(tol)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be None or a positive finite float, got {tol!r}") from None
    if not np.isfinite(t) or t <= 0:
        raise ValueError(f"{name} must be None or a positive finite float, got {tol!r}")
    return t


def as_int(value, name: str, *, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as a Python ``int`` (sizes, node/channel indices, counts).

    Accepted: ``int``, numpy integers, and floats with an integral value (``3.0``, as YAML/JSON
    may give). Refused with a ``ValueError`` naming ``name``: ``bool`` (``True`` is not the
    index 1), fractional or non-finite floats (never truncated), complex numbers, strings and
    anything else; values outside ``[minimum, maximum]``.
    """
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be an integer, got the boolean {value!r}")
    if isinstance(value, (int, np.integer)):
        v = int(value)
    elif isinstance(value, (float, np.floating)):
        if not np.isfinite(value):
            raise ValueError(f"{name} must be an integer, got {value!r}")
        if float(value) != int(value):
            raise ValueError(f"{name} must be an integer, got {value!r} (fractional values are not truncated)")
        v = int(value)
    else:
        raise ValueError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    if minimum is not None and v < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {v}")
    if maximum is not None and v > maximum:
        raise ValueError(f"{name} must be an integer <= {maximum}, got {v}")
    return v


def check_seed(seed, name: str = "seed") -> int | None:
    """``None`` or a non-negative integer seed (``numpy.random.default_rng``'s domain): ``int`` or a numpy
    integer; ``bool`` and floats (even ``1.0``, as Gymnasium's own seeding) are refused with a
    ``ValueError`` naming ``name``."""
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"{name} must be None or a non-negative integer, got {type(seed).__name__} {seed!r}")
    if seed < 0:
        raise ValueError(f"{name} must be None or a non-negative integer, got {seed!r}")
    return int(seed)


def as_flag(value, name: str) -> bool:
    """``True`` or ``False`` (also numpy's bool): an option that is a switch. Anything else (``"no"``,
    ``0``, ``None``) is refused with a ``ValueError`` naming ``name``, not cast by truthiness."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def as_float(value, name: str, *, minimum: float | None = None, positive: bool = False, allow_inf: bool = False,
             maximum: float | None = None) -> float:
    """``value`` as a real ``float`` (a scalar parameter: margin, shift, gain, step).

    Refused with a ``ValueError`` naming ``name`` and what was expected: ``bool``, complex numbers,
    strings, ``None``, containers, NaN, infinities (unless ``allow_inf``), integers beyond the float
    range, values below ``minimum`` / not ``> 0`` with ``positive`` / above ``maximum``.
    """
    want = ("a positive" if positive else "a") + (" number" if allow_inf else " finite number")
    if minimum is not None:
        want += f" >= {minimum:g}"
    if maximum is not None:
        want += f" <= {maximum:g}"
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in NUMERIC_KINDS:
        value = value.item()  # a 0-d array of a real number
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be {want}, got {type(value).__name__} {value!r}")
    try:
        v = float(value)
    except OverflowError:
        raise ValueError(f"{name} must be {want}, got a number too large for a float (|x| > 1.8e308)") from None
    if np.isnan(v) or (np.isinf(v) and not allow_inf) or (positive and v <= 0) \
            or (minimum is not None and v < minimum) or (maximum is not None and v > maximum):
        raise ValueError(f"{name} must be {want}, got {value!r}")
    return v
