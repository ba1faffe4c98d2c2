"""Time :func:`design_distributed_observer` on a random large system, and single-node
:func:`strong_detectability` against the implementation before issue 12.

Usage: python benchmarks/bench_design.py [--nodes 50] [--states 100] [--seed 0] [--repeats 3]
                                         [--blas-threads 1|auto] [--profile]
       python benchmarks/bench_design.py --single-node [--sizes 100 200 300] [--outputs 3]
                                         [--unknown 2] [--repeats 1] [--skip-reference]
       python benchmarks/bench_design.py --nontrivial [--nodes 8] [--states 100]

``--single-node``: one node of a random plant (``single_node_system``) of each size,
designed by the current :func:`strong_detectability` and by the frozen copy of the
implementation before issue 12 (``tests/_lemma2_prerewrite_snapshot.py``: ``_unobservable_subspace``
recomputes a full SVD at each of up to r + 1 steps, O(n^4)) on the same data in the same
run, alternating the two so that load on a shared machine hits both alike. Prints both
times, their ratio and whether the results agree (delta, subspace, E_bar = T_d E T_d^T).

``--nontrivial``: a network whose nodes all have delta_i > p_i (the step-7 branch with an
observer E_i != 0), unlike the default network where most nodes have E_i = 0.

System: random sparse ``A (n, n)`` (about 3 nonzeros per row), ``N`` single-column
input channels (random sparse columns), node ``i`` measures 3 distinct states
and knows only its own channel ``i``, random connected O-O graph. Prints the
best wall time over ``--repeats`` runs (seconds) and, with ``--profile``, the
top cumulative-time entries of cProfile. Goal: < 2 s for N = 50, n = 100.

BLAS threads: the design works on many small (n = 100) dense matrices, where
multi-threaded OpenBLAS only adds synchronisation. On a loaded 2-core machine
the threaded SVD of a 100x100 matrix was measured at ~55 ms instead of ~3-4 ms
single-threaded (the design then takes ~23 s instead of ~0.7 s). The script
therefore pins BLAS to one thread by default (``--blas-threads 1``, set through
the environment before numpy is imported); ``--blas-threads auto`` keeps the
environment's setting to measure the default behaviour.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import time


def _configure_blas(argv) -> str:
    """Apply ``--blas-threads`` before numpy is imported (env vars are read at load)."""
    val = "1"
    argv = list(sys.argv[1:] if argv is None else argv)
    for k, a in enumerate(argv):
        if a == "--blas-threads" and k + 1 < len(argv):
            val = argv[k + 1]
        elif a.startswith("--blas-threads="):
            val = a.split("=", 1)[1]
    if val != "auto":
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = val
    return val


_BLAS = _configure_blas(None) if __name__ == "__main__" else "auto"

import numpy as np  # noqa: E402
from scipy.linalg import block_diag  # noqa: E402

from dobs_envs.assumptions import CollectiveDetectabilityError  # noqa: E402
from dobs_envs.design import design_distributed_observer  # noqa: E402
from dobs_envs.design.lemma2 import lemma2_residuals, strong_detectability  # noqa: E402
from dobs_envs.graphs import random_connected_graph  # noqa: E402
from dobs_envs.scenarios.random import _haar_orthogonal, random_spectrum  # noqa: E402

_TESTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests")


def _reference():
    """The frozen pre-issue-12 strong_detectability (tests/_lemma2_prerewrite_snapshot.py)."""
    if _TESTS not in sys.path:
        sys.path.insert(0, _TESTS)
    import _lemma2_prerewrite_snapshot

    return _lemma2_prerewrite_snapshot.strong_detectability


def single_node_system(n: int, p: int = 3, m: int = 2, seed: int = 0):
    """One observer node of a random plant with ``delta > p`` (non-trivial step 7).

    ``A = Q M Q^T`` (Haar ``Q``): ``M`` block upper triangular with the modes of
    :func:`~dobs_envs.scenarios.random.random_spectrum` drawn in ``Re in [-2, -0.5]``
    plus one integrator and one unstable mode at 0.3 (they need the injection J_2),
    coupling ``N(0, 0.25 / n)`` above the diagonal. ``m`` Gaussian unknown-input
    columns, ``C`` selects ``p`` states. Few outputs and a dense ``A`` give a long
    observability staircase (about n / p steps): the O(n^4) case of issue 12.
    """
    rng = np.random.default_rng(seed)
    modes = random_spectrum(rng, n, real_range=(-2.0, -0.5), p_zero=0.0)
    modes[0] = (0.0, modes[0][1])
    modes[1] = (0.3, modes[1][1])
    blocks = [np.array([[a]]) if b == 0 else np.array([[a, b], [-b, a]]) for a, b in modes]
    M = block_diag(*blocks)
    upper = np.triu(np.ones((n, n)), 1)
    start = 0
    for blk in blocks:
        w = blk.shape[0]
        upper[start:start + w, start:start + w] = 0.0
        start += w
    M = M + upper * rng.normal(0.0, 0.5 / np.sqrt(n), (n, n))
    Q = _haar_orthogonal(rng, n)
    A = Q @ M @ Q.T
    B = rng.standard_normal((n, m))
    C = np.eye(n)[np.sort(rng.choice(n, size=p, replace=False))]
    return A, B, C


def nontrivial_network(N: int, n: int, seed: int):
    """A network in which every node has ``delta_i > p_i``: the plant of
    :func:`single_node_system`, ``N`` single-column channels, node ``i`` measures 3
    states and knows its own channel and every other but one (so ``B_{-i}`` has one
    column and each node reconstructs more than it measures)."""
    A, _, _ = single_node_system(n, seed=seed)
    rng = np.random.default_rng(seed + 1)
    chans = [rng.standard_normal((n, 1)) for _ in range(N)]
    perm = rng.permutation(n)
    C = [np.eye(n)[sorted({int(perm[(3 * i + k) % n]) for k in range(3)})] for i in range(N)]
    known = [[k for k in range(N) if k != (i + 1) % N] for i in range(N)]
    graph = random_connected_graph(N, 0.3, seed)
    return A, chans, C, known, graph


def _agree(r_new, r_old) -> tuple[bool, float, float]:
    """Same delta and subspace (projector distance); and the spread of the spectra of
    E (a free choice through J_2: equal in exact arithmetic, but the shifted ARE of a
    large pair observed through few outputs is ill-conditioned, so the two round-offs
    may give visibly different, equally valid E)."""
    if r_new.delta != r_old.delta:
        return False, float("inf"), float("inf")
    dP = float(np.abs(r_new.T_d @ r_new.T_d.T - r_old.T_d @ r_old.T_d.T).max())
    e1 = np.sort_complex(np.linalg.eigvals(r_new.E))
    e0 = np.sort_complex(np.linalg.eigvals(r_old.E))
    dE = float(np.abs(e1 - e0).max() / max(1.0, np.abs(e0).max())) if e0.size else 0.0
    return dP <= 1e-6, dP, dE


def bench_single_node(sizes, p, m, seed, repeats, with_reference=True):
    ref = _reference() if with_reference else None
    print(f"single-node strong_detectability (p = {p} outputs, m = {m} unknown inputs, "
          f"BLAS threads {_BLAS}; best of {repeats}; reference = before issue 12)")
    rows = []
    for n in sizes:
        A, B, C = single_node_system(n, p, m, seed)
        t_new, t_old = np.inf, np.inf
        r_new = r_old = None
        for _ in range(repeats):  # alternate, so that machine load hits both alike
            t0 = time.perf_counter()
            r_new = strong_detectability(A, B, C)
            t_new = min(t_new, time.perf_counter() - t0)
            if ref is not None:
                t0 = time.perf_counter()
                r_old = ref(A, B, C)
                t_old = min(t_old, time.perf_counter() - t0)
        line = f"  n = {n:4d}: delta = {r_new.delta:4d} (p = {p}), new {t_new:8.3f} s"
        if ref is not None:
            ok, dP, dE = _agree(r_new, r_old)
            r_ok = max(lemma2_residuals(A, B, C, r_new) + lemma2_residuals(A, B, C, r_old)) <= 1e-9
            line += (f", before {t_old:8.3f} s, ratio {t_old / t_new:6.1f}x; same delta and "
                     f"subspace: {ok} (|dP_d| = {dP:.1e}), both valid: {r_ok}, "
                     f"rel. spread of eig(E): {dE:.1e}")
        print(line, flush=True)
        rows.append((n, t_new, t_old))
    return rows


def bench_nontrivial(N, n, seed, repeats):
    A, chans, C, known, graph = nontrivial_network(N, n, seed)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        d = design_distributed_observer(A, chans, C, known, graph)
        best = min(best, time.perf_counter() - t0)
    print(f"design_distributed_observer, every node delta_i > p_i: N={N} nodes, n={n} states, "
          f"delta_i in [{d.delta.min()}, {d.delta.max()}], p_i = 3, max |eig(E_i)| real part "
          f"{max(np.linalg.eigvals(E).real.max() for E in d.E):.3f}: {best:.3f} s (best of {repeats})")


def random_system(N: int, n: int, seed: int):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) * (rng.random((n, n)) < 3.0 / n)
    chans = []
    for _ in range(N):
        b = rng.standard_normal((n, 1)) * (rng.random((n, 1)) < 0.1)
        b[rng.integers(n), 0] = 1.0  # never an all-zero column
        chans.append(b)
    # cover every state by at least one measurement so that Assumption 6 holds
    perm = rng.permutation(n)
    C = []
    for i in range(N):
        idx = {int(perm[(3 * i + k) % n]) for k in range(3)}
        C.append(np.eye(n)[sorted(idx)])
    known = [[i] for i in range(N)]
    graph = random_connected_graph(N, 0.1, seed)
    return A, chans, C, known, graph


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--nodes", type=int, default=50)
    ap.add_argument("--states", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--blas-threads", default="1", help="BLAS threads (int) or 'auto' (environment)")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--single-node", action="store_true", help="time one node, before and after")
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 200, 300])
    ap.add_argument("--outputs", type=int, default=3)
    ap.add_argument("--unknown", type=int, default=2)
    ap.add_argument("--skip-reference", action="store_true")
    ap.add_argument("--nontrivial", action="store_true", help="network with delta_i > p_i at every node")
    args = ap.parse_args(argv)
    if args.single_node:
        bench_single_node(args.sizes, args.outputs, args.unknown, args.seed, args.repeats,
                          with_reference=not args.skip_reference)
        return 0
    if args.nontrivial:
        bench_nontrivial(args.nodes, args.states, args.seed, args.repeats)
        return 0
    A, chans, C, known, graph = random_system(args.nodes, args.states, args.seed)

    def run():
        return design_distributed_observer(A, chans, C, known, graph)

    try:
        d = run()
    except CollectiveDetectabilityError as exc:  # pragma: no cover - depends on seed
        print(f"seed {args.seed}: {exc}")
        return 1
    best = np.inf
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t0)
    print(
        f"design_distributed_observer: N={args.nodes} nodes, n={args.states} states, "
        f"m={d.n_inputs} inputs, delta_i in [{d.delta.min()}, {d.delta.max()}] "
        f"(mean {d.delta.mean():.1f}), BLAS threads {_BLAS}: {best:.3f} s "
        f"(best of {args.repeats}; goal < 2 s)"
    )
    if args.profile:
        pr = cProfile.Profile()
        pr.enable()
        run()
        pr.disable()
        pstats.Stats(pr).sort_stats("cumulative").print_stats(20)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
