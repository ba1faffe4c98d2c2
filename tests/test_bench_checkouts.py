"""benchmarks/checkouts.py: the other checkout of the comparison scripts, a directory or a git ref."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

import pytest

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("bench_checkouts", os.path.join(_ROOT, "benchmarks", "checkouts.py"))
co = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(co)


def _git(*args):
    return subprocess.run(["git", "-C", _ROOT, *args], capture_output=True, text=True, check=True).stdout


pytestmark = pytest.mark.skipif(not os.path.exists(os.path.join(_ROOT, ".git")), reason="not a git checkout")


def test_a_directory_is_used_as_it_is(tmp_path):
    with co.checkout(str(tmp_path)) as path:
        assert path == str(tmp_path)
    assert tmp_path.is_dir()  # untouched


def test_a_ref_is_a_temporary_worktree_removed_afterwards():
    head = _git("rev-parse", "HEAD").strip()
    before = _git("worktree", "list", "--porcelain")
    with co.checkout("HEAD") as path:
        assert path not in before
        assert os.path.isfile(os.path.join(path, "benchmarks", "compare_checkouts.py"))
        assert subprocess.run(["git", "-C", path, "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip() == head
    assert not os.path.exists(path)
    assert _git("worktree", "list", "--porcelain") == before


def test_an_unknown_ref_names_itself():
    with pytest.raises(ValueError, match="no-such-ref-xyz"):
        with co.checkout("no-such-ref-xyz"):
            pass


@pytest.mark.parametrize("script", ["compare_checkouts.py", "bench_envs.py"])
def test_the_scripts_refuse_an_unknown_base_with_a_usage_error(script):
    res = subprocess.run([sys.executable, os.path.join(_ROOT, "benchmarks", script), "--base", "no-such-ref-xyz"],
                         capture_output=True, text=True, cwd=_ROOT, timeout=120)
    assert res.returncode == 2
    assert "no-such-ref-xyz" in res.stderr and "Traceback" not in res.stderr
