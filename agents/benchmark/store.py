"""The benchmark's ``--out`` directory: what it may hold (:func:`foreign_entries`, :func:`claim_out_dir`)
and the run records the driver writes there (:func:`write_record`) from what a worker returns.

Workers never write into ``out`` (no file system shared with them is assumed, :mod:`agents.benchmark.backends`):
a worker trains in a scratch directory of its own machine and returns the run's files with its
result; the driver writes them into ``<out>/models/<env>/<budget>/<agent>/s<seed>``, ``result.json``
last and atomically, so a run counts as finished only once every file is in place.
"""
from __future__ import annotations

import json
import os

from ..config.envs import ENVS
from ..training.runs import clear_run
from .plan import BUDGETS, is_agent_name

__all__ = ["MARKER", "OutDirError", "foreign_entries", "claim_out_dir", "RECORD_FILES", "write_record",
           "read_run_files"]


# ---------------------------------------------------------------------- what an --out directory may hold
#: written into ``out`` by every benchmark run (before anything else): the directory is the benchmark's
MARKER = ".dobs-envs-benchmark"
#: files the benchmark writes at the top level of ``out`` and in ``out/<env>``
_TOP_FILES = ("summary.json", "summary.png")
_ENV_FILES = ("results.json", "results.md", "results.csv", "error_norms.png", "learning_curves.png")
#: files a training run (``agents.training.train``) and the benchmark write in a run directory
_RUN_FILES = ("config.json", "model.zip", "vecnormalize.pkl", "replay_buffer.pkl", "curve.json", "result.json",
              "policy.npz", "policy.json", "train_curve.json")


class OutDirError(ValueError):
    """``out`` holds entries the benchmark did not write (``entries``, paths relative to ``out``), or is a file."""

    def __init__(self, out: str, entries: list[str], detail: str | None = None):
        self.out, self.entries = out, list(entries)
        shown = ", ".join(self.entries[:5]) + (f" and {len(self.entries) - 5} more" if len(self.entries) > 5 else "")
        super().__init__(detail or f"{out!r} holds {len(self.entries)} entr{'y' if len(self.entries) == 1 else 'ies'} "
                                   f"the benchmark did not write ({shown}); the benchmark would overwrite or delete "
                                   f"files there: pass --overwrite (overwrite=True) or choose another out")


def _run_dir_foreign(path: str, rel: str) -> list[str]:
    """Entries of a run directory ``<out>/models/<env>/<budget>/<agent>/s<seed>`` no run writes."""
    bad = []
    for f in sorted(os.listdir(path)):
        name = f[:-4] if f.endswith(".tmp") else f  # atomic writes leave <file>.tmp behind when killed
        if name == "checkpoints" and os.path.isdir(os.path.join(path, f)):
            continue
        if name not in _RUN_FILES or not os.path.isfile(os.path.join(path, f)):
            bad.append(f"{rel}/{f}")
    return bad


def _models_foreign(out: str) -> tuple[list[str], int]:
    """``(entries of out/models outside the layout models/<env>/<budget>/<agent>/s<seed>/<run files>, runs)``."""
    bad, runs = [], 0
    root = os.path.join(out, "models")
    levels = (set(ENVS).__contains__, set(BUDGETS).__contains__, is_agent_name)
    def walk(path: str, rel: str, depth: int) -> None:  # noqa: E306
        nonlocal runs
        for f in sorted(os.listdir(path)):
            p, r = os.path.join(path, f), f"{rel}/{f}"
            if not os.path.isdir(p):
                bad.append(r)
            elif depth < 3:
                if levels[depth](f):
                    walk(p, r, depth + 1)
                else:
                    bad.append(r)
            elif f.startswith("s") and f[1:].isdigit():
                runs += os.path.isfile(os.path.join(p, "config.json"))
                bad.extend(_run_dir_foreign(p, r))
            else:
                bad.append(r)
    walk(root, "models", 0)
    return bad, runs


