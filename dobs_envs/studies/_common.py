"""What the studies share: running independent cells in worker processes, writing the results."""
from __future__ import annotations

import json
import os


def run_cells(fn, jobs: list[tuple], workers: int = 1) -> list:
    """``[fn(*job) for job in jobs]``, in ``workers`` spawned processes when ``workers > 1``
    (results in the order of ``jobs``; submit the longest jobs first for the best packing)."""
    if workers <= 1:
        return [fn(*job) for job in jobs]
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as ex:
        return list(ex.map(fn, *zip(*jobs)))


def write_results(res: dict, out: str | None, name: str, plot=None) -> None:
    """``out/<name>.json`` (and ``out/<name>.png`` drawn by ``plot(res, path)``); nothing when ``out`` is None."""
    if out is None:
        return
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, f"{name}.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    if plot is not None:
        plot(res, os.path.join(out, f"{name}.png"))
