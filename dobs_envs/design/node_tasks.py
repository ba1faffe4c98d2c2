"""Where the per-node Lemma 2 designs of :func:`~dobs_envs.design.observer.design_distributed_observer` run.

The ``N`` Lemma 2 problems ``(A, B_{-i}, C_i)`` of a network (eq. ``splitinput``) are
independent: ``backend="serial"`` solves them one after the other in this process,
``backend="ray"`` submits each as a Ray task (one CPU) to the Ray runtime of this process, so
that a large network's design spreads over a cluster. Both run the same function
(:func:`node_design`) on the same data with single-threaded BLAS, so the results are equal
bit for bit on machines with the same BLAS.

Ray is optional (``pip install 'dobs-envs[distributed]'``) and imported only when
``backend="ray"`` is asked for. If Ray is not initialised yet, :func:`run_node_designs` calls
``ray.init()``, which joins the cluster named by ``RAY_ADDRESS`` or a cluster started on this
machine with ``ray start``, and otherwise starts a local Ray sized to the machine; that runtime
stays up for later calls (Ray's own convention). Call ``ray.init(address=...)`` first to choose
the cluster; ``ray.shutdown()`` ends a runtime you no longer need.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from ..linalg.subspaces import IllConditionedError
from .lemma2 import StrongDetectability, strong_detectability

__all__ = ["DESIGN_BACKENDS", "node_design", "run_node_designs"]

#: where the per-node designs run
DESIGN_BACKENDS = ("serial", "ray")


def node_design(i: int, A: np.ndarray, B_minus: np.ndarray, C_i: np.ndarray, tol, poles_i) -> StrongDetectability:
    """Lemma 2 (:func:`~dobs_envs.design.lemma2.strong_detectability`) of node ``i``'s triplet
    ``(A, B_{-i}, C_i)`` with single-threaded BLAS.

    Multi-threaded BLAS only adds synchronisation on these many small dense matrices (a
    100x100 SVD measured 55 ms with 2 OpenBLAS threads on a loaded 2-core machine, 4 ms with
    one). A failure is re-raised as the same class (``IllConditionedError`` or ``ValueError``)
    with the node named.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        try:
            return strong_detectability(A, B_minus, C_i, tol=tol, poles=poles_i)
        except ValueError as exc:
            cls = IllConditionedError if isinstance(exc, IllConditionedError) else ValueError
            raise cls(f"node {i}: Lemma 2 (strong_detectability) failed: {exc}") from exc


def _ray_node_design(i, A, B_minus, C_i, tol, poles_i):
    """:func:`node_design` as a Ray task: a failure is returned (not raised) so that the caller
    re-raises the library's own error class and message, not Ray's wrapper."""
    try:
        return node_design(i, A, B_minus, C_i, tol, poles_i)
    except ValueError as exc:
        return exc


def _import_ray():
    try:
        import ray
    except ImportError:
        raise ImportError("backend='ray' needs Ray: pip install 'dobs-envs[distributed]'") from None
    return ray


def run_node_designs(
    backend: str,
    A: np.ndarray,
    B_minus: Sequence[np.ndarray],
    C: Sequence[np.ndarray],
    tol,
    poles: dict,
) -> list[StrongDetectability]:
    """The Lemma 2 results of every node, in node order.

    Parameters
    ----------
    backend : ``"serial"`` or ``"ray"`` (:data:`DESIGN_BACKENDS`).
    A : ndarray, shape (n, n)
    B_minus : sequence of N ndarrays, shape (n, q_i)
        Node ``i``'s unknown-input matrix ``B_{-i}`` (eq. ``splitinput``).
    C : sequence of N ndarrays, shape (p_i, n)
    tol : float or None
        The SVD threshold of every node's design.
    poles : mapping node -> eigenvalues
        Pinned eigenvalues of the nodes that have them (others: ``None``).

    Raises
    ------
    ValueError, IllConditionedError
        The first failing node's error (node named), whichever backend ran it.
    """
    if backend not in DESIGN_BACKENDS:
        raise ValueError(f"backend must be one of {DESIGN_BACKENDS}, got {backend!r}")
    N = len(C)
    if backend == "serial":
        return [node_design(i, A, B_minus[i], C[i], tol, poles.get(i)) for i in range(N)]
    ray = _import_ray()
    if not ray.is_initialized():
        ray.init(include_dashboard=False, log_to_driver=False)
    task = ray.remote(num_cpus=1)(_ray_node_design)
    A_ref = ray.put(A)  # sent to the object store once, shared by every task
    refs = [task.remote(i, A_ref, B_minus[i], C[i], tol, poles.get(i)) for i in range(N)]
    results = ray.get(refs)
    for r in results:
        if isinstance(r, BaseException):
            raise r
    return results
