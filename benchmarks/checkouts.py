"""The other checkout a benchmark script compares with: a directory the user gives, or a git ref.

``--base REF`` of ``compare_checkouts.py``, ``bench_envs.py`` and ``bench_design_ray.py``: an existing
directory is used as it is (nothing written into it); anything else is a git ref (a branch, a tag, a
commit, ``HEAD~3``) of the repository this file belongs to, checked out with ``git worktree add --detach``
into a temporary directory for the run and removed afterwards (``git worktree remove --force``, also
when the run fails or is interrupted), so the comparison needs no second checkout on the machine. The
default is the branch ``main``. A directory keeps the numba cache its worker builds (under the temp
directory, keyed by the path) from one run to the next; a ref's fresh worktree compiles cold (minutes).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile

#: the repository the scripts belong to (the default ``--head``, where a ref is looked up)
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

__all__ = ["REPO", "checkout", "add_base_argument"]


def add_base_argument(ap, default: str = "main", what: str = "the checkout compared with") -> None:
    """``--base REF|PATH`` on the argparse parser ``ap``."""
    ap.add_argument("--base", default=default, metavar="REF|PATH",
                    help=f"{what}: a directory, or a git ref of this repository checked out in a temporary "
                         f"git worktree for the run (default: {default})")


@contextlib.contextmanager
def checkout(spec: str, repo: str = REPO):
    """The directory of ``spec`` for the duration of the ``with`` block.

    ``spec`` an existing directory (returned as its absolute path, untouched), or a git ref of ``repo``
    (checked out into a temporary worktree, removed on exit). A ref that git does not know raises
    ``ValueError`` naming it.
    """
    if os.path.isdir(spec):
        yield os.path.abspath(spec)
        return
    res = subprocess.run(["git", "-C", repo, "rev-parse", "--verify", "--quiet", spec + "^{commit}"],
                         capture_output=True, text=True)
    if res.returncode != 0:
        raise ValueError(f"--base {spec!r}: neither a directory nor a git ref of {repo}")
    commit = res.stdout.strip()
    tmp = tempfile.mkdtemp(prefix="dobs_base_")
    path = os.path.join(tmp, commit[:12])
    subprocess.run(["git", "-C", repo, "worktree", "add", "--detach", "--quiet", path, commit], check=True)
    try:
        yield path
    finally:
        subprocess.run(["git", "-C", repo, "worktree", "remove", "--force", path], check=False)
        shutil.rmtree(tmp, ignore_errors=True)
        subprocess.run(["git", "-C", repo, "worktree", "prune"], check=False)
