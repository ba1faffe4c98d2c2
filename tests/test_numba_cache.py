"""dobs_envs.numba_cache: cache files of the kernel modules built from other sources are removed."""
from __future__ import annotations

import glob
import os

import numpy as np

from dobs_envs import numba_cache
from dobs_envs.numba_cache import KERNEL_MODULES, STAMP, cache_dir, ensure_fresh, fingerprint


def _fake_tree(tmp_path):
    modules = ("a/k.py", "b/s.py")
    for rel in modules:
        os.makedirs(tmp_path / os.path.dirname(rel), exist_ok=True)
        (tmp_path / rel).write_text("x = 1\n")
    return str(tmp_path), modules


def _fake_cache(root, modules):
    """Files named as numba names them (<stem>.<qualname>-<line>.py<ver>.nbi/.nbc) and one of another module."""
    made = []
    for rel in modules:
        d = cache_dir(os.path.join(root, rel))
        stem = os.path.splitext(os.path.basename(rel))[0]
        for ext in ("nbi", "nbc"):
            f = os.path.join(d, f"{stem}.f-3.py311.{ext}")
            open(f, "w").close()
            made.append(f)
        open(os.path.join(d, "other.g-1.py311.nbi"), "w").close()
    return made


def test_stale_caches_are_removed_and_fresh_ones_kept(tmp_path):
    root, modules = _fake_tree(tmp_path)
    made = _fake_cache(root, modules)
    assert sorted(ensure_fresh(root, modules)) == sorted(made)  # no fingerprint recorded yet: stale
    for rel in modules:
        d = cache_dir(os.path.join(root, rel))
        assert os.path.exists(os.path.join(d, "other.g-1.py311.nbi"))  # other modules' caches untouched
        assert open(os.path.join(d, STAMP)).read().split() == [f"{rel}={fingerprint(root, modules)}"]
    assert ensure_fresh(root, modules) == []  # once per process and root
    numba_cache._done.discard(root)
    made = _fake_cache(root, modules)
    assert ensure_fresh(root, modules) == []  # same sources: the caches are kept
    assert all(os.path.exists(f) for f in made)
    numba_cache._done.discard(root)
    (tmp_path / "a" / "k.py").write_text("x = 2\n")  # an edit of one module makes every module's cache stale
    assert sorted(ensure_fresh(root, modules)) == sorted(made)


def test_the_real_kernel_caches_live_where_they_are_checked():
    """numba writes the compiled kernels' cache files into the directories ensure_fresh cleans, and
    they carry today's fingerprint."""
    from dobs_envs.envs import TrackingEnv

    core = TrackingEnv.make_core(1)
    core.reset(None, [0])
    core.advance(np.zeros((1, core.n_inputs)))
    root = os.path.dirname(numba_cache.__file__)
    d = cache_dir(os.path.join(root, "envs/step_kernel.py"))
    assert glob.glob(os.path.join(d, "step_kernel.*.nbi")), d
    fp = fingerprint()
    for rel in KERNEL_MODULES:
        stamp = os.path.join(cache_dir(os.path.join(root, rel)), STAMP)
        assert f"{rel}={fp}" in open(stamp).read().split()
