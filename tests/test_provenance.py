"""agents.training.provenance: what trained a run (the source revision and the machine), on a real git repository
and this machine's /proc/cpuinfo and LLVM."""
from __future__ import annotations

import json
import os
import shutil
import subprocess

import pytest

from agents.training import provenance
from agents.training.provenance import SIMD_FLAGS, machine, run_provenance, source_revision

GIT = shutil.which("git")


def _git(root, *args):
    env = {**os.environ, "GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
           "GIT_COMMITTER_EMAIL": "t@t"}
    return subprocess.run(["git", "-C", str(root), *args], check=True, capture_output=True, text=True,
                          env=env).stdout.strip()


@pytest.mark.skipif(GIT is None, reason="needs git")
def test_source_revision_of_a_checkout_its_commit_and_whether_tracked_files_changed(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    _git(repo, "init", "-q")
    (repo / "a.py").write_text("x = 1\n")
    _git(repo, "add", "a.py")
    _git(repo, "commit", "-q", "-m", "one")
    head = _git(repo, "rev-parse", "HEAD")
    assert source_revision(str(repo)) == {"commit": head, "dirty": False}
    (repo / "new.py").write_text("untracked\n")  # an untracked file is not the run's code
    assert source_revision(str(repo)) == {"commit": head, "dirty": False}
    (repo / "a.py").write_text("x = 2\n")
    assert source_revision(str(repo)) == {"commit": head, "dirty": True}
    _git(repo, "commit", "-q", "-am", "two")
    assert source_revision(str(repo)) == {"commit": _git(repo, "rev-parse", "HEAD"), "dirty": False} != head
    # a worktree (.git is a file there) of the first commit
    _git(repo, "worktree", "add", "-q", "--detach", str(tmp_path / "wt"), head)
    assert source_revision(str(tmp_path / "wt")) == {"commit": head, "dirty": False}


def test_source_revision_outside_a_checkout_is_unknown(tmp_path, monkeypatch):
    assert source_revision(str(tmp_path)) == {"commit": None, "dirty": None}
    # the installed package (no .git beside it): pip's record of a git URL install, else unknown
    monkeypatch.setattr(provenance, "_ROOT", str(tmp_path))
    monkeypatch.setattr(provenance, "_installed_commit", lambda: "0123abc")
    assert source_revision() == {"commit": "0123abc", "dirty": None}
    monkeypatch.setattr(provenance, "_installed_commit", lambda: None)
    assert source_revision() == {"commit": None, "dirty": None}


def test_installed_commit_reads_pep_610_direct_url(monkeypatch):
    from importlib import metadata

    class Dist:
        def __init__(self, text):
            self.text = text

        def read_text(self, name):
            assert name == "direct_url.json"
            return self.text

    for text, expected in [(json.dumps({"url": "https://x/y.git", "vcs_info": {"vcs": "git", "commit_id": "f00d"}}),
                            "f00d"),
                           (json.dumps({"url": "file:///src", "dir_info": {}}), None), (None, None), ("{not json", None),
                           (json.dumps({"vcs_info": "malformed"}), None), (json.dumps([1]), None)]:
        monkeypatch.setattr(metadata, "distribution", lambda name, t=text: Dist(t))
        assert provenance._installed_commit() == expected


def test_machine_names_the_compile_target_and_the_simd_extensions():
    from llvmlite import binding as llvm

    m = machine()
    assert set(m) == {"llvm_cpu", "cpu", "simd", "cpus", "platform", "python"}
    assert m["llvm_cpu"] == llvm.get_host_cpu_name() and m["cpus"] == os.cpu_count()
    assert set(m["simd"]) <= set(SIMD_FLAGS)
    if os.path.exists("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as fh:
            flags = next((ln.split(":", 1)[1].split() for ln in fh if ln.split(":")[0].strip() in ("flags", "Features")),
                         [])
        assert m["simd"] == [f for f in SIMD_FLAGS if f in flags]


def test_run_provenance_is_json_and_a_copy():
    a = run_provenance()
    assert set(a) == {"source", "machine"} and json.loads(json.dumps(a)) == a
    a["machine"]["simd"].append("x")
    a["source"]["commit"] = "changed"
    assert run_provenance() != a
