"""Process trees read from /proc (Linux), for the tests that check that Ctrl-C ends every worker."""
from __future__ import annotations

import os


def children(pid: int) -> set[int]:
    """The direct children of ``pid`` (empty once it has exited)."""
    kids = set()
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as fh:
                kids |= {int(c) for c in fh.read().split()}
    except FileNotFoundError:
        pass
    return kids


def descendants(pid: int) -> set[int]:
    """Every process below ``pid``."""
    out, todo = set(), [pid]
    while todo:
        for kid in children(todo.pop()):
            if kid not in out:
                out.add(kid)
                todo.append(kid)
    return out


def alive(pid: int) -> bool:
    """Whether ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False