def foreign_entries(out: str) -> list[str]:
    """The entries of ``out`` (paths relative to it) that the benchmark did not write; ``[]``: the
    benchmark may write there. ``out`` missing or empty: ``[]``.

    The rule. The benchmark writes ``out/{MARKER}`` first, then only the layout
    ``models/<env>/<budget>/<agent>/s<seed>/`` (run files: config.json, model.zip,
    vecnormalize.pkl, replay_buffer.pkl, curve.json, result.json, checkpoints/; a jitted run's policy.npz,
    policy.json, train_curve.json), ``<env>/results.{json,md,csv}``,
    ``<env>/error_norms.png``, ``<env>/learning_curves.png``, ``summary.json`` and ``summary.png``
    (``<env>``, ``<budget>``, ``<agent>``: the known names, ``<agent>@recipe`` included). An entry outside that layout is foreign.
    The output files (``summary.*``, ``<env>/*``) are the benchmark's only when the marker is there,
    or, in a directory of a benchmark older than the marker, when ``models/`` holds at least one run
    of the layout (with its ``config.json``); without either, they are the user's (foreign).
    """
    if not os.path.isdir(out):
        return []
    top = sorted(os.listdir(out))
    bad, runs = [], 0
    if "models" in top:
        if os.path.isdir(os.path.join(out, "models")):
            bad, runs = _models_foreign(out)
        else:
            bad.append("models")
    ours = MARKER in top or runs > 0
    for f in top:
        p = os.path.join(out, f)
        if f in (MARKER, "models"):
            continue
        if f in _TOP_FILES and os.path.isfile(p) and ours:
            continue
        if f in ENVS and os.path.isdir(p) and ours:
            bad.extend(f"{f}/{g}" for g in sorted(os.listdir(p))
                       if g not in _ENV_FILES or not os.path.isfile(os.path.join(p, g)))
            continue
        bad.append(f)
    return bad


def claim_out_dir(out: str, *, overwrite: bool = False) -> None:
    """Check ``out`` with :func:`foreign_entries` and write the marker: the benchmark's first write.

    Raises :class:`OutDirError` when ``out`` is a file, or holds foreign entries and not ``overwrite``
    (then nothing is written)."""
    if os.path.exists(out) and not os.path.isdir(out):
        raise OutDirError(out, [], f"{out!r} is a file, not a directory")
    bad = foreign_entries(out)
    if bad and not overwrite:
        raise OutDirError(out, bad)
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, MARKER), "w") as fh:
        fh.write("written by `dobs-envs benchmark`: this directory holds its runs and results "
                 "(agents.benchmark.store.foreign_entries)\n")


# ---------------------------------------------------------------------- run records (written by the driver)
#: the files of a trained run a worker returns (``result.json`` is the record's ``result``, written last);
#: the benchmark trains without checkpoints, and a complete run keeps no replay buffer; a jitted run
#: (:mod:`agents.training.jax`) has its exported policy and its trainer's curve instead of model and normaliser
RECORD_FILES = ("config.json", "model.zip", "vecnormalize.pkl", "curve.json", "policy.npz", "policy.json",
                "train_curve.json")
#: the files a kept model is evaluated again from (:func:`agents.training.loading.load_agent`; those present)
MODEL_FILES = ("config.json", "model.zip", "vecnormalize.pkl", "policy.npz", "policy.json")


def write_record(path: str, record: dict) -> None:
    """Write a worker's ``record`` into the run directory ``path``.

    ``record["files"]`` (name -> bytes, names from :data:`RECORD_FILES`): a newly trained run; the
    previous run's files in ``path`` are removed first (none of them may be taken for the new
    run's). Empty for a kept model evaluated again: its files stay as they are. Then
    ``record["result"]`` is written as ``result.json``, atomically and last."""
    files = record["files"]
    unknown = sorted(set(files) - set(RECORD_FILES))
    if unknown:
        raise ValueError(f"a run record holds files {unknown}; expected some of {RECORD_FILES}")
    os.makedirs(path, exist_ok=True)
    done = os.path.join(path, "result.json")
    if files:
        if os.path.exists(done):
            os.remove(done)  # first: the old result never describes the new files
        clear_run(path)
        if os.path.isfile(os.path.join(path, "curve.json")):
            os.remove(os.path.join(path, "curve.json"))
        for name, data in files.items():
            target = os.path.join(path, name)
            with open(target + ".tmp", "wb") as fh:
                fh.write(data)
            os.replace(target + ".tmp", target)
    with open(done + ".tmp", "w") as fh:
        json.dump(record["result"], fh)
    os.replace(done + ".tmp", done)  # atomic: a half-written result is never taken as finished


def read_run_files(path: str, names=MODEL_FILES) -> dict:
    """The files ``names`` present in the run directory ``path``, as ``{name: bytes}`` (what a worker
    needs to evaluate a kept model again on its own machine)."""
    out = {}
    for name in names:
        p = os.path.join(path, name)
        if os.path.isfile(p):
            with open(p, "rb") as fh:
                out[name] = fh.read()
    return out
