"""Numerical studies beyond the paper's printed runs: step-size convergence, Theorem 6's residual set,
the paper's controller under communication faults."""
from .convergence import convergence_study
from .faults import faults_study
from .theorem6 import theorem6_study

__all__ = ["convergence_study", "faults_study", "theorem6_study"]
