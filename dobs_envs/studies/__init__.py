"""Numerical studies beyond the paper's printed runs: step-size convergence, Theorem 6's residual set."""
from .convergence import convergence_study
from .theorem6 import theorem6_study

__all__ = ["convergence_study", "theorem6_study"]
