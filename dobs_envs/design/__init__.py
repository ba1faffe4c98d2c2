"""The paper's design layer (Lemma 2, observer gains, controller gains).

Public API
----------
- :func:`strong_detectability`, :class:`StrongDetectability` -- Lemma 2 (FUIO), Appendix algorithm.
- :func:`reconstructible_subspace` -- independent geometric characterisation of ``Im T_id``.
- :func:`shifted_are_feedback` (NE2), :func:`lyapunov_P` / :func:`sliding_mode_P` (NE3),
  :func:`observer_are_gain` (NE1), :func:`stabilising_are` (the ARE solve behind them).
- :class:`ObserverDesign`, :func:`design_distributed_observer` (eq. barEFGB/TidTiu),
  :func:`design_mas_observer` (eq. obidynamicMAS), :func:`observer_residuals`.
- :class:`IllConditionedError` -- a ``ValueError``: the data are too badly scaled or too close
  to a rank/stability boundary for a reliable design in double precision (message says why).
"""
from .gains import lyapunov_P, observer_are_gain, shifted_are_feedback, sliding_mode_P, split_gain, stabilising_are
from .geometric import reconstructible_subspace
from ..linalg.subspaces import IllConditionedError
from .lemma2 import StrongDetectability, strong_detectability
from .observer import (
    ObserverDesign,
    design_distributed_observer,
    design_mas_observer,
    observer_residuals,
)

__all__ = [
    "IllConditionedError",
    "StrongDetectability",
    "strong_detectability",
    "reconstructible_subspace",
    "shifted_are_feedback",
    "lyapunov_P",
    "sliding_mode_P",
    "stabilising_are",
    "observer_are_gain",
    "split_gain",
    "ObserverDesign",
    "design_distributed_observer",
    "design_mas_observer",
    "observer_residuals",
]
