"""What trained a run: the source revision of this package and the machine (``config.json`` ``provenance`` of every
run directory, SB3's and the jitted trainer's; ``summary.json`` of a benchmark).

Why both. On one machine the same code, recipe and seed train the same run bit for bit (the jitted runs of
``results/`` retrained by the documented command, docs/results/index.md). But XLA and numba compile for the host
CPU (LLVM's name for it, e.g. ``znver3``, and its instruction set), and another CPU can round a reduction
differently; training amplifies a last-digit difference into a different policy. Runs of the same recipe and seeds
trained on 2026-12-05 differ from the runs of 2026-12-06 although the jax, jaxlib and optax versions recorded were
equal; the commit that had trained disturbance_rejection's shared-PPO runs (21e2d00), retrained on 2026-12-06, gave
the 2026-12-06 runs bit for bit, so the code was not the cause, and nothing recorded which machine had trained them.
So a run records which code (``source``) and which CPU (``machine``) produced it.

- ``source``: ``commit`` (``git rev-parse HEAD`` of the checkout holding this package) and ``dirty`` (whether its
  tracked files differ from that commit: the run's code is then not exactly the commit's). An installed package
  outside a git checkout: the commit pip installed it from when that was a git URL, ``dirty`` None; both None
  otherwise (installed from a directory or an archive) or without git.
- ``machine``: LLVM's host CPU name (``llvm_cpu``: the target numba and XLA:CPU compile for), the CPU's model name,
  the SIMD extensions present (``simd``: those that change the compiled arithmetic), the number of logical CPUs, the
  platform and Python's version.

Read once per process (cached), when a run starts (a benchmark: when the command starts): the code imported then
is the code that runs, whatever happens to the files afterwards. Nothing here enters a run's numbers or the
benchmark's reuse of stored runs.
"""
from __future__ import annotations

import functools
import json
import os
import platform
import subprocess

__all__ = ["run_provenance", "source_revision", "machine", "SIMD_FLAGS"]

#: the CPU flags (Linux ``/proc/cpuinfo`` names) that decide which vector instructions compiled code may use
SIMD_FLAGS = ("sse4_2", "avx", "avx2", "fma", "f16c", "avx512f", "avx512dq", "avx512bw", "avx512vl", "avx512_vnni",
              "avx512_bf16", "avx512_fp16", "amx_tile", "asimd", "sve")

_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _git(root: str, *args: str) -> str:
    out = subprocess.run(["git", "-C", root, *args], capture_output=True, text=True, timeout=30, check=True)
    return out.stdout.strip()


def _installed_commit() -> str | None:
    """The commit pip installed this package from, when it was installed from a git URL (PEP 610's
    ``direct_url.json`` ``vcs_info.commit_id``), else None."""
    try:
        from importlib import metadata

        info = json.loads(metadata.distribution("dobs-envs").read_text("direct_url.json") or "{}")
        commit = info["vcs_info"]["commit_id"]
    except Exception:  # noqa: BLE001 - no metadata, no file, not JSON, no such field: unknown
        return None
    return commit if isinstance(commit, str) else None


def source_revision(root: str | None = None) -> dict:
    """``{"commit", "dirty"}`` of the git checkout at ``root`` (default: the one holding this package). Outside a
    git checkout (an installed package): the commit pip installed it from if that was a git URL, ``dirty`` None;
    both None otherwise, or when git cannot be run."""
    own = root is None
    root = _ROOT if own else root
    if not os.path.exists(os.path.join(root, ".git")):  # a directory, or a worktree's file
        return {"commit": _installed_commit() if own else None, "dirty": None}
    try:
        commit = _git(root, "rev-parse", "HEAD")
        dirty = bool(_git(root, "status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    return {"commit": commit, "dirty": dirty}


def _cpuinfo() -> tuple[str | None, set]:
    """``(model name, flags)`` of the first CPU in ``/proc/cpuinfo`` (``(None, set())`` where unreadable)."""
    model, flags = None, set()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                key = key.strip()
                if key == "model name" and model is None:
                    model = value.strip()
                elif key in ("flags", "Features") and not flags:
                    flags = set(value.split())
    except OSError:
        pass
    return model, flags


def machine() -> dict:
    """``{"llvm_cpu", "cpu", "simd", "cpus", "platform", "python"}`` of this machine (module doc)."""
    try:
        from llvmlite import binding as llvm  # numba's LLVM (a dependency of the package)

        llvm_cpu = str(llvm.get_host_cpu_name())
    except Exception:  # noqa: BLE001 - any failure of an optional probe: recorded as unknown
        llvm_cpu = None
    model, flags = _cpuinfo()
    return {"llvm_cpu": llvm_cpu, "cpu": model or platform.processor() or None,
            "simd": [f for f in SIMD_FLAGS if f in flags], "cpus": os.cpu_count(),
            "platform": platform.platform(), "python": platform.python_version()}


@functools.lru_cache(maxsize=1)
def _cached() -> dict:
    return {"source": source_revision(), "machine": machine()}


def run_provenance() -> dict:
    """``{"source": source_revision(), "machine": machine()}`` of this process (a fresh copy of a cached read)."""
    c = _cached()
    return {"source": dict(c["source"]), "machine": {**c["machine"], "simd": list(c["machine"]["simd"])}}
