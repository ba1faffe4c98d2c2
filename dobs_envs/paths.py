"""Output paths given on the command line, checked once before any work starts.

Every ``dobs-envs`` command that writes (``reproduce --out``, ``train --out`` / ``--tensorboard``,
``benchmark --out``, ``tune --out``, ``evaluate --json``) checks its output path here, so that a path
that cannot be created (a regular file in the way, e.g. ``--out notes.txt/run``) is one usage line
naming the option, not a ``NotADirectoryError`` traceback after minutes of work. Plain ``os.path``
only: imported by :mod:`dobs_envs.reproduce` and by the ``agents`` commands alike.
"""
from __future__ import annotations

import os

__all__ = ["OutputPathError", "check_output_dir", "check_output_file"]


class OutputPathError(ValueError):
    """An output path that cannot be written: the message starts with the option and the path."""


def _blocking_file(path: str) -> str | None:
    """The existing non-directory that ``path`` or one of its parents is (the nearest existing
    ancestor, when it is not a directory), or None when every existing ancestor is a directory."""
    p = os.path.abspath(path)
    while True:
        if os.path.lexists(p):
            return None if os.path.isdir(p) else p
        parent = os.path.dirname(p)
        if parent == p:
            return None
        p = parent


def check_output_dir(path: str, option: str = "--out") -> str:
    """``path`` when it can be the output directory of a command (it is a directory, or it can be made:
    no regular file among it and its parents); else :class:`OutputPathError`
    ``"<option> '<path>' is a file, not a directory"`` or ``"<option> '<path>': '<parent>' is a file,
    not a directory"``. Whether a directory already holds results is each command's own rule."""
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise OutputPathError(f"{option} {path!r}: expected a directory path")
    path = os.fspath(path)
    block = _blocking_file(path)
    if block is None:
        return path
    if block == os.path.abspath(path):
        raise OutputPathError(f"{option} {path!r} is a file, not a directory")
    raise OutputPathError(f"{option} {path!r}: {block!r} is a file, not a directory")


def check_output_file(path: str, option: str, *, overwrite: bool = False, example: str = "out.json") -> str:
    """``path`` when a file can be written there: not a directory, its directory exists (files are not
    written into directories made on the fly) and is a directory, and no file of that name exists unless
    ``overwrite``; else :class:`OutputPathError` naming ``option``."""
    if not isinstance(path, (str, os.PathLike)) or not str(path):
        raise OutputPathError(f"{option} {path!r}: expected a file path")
    path = os.fspath(path)
    if os.path.isdir(path):
        raise OutputPathError(f"{option} {path!r} is a directory; give a file name, e.g. "
                              f"{os.path.join(path, example)}")
    block = _blocking_file(path)
    if block is not None and block != os.path.abspath(path):
        raise OutputPathError(f"{option} {path!r}: {block!r} is a file, not a directory")
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        raise OutputPathError(f"{option} {path!r}: directory {d!r} does not exist")
    if os.path.lexists(path) and not overwrite:
        raise OutputPathError(f"{option} {path!r} already exists; pass --overwrite to replace it, or choose another "
                              f"file")
    return path
