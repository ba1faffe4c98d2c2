"""Execution backends: run a list of :class:`Job` s and yield their results as they finish.

=========  =========================================================================================
backend    where the jobs run
=========  =========================================================================================
serial     one after another in this process
process    a pool of spawned worker processes on this machine (the default; ``workers``: one per
           CPU core, at most 8; one worker or one job: in this process)
ray        Ray tasks (``pip install 'dobs-envs[distributed]'``): without ``address`` a local Ray
           started for the benchmark, sized to the machine (``workers`` CPUs if given) and shut
           down after it; with ``address`` (``"auto"``, ``"host:port"``, ``"ray://..."``) the
           existing cluster it names (left running); in a process where Ray is already
           initialised, that session as it is
=========  =========================================================================================

A job is a module-level function and its arguments (pickled by reference: every machine that runs
jobs must have this package installed) and the CPUs it takes (a Ray task's ``num_cpus``; the
benchmark sets the worker's torch threads to match). Jobs return plain data; nothing assumes a file
system shared between the driver and the workers (:mod:`agents.benchmark.tasks`, :mod:`agents.benchmark.store`).

A backend is a context manager. Leaving it on an exception (Ctrl-C included) cancels the queued jobs
and ends the running ones: no worker outlives the benchmark, and a local Ray started for it is shut
down. The results yielded before are the caller's to keep.
"""
from __future__ import annotations

import abc
import logging
import multiprocessing
import os
import signal
import shutil
import tempfile
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator

__all__ = ["BACKENDS", "Job", "Backend", "SerialBackend", "ProcessBackend", "RayBackend", "make_backend",
           "check_address", "default_workers"]

BACKENDS = ("serial", "process", "ray")
#: the install hint of the ray backend's missing dependency
RAY_EXTRA = "pip install 'dobs-envs[distributed]'"


@dataclass(frozen=True)
class Job:
    """One unit of work: ``fn(*args)``; ``key`` identifies it to the caller, ``cpus`` is its CPU count."""

    key: tuple
    fn: Callable
    args: tuple = ()
    cpus: int = 1
    kw: dict = field(default_factory=dict)


def default_workers() -> int:
    """One worker per CPU core, at most 8 (the process pool's default)."""
    return min(os.cpu_count() or 1, 8)


class Backend(abc.ABC):
    """Base class: ``with backend: for job, result in backend.run(jobs): ...``."""

    name = "?"
    #: the directory a job makes its scratch directory in (``None``: the worker's temporary directory)
    scratch: str | None = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        return False

    def parallel(self, n_jobs: int) -> bool:
        """Whether ``n_jobs`` jobs run in other processes (the caller then prepares what they share)."""
        return False

    def describe(self) -> str:
        return self.name

    @abc.abstractmethod
    def run(self, jobs: list[Job]) -> Iterator[tuple[Job, Any]]:
        """Run ``jobs``; yield ``(job, its return value)`` as each finishes (any order)."""


class _LocalScratch(Backend):
    """A backend on this machine: the jobs' scratch directories go in one temporary directory made
    on entry and removed on exit (also after Ctrl-C, once the workers have ended)."""

    def __enter__(self):
        self.scratch = tempfile.mkdtemp(prefix="dobs-envs-bench-")
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if self.scratch is not None:
            shutil.rmtree(self.scratch, ignore_errors=True)
            self.scratch = None
        return False


class SerialBackend(_LocalScratch):
    """The jobs one after another in this process."""

    name = "serial"

    def run(self, jobs):
        for job in jobs:
            yield job, job.fn(*job.args, **job.kw)


def _ignore_sigint() -> None:
    """Worker initializer: Ctrl-C reaches the whole process group; the main process alone handles it
    (and terminates the workers), so workers print no tracebacks and start no new job."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _terminate_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel the queued jobs and end the running ones (their runs have no result.json, so the next
    invocation trains them again; finished runs are kept)."""
    pool.shutdown(wait=False, cancel_futures=True)
    terminate = getattr(pool, "terminate_workers", None)  # Python >= 3.14
    procs = list((getattr(pool, "_processes", None) or {}).values())
    if terminate is not None:
        terminate()
    else:
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
    for proc in procs:
        proc.join(timeout=10)


class ProcessBackend(_LocalScratch):
    """A pool of ``workers`` spawned processes on this machine (default :func:`default_workers`);
    with one worker, or a single job, the job runs in this process."""

    name = "process"

    def __init__(self, workers: int | None = None):
        self.workers = int(workers or default_workers())
        self._pool: ProcessPoolExecutor | None = None

    def parallel(self, n_jobs: int) -> bool:
        return self.workers > 1 and n_jobs > 1

    def describe(self) -> str:
        return f"{self.workers} worker{'s' if self.workers != 1 else ''}"

    def run(self, jobs):
        if not self.parallel(len(jobs)):
            yield from SerialBackend.run(self, jobs)
            return
        ctx = multiprocessing.get_context("spawn")
        self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=_ignore_sigint)
        futs = {self._pool.submit(job.fn, *job.args, **job.kw): job for job in jobs}
        pending = set(futs)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                yield futs[f], f.result()
        self._pool.shutdown()
        self._pool = None

    def __exit__(self, exc_type, exc, tb) -> bool:
        if self._pool is not None:  # an exception or Ctrl-C: no worker outlives the benchmark
            _terminate_workers(self._pool)
            self._pool = None
        return super().__exit__(exc_type, exc, tb)


