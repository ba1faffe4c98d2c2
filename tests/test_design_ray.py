"""Issue 22, item 4: the per-node Lemma 2 designs of a large network as Ray tasks.

``design_distributed_observer(..., backend="ray")`` must give the serial result exactly: both
backends run :func:`dobs_envs.design.node_tasks.node_design` on the same arrays with
single-threaded BLAS on this machine, so every array of the design is compared with
``np.array_equal`` (no tolerance). A real local Ray (``ray.init(num_cpus=2)``), never a mock.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from dobs_envs.design import IllConditionedError, design_distributed_observer
from dobs_envs.graphs import random_connected_graph

ray = pytest.importorskip("ray", reason="the distributed extra (ray) is not installed")


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, object_store_memory=80 * 2**20)
    yield
    ray.shutdown()


def network(N: int, n: int, seed: int):
    """A random sparse plant with N single-column channels; node i measures 3 states and knows
    channel i; every state is measured by some node (Assumption 6)."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) * (rng.random((n, n)) < 3.0 / n)
    chans = []
    for _ in range(N):
        b = rng.standard_normal((n, 1)) * (rng.random((n, 1)) < 0.1)
        b[rng.integers(n), 0] = 1.0
        chans.append(b)
    perm = rng.permutation(n)
    C = [np.eye(n)[sorted({int(perm[(3 * i + k) % n]) for k in range(3)})] for i in range(N)]
    return A, chans, C, [[i] for i in range(N)], random_connected_graph(N, 0.1, seed)


def _arrays(design):
    """Every array of an ObserverDesign (tuples of per-node arrays flattened), by field name."""
    out = {}
    for f in dataclasses.fields(design):
        v = getattr(design, f.name)
        if isinstance(v, np.ndarray):
            out[f.name] = v
        elif isinstance(v, tuple) and v and all(isinstance(x, np.ndarray) for x in v):
            for i, x in enumerate(v):
                out[f"{f.name}[{i}]"] = x
    return out


def test_forty_node_design_on_ray_equals_serial(local_ray):
    A, chans, C, known, graph = network(40, 60, seed=3)
    serial = design_distributed_observer(A, chans, C, known, graph)
    on_ray = design_distributed_observer(A, chans, C, known, graph, backend="ray")
    a, b = _arrays(serial), _arrays(on_ray)
    assert a.keys() == b.keys() and len(a) > 5 * 40  # T_d, T_u, E, F, G per node + the stacked gains
    unequal = [k for k in a if not np.array_equal(a[k], b[k])]
    assert not unequal, f"ray design differs from the serial one in {unequal[:5]}"
    assert [r.delta for r in serial.lemma2] == [r.delta for r in on_ray.lemma2]


def test_node_failure_is_the_same_error_on_ray(local_ray):
    A, chans, C, known, graph = network(6, 12, seed=1)
    bad = {4: [1.0]}  # an unstable pole: node 4's Lemma 2 refuses it
    with pytest.raises(ValueError) as serial:
        design_distributed_observer(A, chans, C, known, graph, poles=bad)
    with pytest.raises(ValueError) as on_ray:
        design_distributed_observer(A, chans, C, known, graph, poles=bad, backend="ray")
    assert type(on_ray.value) is type(serial.value)
    assert str(on_ray.value) == str(serial.value)
    assert str(on_ray.value).startswith("node 4: Lemma 2")
    assert not isinstance(on_ray.value, IllConditionedError)


def test_unknown_backend_is_named():
    A, chans, C, known, graph = network(3, 6, seed=0)
    with pytest.raises(ValueError, match=r"backend must be one of \('serial', 'ray'\), got 'dask'"):
        design_distributed_observer(A, chans, C, known, graph, backend="dask")
