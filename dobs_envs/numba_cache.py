"""numba's on-disk cache of the compiled kernels, kept consistent across modules.

numba keys a cached function on its *own* source file only (its modification time and size),
but the cached machine code of a kernel also holds the callees it inlined from other modules:
``envs.step_kernel.advance_range`` holds ``sim.period_kernel.advance_rows``. After an edit of
``sim/period_kernel.py`` alone, the cached ``advance_range`` would go on running the old kernel, with
no error (seen in a development checkout on 2026-12-02: the tests passed on the stale code).

:func:`ensure_fresh` fingerprints the sources of every module with cached kernels
(:data:`KERNEL_MODULES`) and, where the fingerprint differs from the one recorded in that
module's cache directory (wherever numba puts it: ``__pycache__`` beside the file,
``NUMBA_CACHE_DIR``, or the user-wide fallback), removes that module's cache files before any
of them is loaded. Every kernel module calls it on import; it does its work once per process
(reading seven source files, well under a millisecond) and never raises: at worst numba
compiles again.
"""
from __future__ import annotations

import glob
import hashlib
import os

__all__ = ["KERNEL_MODULES", "ensure_fresh", "fingerprint", "cache_dir"]

#: modules of ``dobs_envs`` (paths relative to the package) whose source is compiled into the cached
#: kernels: those whose kernels numba caches (each one's cached code may hold code compiled from the
#: others), then the declarations of the kernels' arguments (``sim/kernel_args.py``) and the generator
#: of their compiled unpacking (``packing.py``): numba caches that generated code under the kernel
#: module's file, which does not change when a declaration does
KERNEL_MODULES = ("sim/period_kernel.py", "sim/jit.py", "envs/step_kernel.py", "envs/features.py", "control/law_kernel.py",
                  "rollout.py", "sim/fault_kernel.py", "sim/kernel_args.py",
                  "sim/fault_state.py", "sim/fault_rng.py", "packing.py")

#: name of the file, in a module's cache directory, that records the fingerprint its cache was built from
STAMP = "dobs_envs_kernels.fingerprint"

_ROOT = os.path.dirname(os.path.abspath(__file__))
_done: set = set()


def fingerprint(root: str = _ROOT, modules=KERNEL_MODULES) -> str:
    """SHA-1 of the kernel modules' sources (missing files count as empty)."""
    h = hashlib.sha1()
    for rel in modules:
        h.update(rel.encode() + b"\0")
        try:
            with open(os.path.join(root, rel), "rb") as fh:
                h.update(fh.read())
        except OSError:
            pass
        h.update(b"\0")
    return h.hexdigest()


def cache_dir(source: str) -> str:
    """The directory where numba caches the functions of the file ``source`` (numba's own cache
    locators; ``__pycache__`` beside the file if they cannot be asked)."""
    try:
        from numba.core.caching import CompileResultCacheImpl  # what njit(cache=True) uses

        ns: dict = {}
        exec(compile("def _probe():\n    pass\n", source, "exec"), ns)  # a function 'defined in' source
        return CompileResultCacheImpl(ns["_probe"])._locator.get_cache_path()
    except Exception:  # another numba version's internals: the in-tree default
        return os.path.join(os.path.dirname(source), "__pycache__")


def ensure_fresh(root: str = _ROOT, modules=KERNEL_MODULES) -> list[str]:
    """Remove the cache files of ``modules`` (under ``root``) built from other sources than today's.

    Returns the removed files. Runs once per process and ``root``; errors (a read-only cache
    directory, a file another process removed first) are ignored.
    """
    if root in _done:
        return []
    _done.add(root)
    fp = fingerprint(root, modules)
    removed = []
    for rel in modules:
        src = os.path.join(root, rel)
        d = cache_dir(src)
        stamp = os.path.join(d, STAMP)
        stem = os.path.splitext(os.path.basename(src))[0]
        try:
            with open(stamp) as fh:
                recorded = fh.read().split()
        except OSError:
            recorded = []
        key = f"{rel}={fp}"
        if key in recorded:
            continue
        for f in glob.glob(os.path.join(d, glob.escape(stem) + ".*.nb[ic]")):
            try:
                os.remove(f)
                removed.append(f)
            except OSError:
                pass
        # one line per module whose cache lives here (two kernel modules may share a directory)
        keep = [r for r in recorded if not r.startswith(rel + "=")] + [key]
        try:
            os.makedirs(d, exist_ok=True)
            tmp = f"{stamp}.{os.getpid()}.tmp"
            with open(tmp, "w") as fh:
                fh.write("\n".join(keep) + "\n")
            os.replace(tmp, stamp)
        except OSError:
            pass
    return removed