def check_address(address: str, timeout: float = 5.0) -> None:
    """Raise ``ConnectionError`` at once when ``address`` is ``host:port`` and nothing listens there
    (Ray itself would retry for minutes); ``auto`` and ``ray://`` addresses are left to Ray."""
    import socket

    if address == "auto" or "://" in address:
        return
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit() or not host:
        raise ValueError(f"address {address!r}: expected host:port, ray://host:port or auto")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            pass
    except OSError as exc:
        raise ConnectionError(f"no Ray cluster answers at {address} ({exc.strerror or exc}); start one with "
                              f"`ray start --head --port {port}` or check the address") from None


def _call(fn, args, kw):
    """The Ray task: ``fn(*args, **kw)`` in a Ray worker."""
    return fn(*args, **kw)


class RayBackend(Backend):
    """Every job a Ray task with ``num_cpus = job.cpus`` (see the module doc for ``address``).

    ``init_kwargs``: further :func:`ray.init` arguments for a local Ray (e.g. ``object_store_memory``)."""

    name = "ray"

    def __init__(self, address: str | None = None, workers: int | None = None, **init_kwargs):
        try:
            import ray  # noqa: F401
        except ImportError:
            raise ImportError(f"the ray backend needs Ray: {RAY_EXTRA}") from None
        if address is not None and workers is not None:
            raise ValueError("workers sizes the local Ray the benchmark starts; a cluster given by address has its own "
                             "size: give one of them")
        if address is not None:
            check_address(address)
        self.address, self.workers, self.init_kwargs = address, workers, init_kwargs
        self._owned = False
        self._pending: list = []

    def parallel(self, n_jobs: int) -> bool:
        return True

    def describe(self) -> str:
        import ray

        cpus = int(ray.cluster_resources().get("CPU", 0)) if ray.is_initialized() else "?"
        where = "local" if self.address is None else self.address
        return f"ray {where}, {cpus} CPUs"

    def __enter__(self):
        import ray

        if ray.is_initialized():  # the caller's session (e.g. a notebook's or a test's ray.init)
            self._owned = False
            return self
        kw = {"include_dashboard": False, "logging_level": logging.WARNING, **self.init_kwargs}
        if self.address is None:  # "local": never join a cluster this machine happens to run
            ray.init(address="local", num_cpus=self.workers or os.cpu_count() or 1, **kw)
        else:
            kw.pop("include_dashboard")
            ray.init(address=self.address, **kw)
        self._owned = True
        return self

    def run(self, jobs):
        import ray

        task = ray.remote(_call)
        refs = {task.options(num_cpus=job.cpus, name=":".join(map(str, job.key))).remote(job.fn, job.args, job.kw): job
                for job in jobs}
        self._pending = list(refs)
        while self._pending:
            done, self._pending = ray.wait(self._pending, num_returns=1)
            for r in done:
                yield refs[r], ray.get(r)

    def __exit__(self, exc_type, exc, tb) -> bool:
        import ray

        # An exception or Ctrl-C: end the queued and running tasks. A local Ray this backend started ends
        # them by shutting down (its processes end), so only a cluster or a caller's session, which stay up,
        # need ray.cancel. That keeps Ray 2.60's race of a cancel with a task's reply (a fatal check, "Tried
        # to complete task that was not pending", ray-project/ray#54527) off a local Ray's Ctrl-C.
        local_owned = self._owned and self.address is None
        if self._pending and not local_owned and ray.is_initialized():
            for r in self._pending:
                ray.cancel(r, force=True)
        self._pending = []
        if self._owned and ray.is_initialized():
            ray.shutdown()  # a local Ray: its processes end; a cluster: this driver disconnects
        self._owned = False
        return False


def make_backend(name: str = "process", *, workers: int | None = None, address: str | None = None,
                 **ray_init) -> Backend:
    """The backend ``name`` (:data:`BACKENDS`); ``address`` and ``ray_init`` only with ``"ray"``."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; choose from {list(BACKENDS)}")
    if name != "ray" and (address is not None or ray_init):
        raise ValueError(f"address names a Ray cluster: it needs backend='ray', not {name!r}")
    if name == "serial":
        return SerialBackend()
    if name == "process":
        return ProcessBackend(workers)
    return RayBackend(address, workers, **ray_init)
