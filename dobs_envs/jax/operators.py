"""Vectors as tuples of scalars, and the system's matrix-vector products over their nonzeros.

Inside a control period the JAX simulation keeps every vector as a tuple of scalars (one per
component) and writes each product as the sum of its matrix's nonzeros, in the order of their
columns: the layout of the compiled core's kernels (:mod:`dobs_envs.sim.period_kernel`: one scalar
per component, the rows' nonzeros). Under ``jax.vmap`` every scalar becomes a vector over the copies
and every operation an element-wise one, which XLA fuses into a few loops with the copies innermost.
Written with ``einsum`` on ``(N, n)`` arrays instead, the same period ran 2.5x (float64) to 3.5x
(float32) slower at 1024 copies on one core (``benchmarks/bench_jax_envs.py``).

The nonzeros are found once, when the environment is built (:func:`patterns_of`), from the system's
matrices: they are part of the environment's static structure, and the parameters' values
(:class:`~dobs_envs.jax.params.EnvParams`) are read at those positions only. ``make(..., sparse=False)``
takes every entry instead, for parameters whose zeros differ from the default system's (for example
``jax.vmap`` over systems).
"""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

__all__ = ["OPERATORS", "patterns_of", "coefficients", "matvec", "Coefficients", "unstack", "stack"]

#: operator -> (params field, kind): "shared" ``out[o] = sum_k M[o, k] x[k]`` (M's leading axes flattened
#: into the output) or "node" ``out[i, r] = sum_k M[i, r, k] x[i, k]`` (one matrix per observer node;
#: ``x`` and ``out`` flattened node-major)
OPERATORS = {
    "C": ("C", "shared"),  # y_i = C_i x, eq. (localmeasure)
    "G": ("G_bar", "node"),  # Gbar_i y_i, eq. (hatxieq)
    "P": ("P_u", "node"),  # P_u,i d_i, eqs. (TidTiu)/(H_idefine)
    "E": ("E_bar", "node"),  # Ebar_i z_i, eq. (zidynamic)
    "F": ("F_bar", "node"),  # Fbar_i y_i, eq. (zidynamic)
    "Bbar": ("B_bar", "shared"),  # Bbar_i u (every node sees the whole u)
    "L": ("laplacian", "shared"),  # (L xhat)[., k] for each state component k
    "A": ("A", "shared"),  # eq. (LTIsys)
    "B": ("B", "shared"),
    "Bv": ("B_v", "shared"),
    "Ar": ("A_r", "shared"),  # eq. (refxdy)
    "Phi": ("Phi_v", "shared"),  # expm(S dt)
}


def patterns_of(params, *, sparse: bool = True) -> dict:
    """``{operator: terms}``: for each output entry, the ``(matrix flat index, vector flat index)`` pairs of
    the operator's nonzeros in ``params`` (every entry with ``sparse=False``), in column order (static)."""
    out = {}
    for op, (field, kind) in OPERATORS.items():
        M = np.asarray(getattr(params, field))
        nz = (M != 0) if sparse else np.ones(M.shape, dtype=bool)
        if kind == "node":
            N, R, K = M.shape
            terms = tuple(tuple((int((i * R + r) * K + k), int(i * K + k)) for k in range(K) if nz[i, r, k])
                          for i in range(N) for r in range(R))
        else:
            K = M.shape[-1]
            flat = nz.reshape(int(np.prod(M.shape[:-1])), K)
            terms = tuple(tuple((int(o * K + k), int(k)) for k in range(K) if flat[o, k])
                          for o in range(flat.shape[0]))
        out[op] = terms
    return out


class Coefficients(tuple):
    """Per output entry, the ``(coefficient, vector index)`` pairs of an operator (:func:`coefficients`)."""


def coefficients(M, terms) -> Coefficients:
    """The coefficients of the nonzeros ``terms`` (:func:`patterns_of`) read from the array ``M``: scalars
    taken once, outside the Euler loop."""
    Mf = M.reshape(-1)
    return Coefficients(tuple((Mf[mi], xi) for mi, xi in t) for t in terms)


def matvec(coef: Coefficients, x: tuple, zero) -> tuple:
    """``M x`` with ``x`` a tuple of scalars: each output the sum of its terms in column order (``zero``
    for a row without nonzeros)."""
    out = []
    for t in coef:
        acc = None
        for c, xi in t:
            term = c * x[xi]
            acc = term if acc is None else acc + term
        out.append(zero if acc is None else acc)
    return tuple(out)


def unstack(a) -> tuple:
    """The entries of an array as a tuple of scalars (row-major)."""
    a = a.reshape(-1)
    return tuple(a[k] for k in range(a.shape[0]))


def stack(t: tuple, shape, dtype):
    """The inverse of :func:`unstack`."""
    return jnp.stack(t).reshape(shape) if t else jnp.zeros(shape, dtype)
