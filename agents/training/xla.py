"""XLA's CPU runtime as the jitted trainers need it: its thread pool and the flags read when JAX creates its
CPU client (at the process's first JAX computation; nothing here has an effect after that).

- :func:`xla_threads`: one XLA thread per training process (the benchmark's runs, one per core);
- :func:`xla_safe_flags`: :data:`XLA_NO_CONCURRENT_SCHEDULER` added to ``XLA_FLAGS`` (done when
  :mod:`agents.training.jax` is imported, if JAX has not computed anything yet);
- :func:`check_xla_runtime`: a :class:`RuntimeWarning` when a trainer is built in a process whose CPU client
  already runs several threads without that flag.

**Why the flag.** With jaxlib 0.10.2 on CPU and a client of more than one thread, a vmapped jitted trainer
(``jax.jit(jax.vmap(train))`` of :func:`agents.training.jax.ppo.make_train` over 2 or 4 seeds) deadlocks in
most runs: the main thread waits for the result buffers (``AwaitBuffersReady``), every XLA worker thread
idles in its pool (gdb), 0 % CPU, forever. Measured on the 2-core machine, 2026-12-05, fresh processes of
the program of ``tests/test_xla_runtime.py`` (tracking, 2 copies x 16 steps, 2 updates; it takes ~15-25 s):
vmapped over 2 or 4 seeds with XLA's default flags, **7 of 7 hung** (timeouts of 90-150 s; the flag below set
to ``true`` counts as default); one run, not vmapped, 4 of 4 finished; ``PJRT_NPROC=1`` always finished (every
jitted test of the suite runs so); ``--xla_cpu_multi_thread_eigen=false``, ``--xla_cpu_use_xnnpack=false`` or
XNN graph fusion off: still hung; with **--xla_cpu_enable_concurrency_optimized_scheduler=false: 12 of 12
finished**. So the hang needs XLA:CPU's concurrency-optimised HLO schedule (which lets the runtime run
independent operations at once); with workers idle and work outstanding it looks like a lost wake-up in XLA's
runtime, not a fault of these trainers. With one thread the flag changes nothing: a 6-update PPO run gives
bitwise the same arrays with and without it, at the same speed (2.9-3.0 s CPU both ways).
"""
from __future__ import annotations

import os
import sys
import warnings

__all__ = ["XLA_ONE_THREAD", "PJRT_THREADS", "XLA_NO_CONCURRENT_SCHEDULER", "xla_threads", "xla_safe_flags",
           "xla_pool_threads", "check_xla_runtime"]

#: XLA's CPU flag for one thread, kept for jaxlib versions that honour it (read when JAX creates its CPU
#: client, i.e. at the first JAX computation); jaxlib 0.10 ignores it (its Eigen pool kept 2 threads)
XLA_ONE_THREAD = ("--xla_cpu_multi_thread_eigen=false",)
#: environment variable that sizes the thread pool of the PJRT CPU client, on which XLA runs its
#: intra-op work (read when JAX creates that client); "1": one thread
PJRT_THREADS = "PJRT_NPROC"
#: XLA's CPU flag that avoids the deadlock of multi-threaded clients on vmapped trainers (module docstring)
XLA_NO_CONCURRENT_SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler=false"


def _add_flags(flags: tuple[str, ...]) -> None:
    """Append to ``XLA_FLAGS`` each flag whose name the user has not set (any value the user gave wins)."""
    current = os.environ.get("XLA_FLAGS", "")
    missing = [f for f in flags if f.split("=")[0] not in current]
    if missing:
        os.environ["XLA_FLAGS"] = " ".join([current, *missing]).strip()


def xla_threads(threads: int | None = 1) -> None:
    """With ``threads=1``, XLA single-threaded (``PJRT_NPROC=1`` unless the user set it, and
    :data:`XLA_ONE_THREAD` added to ``XLA_FLAGS``); with any ``threads``, :func:`xla_safe_flags`. The XLA part
    of :func:`agents.training.train.set_threads` (the jitted trainer's, which needs no torch); effective only
    before JAX's first computation."""
    if threads == 1:
        os.environ.setdefault(PJRT_THREADS, "1")
        _add_flags(XLA_ONE_THREAD)
    xla_safe_flags()


def _backend_started() -> bool:
    if "jax" not in sys.modules:
        return False
    from jax._src import xla_bridge

    return bool(xla_bridge.backends_are_initialized())


def xla_safe_flags() -> bool:
    """Add :data:`XLA_NO_CONCURRENT_SCHEDULER` to ``XLA_FLAGS`` (unless the user set that flag) if JAX has not
    created its backends yet; returns whether the flag can still take effect (``False``: JAX already runs,
    with whatever flags it started with)."""
    if _backend_started():
        return False
    _add_flags((XLA_NO_CONCURRENT_SCHEDULER,))
    return True


def xla_pool_threads() -> int | None:
    """The number of XLA CPU compute threads of this process (jaxlib names them ``tf_XLAEigen``), counted in
    ``/proc/self/task``; ``None`` where that is not readable (not Linux)."""
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return None
    count = 0
    for t in tasks:
        try:
            with open(f"/proc/self/task/{t}/comm") as f:
                count += "XLAEigen" in f.read()
        except OSError:  # the thread ended meanwhile
            continue
    return count


def check_xla_runtime(where: str) -> None:
    """Warn (:class:`RuntimeWarning`) if JAX's CPU client already runs more than one compute thread and
    ``XLA_FLAGS`` lacks :data:`XLA_NO_CONCURRENT_SCHEDULER`: vmapped, ``where``'s program then deadlocks in most
    runs (module docstring). Silent before JAX starts (importing :mod:`agents.training.jax` adds the flag),
    with one thread, or with the flag."""
    if not _backend_started() or XLA_NO_CONCURRENT_SCHEDULER.split("=")[0] in os.environ.get("XLA_FLAGS", ""):
        return
    threads = xla_pool_threads()
    if threads is not None and threads > 1:
        warnings.warn(
            f"{where}: JAX's CPU client runs {threads} XLA threads without {XLA_NO_CONCURRENT_SCHEDULER}; with "
            f"jaxlib 0.10 a vmapped trainer then deadlocks in most runs. Import agents.training.jax (or call "
            f"agents.training.xla.xla_threads) before JAX's first computation, or set "
            f"XLA_FLAGS={XLA_NO_CONCURRENT_SCHEDULER} (or PJRT_NPROC=1) before starting Python",
            RuntimeWarning, stacklevel=3)
