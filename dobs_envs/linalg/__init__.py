"""Linear-algebra primitives and matrix validators (bottom layer: imports only numpy/scipy).

- :mod:`.subspaces`: SVD ranks with explicit tolerance, orth/null/annihilator,
  projectors, stability classification, eigenvalue clusters;
- :mod:`.validation`: the package's single set of matrix validators (errors name the argument).

Both :mod:`dobs_envs.assumptions` and :mod:`dobs_envs.design` build on this
package, which keeps the import graph acyclic.
"""
from .subspaces import *  # noqa: F401,F403
from .subspaces import __all__ as _subspaces_all
from .validation import as_array, as_flag, as_float, as_int, as_matrix, as_numeric, as_square, as_symmetric, check_seed, check_tol

__all__ = list(_subspaces_all) + ["as_array", "as_matrix", "as_numeric", "as_square", "as_symmetric", "check_tol",
                                   "as_int", "check_seed", "as_flag", "as_float"]
