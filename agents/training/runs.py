"""Run directories: their layout, the atomic saves that write them, and reading them back.

A run directory (``runs/<env>_<algo>[_ma]_s<seed>`` by default, :func:`default_run_dir`) holds

- ``config.json``: everything needed to rebuild the env and the policy inputs; ``status``
  (:data:`RUNNING` / :data:`INTERRUPTED` / :data:`COMPLETE`), ``timesteps_done``, and the
  ``library`` / ``library_version`` that trained it (:mod:`agents.training.algos`; absent in runs
  written before they were recorded, which were trained with :data:`agents.training.algos.LEGACY_LIBRARY`);
- ``model.zip`` and ``vecnormalize.pkl`` (when observations or rewards are normalised);
- ``replay_buffer.pkl`` (off-policy run interrupted by SIGINT, so that it resumes with its buffer);
- ``checkpoints/<algo>_<sb3 steps>_steps.zip`` with its normaliser
  ``<algo>_vecnormalize_<sb3 steps>_steps.pkl``.

A jitted run (``dobs-envs train --trainer jax``, :mod:`agents.training.jax.run`; ``config.json``
``trainer: "jax"``) holds ``policy.npz`` + ``policy.json`` instead of the model and normaliser,
``curve.json`` and ``train_curve.json``; it has no checkpoints and cannot be resumed.

:func:`read_run_config` and :func:`run_files` validate a run directory (or its ``model.zip``,
or one checkpoint) for loading (:func:`agents.training.loading.load_agent`); :func:`resume_point` finds
where :func:`agents.training.train.resume` continues an interrupted run. A damaged or incomplete run
directory raises :class:`RunDirError` (a ``ValueError``) with one line naming the file.
"""
from __future__ import annotations

import json
import os
import pickletools
import re
import zipfile
from dataclasses import dataclass
from typing import Callable

from . import jax as jax_trainer
from .algos import BACKENDS, LEGACY_LIBRARY

__all__ = ["default_run_dir", "RUNNING", "INTERRUPTED", "COMPLETE", "CHECKPOINT", "RunDirError", "RunFiles",
           "read_run_config", "run_files", "ResumePoint", "resume_point", "clear_run", "write_json_atomic",
           "save_atomic", "load_or_refuse"]


def default_run_dir(env: str, algo: str, multi_agent: bool, seed: int) -> str:
    """``runs/<env>_<algo>[_ma]_s<seed>`` (``env`` a name, or a constructor's ``__name__``)."""
    name = env if isinstance(env, str) else getattr(env, "__name__", "env")
    name = name.replace("/", "_").replace(":", "_")
    return os.path.join("runs", f"{name}_{algo}{'_ma' if multi_agent else ''}_s{seed}")


#: ``config.json`` ``status`` of a run directory: written ``running`` when training starts,
#: ``interrupted`` when a SIGINT stopped it (model and normaliser saved), ``complete`` at the end
#: (runs written before the field existed are complete).
RUNNING, INTERRUPTED, COMPLETE = "running", "interrupted", "complete"
#: a checkpoint's file name, ``<algo>_<sb3 steps>_steps.zip`` (SB3's ``CheckpointCallback``)
CHECKPOINT = re.compile(r"^(?P<algo>[a-z0-9]+)_(?P<steps>\d+)_steps\.zip$")


class RunDirError(ValueError):
    """A run directory that is missing, incomplete or corrupt."""


def clear_run(out: str) -> None:
    """Remove the files of a previous run in ``out`` (a new run replaces it: none of its models,
    normalisers or checkpoints may be mistaken for the new run's, e.g. by :func:`agents.training.train.resume`)."""
    for f in ("config.json", "model.zip", "vecnormalize.pkl", "replay_buffer.pkl", "curve.json", "train_curve.json",
              *jax_trainer.POLICY_FILES):
        if os.path.isfile(os.path.join(out, f)):
            os.remove(os.path.join(out, f))
    ck = os.path.join(out, "checkpoints")
    if os.path.isdir(ck):
        for f in os.listdir(ck):
            if re.match(r"^[a-z0-9]+_(?:(?:vecnormalize|replay_buffer)_)?\d+_steps\.(?:zip|pkl)$", f):
                os.remove(os.path.join(ck, f))


def write_json_atomic(path: str, obj: dict) -> None:
    """Write ``obj`` to ``path`` atomically (a torn config.json is never left behind)."""
    with open(path + ".tmp", "w") as fh:
        json.dump(obj, fh, indent=2, default=str)
    os.replace(path + ".tmp", path)


def save_atomic(save: Callable[[str], None], path: str) -> None:
    """``save(path + ".tmp")`` then rename it to ``path`` (a model or pickle is never left half-written;
    the suffix also keeps SB3's ``model.save`` from appending ``.zip``)."""
    save(path + ".tmp")
    os.replace(path + ".tmp", path)


def load_or_refuse(path: str, load: Callable):
    """``load()``, or a :class:`RunDirError` naming ``path`` when the file cannot be read (corrupt, truncated)."""
    try:
        return load()
    except RunDirError:  # already one line naming the file (e.g. agents.training.run_pickles.PickleRefused)
        raise
    except Exception as exc:  # noqa: BLE001 -- a damaged zip/pickle fails anywhere in zipfile/torch/pickle
        raise RunDirError(f"{path} cannot be loaded (corrupt or truncated file? {type(exc).__name__}: "
                          f"{_first_line(exc)})") from exc


def _first_line(exc: BaseException, limit: int = 200) -> str:
    """The first line of ``exc``'s message, at most ``limit`` characters (for one-line errors)."""
    text = (str(exc).strip().splitlines() or [""])[0]
    return text if len(text) <= limit else text[:limit] + "..."


@dataclass(frozen=True)
class RunFiles:
    """The files of a saved agent: its run directory, ``config.json``, the model (``model.zip`` or a
    checkpoint) and the normaliser saved with it (None when the run does not normalise)."""
    run_dir: str
    config: dict
    model: str
    vecnormalize: str | None


def _run_dir_of(path: str) -> tuple[str, str | None]:
    """``(run directory, checkpoint file or None)`` of a path naming a run directory, its
    ``model.zip`` or a checkpoint ``<run>/checkpoints/<algo>_<steps>_steps.zip``."""
    path = str(path)
    if os.path.isfile(path) and CHECKPOINT.match(os.path.basename(path)):
        ck_dir = os.path.dirname(os.path.abspath(path))
        if os.path.basename(ck_dir) == "checkpoints":
            return os.path.dirname(ck_dir), path
    path = path[:-len("model.zip")] if path.endswith("model.zip") else path
    return path.rstrip("/") or ".", None


def read_run_config(path: str, *, require_model: bool = True) -> dict:
    """``config.json`` of a run directory (or of the directory holding ``model.zip`` or the
    checkpoint ``path``), validated; with ``require_model``, the model file must exist too.

    The run's ``algo`` must have a backend (:data:`agents.training.algos.BACKENDS`) implemented by the
    ``library`` the run records (:data:`agents.training.algos.LEGACY_LIBRARY` when it records none); whether
    that library is installed is checked when the model is loaded (:func:`agents.training.algos.backend_of`)."""
    run, ckpt = _run_dir_of(path)
    if not os.path.isdir(run):
        raise RunDirError(f"run directory {run!r} does not exist (expected the --out of a training run)")
    cfg_path = os.path.join(run, "config.json")
    if not os.path.isfile(cfg_path):
        raise RunDirError(f"{run!r} is not a run directory: config.json is missing")
    try:
        with open(cfg_path) as fh:
            cfg = json.load(fh)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RunDirError(f"{cfg_path} is not valid JSON: {exc}") from None
    missing = [k for k in ("env", "algo", "multi_agent") if k not in cfg] if isinstance(cfg, dict) else ["all keys"]
    if missing:
        raise RunDirError(f"{cfg_path} lacks {missing}")
    if cfg.get("trainer") == jax_trainer.TRAINER:  # a jitted run: its exported policy is its model
        if cfg["algo"] not in jax_trainer.ALGOS or cfg.get("library") != jax_trainer.LIBRARY:
            raise RunDirError(f"{cfg_path}: a jitted run of {cfg['algo']!r} by {cfg.get('library')!r}; the jitted "
                              f"trainer here is {jax_trainer.LIBRARY!r} with {list(jax_trainer.ALGOS)}")
        absent = [f for f in jax_trainer.POLICY_FILES if not os.path.isfile(os.path.join(run, f))]
        if ckpt is not None:
            raise RunDirError(f"{run!r} is a jitted run: it has no checkpoints (give the run directory)")
        if require_model and absent:
            raise RunDirError(f"{run!r} is not a finished jitted run: {absent} missing")
        return cfg
    if not isinstance(cfg["algo"], str) or cfg["algo"] not in BACKENDS:
        raise RunDirError(f"{cfg_path}: unknown algo {cfg['algo']!r}")
    library, implementations = cfg.get("library", LEGACY_LIBRARY), [b.library for b in BACKENDS[cfg["algo"]]]
    if library not in implementations:
        raise RunDirError(f"{cfg_path}: the run was trained with {library!r}; {cfg['algo']!r} is implemented here "
                          f"by {' or '.join(map(repr, implementations))}")
    if require_model and ckpt is None and not os.path.isfile(os.path.join(run, "model.zip")):
        hint = ""
        if cfg.get("status") == RUNNING:
            hint = " (training was stopped before it saved a model: resume it with --resume, or evaluate a " \
                   "checkpoint, <run>/checkpoints/<algo>_<steps>_steps.zip)"
        raise RunDirError(f"{run!r} is not a finished run directory: model.zip is missing{hint}")
    return cfg


def run_files(path: str) -> RunFiles:
    """The files :func:`agents.training.loading.load_agent` reads for ``path`` (a run directory, its ``model.zip``
    or a checkpoint)."""
    cfg = read_run_config(path)
    run, ckpt = _run_dir_of(path)
    norm = bool(cfg.get("normalize")) or (ckpt is None and os.path.exists(os.path.join(run, "vecnormalize.pkl")))
    if ckpt is None:
        model, vn = os.path.join(run, "model.zip"), os.path.join(run, "vecnormalize.pkl")
    else:
        m = CHECKPOINT.match(os.path.basename(ckpt))
        if m["algo"] != cfg["algo"]:
            raise RunDirError(f"{ckpt!r} is a {m['algo']} checkpoint, the run trains {cfg['algo']}")
        model = ckpt
        vn = os.path.join(os.path.dirname(ckpt), f"{m['algo']}_vecnormalize_{m['steps']}_steps.pkl")
    if norm and not os.path.isfile(vn):
        raise RunDirError(f"{model!r} has no normaliser ({vn} is missing)")
    return RunFiles(run, cfg, model, vn if norm else None)


@dataclass(frozen=True)
class ResumePoint:
    """The latest save of a run: ``model`` (a .zip), its normaliser and replay buffer (None when
    absent) and the SB3 timesteps it holds."""
    model: str
    vecnormalize: str | None
    replay_buffer: str | None
    sb3_timesteps: int


def _complete_pickle(path: str) -> bool:
    """Whether ``path`` holds a whole pickle (its opcodes parsed up to STOP, nothing executed): a kill
    during SB3's in-place save leaves an empty or truncated normaliser."""
    try:
        with open(path, "rb") as fh:
            for _ in pickletools.genops(fh):
                pass
        return True
    except (OSError, ValueError, EOFError):
        return False


def resume_point(path: str, cfg: dict | None = None) -> ResumePoint:
    """Where :func:`agents.training.train.resume` continues the run in ``path``: the later of ``model.zip`` (saved
    on an interrupt; ``config.json`` ``model_sb3_timesteps``) and the last complete checkpoint (a valid
    zip, with its normaliser when the run normalises). Raises :class:`RunDirError` for a complete
    run or one with no save."""
    cfg = read_run_config(path, require_model=False) if cfg is None else cfg
    total = int(cfg.get("timesteps", 0)) * int(cfg.get("n_agents", 1))
    status = cfg.get("status", COMPLETE)
    if status == COMPLETE or int(cfg.get("sb3_timesteps", 0)) >= total > 0:
        raise RunDirError(f"{path!r} is a complete run ({cfg.get('timesteps')} env steps): nothing to resume; "
                          f"train with --overwrite to replace it or choose another --out")
    norm = bool(cfg.get("normalize"))
    points = []
    model = os.path.join(path, "model.zip")
    if cfg.get("model_sb3_timesteps") is not None and os.path.isfile(model):  # saved on an interrupt
        rb = os.path.join(path, "replay_buffer.pkl")
        points.append(ResumePoint(model, os.path.join(path, "vecnormalize.pkl") if norm else None,
                                  rb if os.path.isfile(rb) else None, int(cfg["model_sb3_timesteps"])))
    ck = os.path.join(path, "checkpoints")
    for f in sorted(os.listdir(ck)) if os.path.isdir(ck) else []:
        m = CHECKPOINT.match(f)
        if m and m["algo"] == cfg["algo"]:
            n = int(m["steps"])
            vn = os.path.join(ck, f"{cfg['algo']}_vecnormalize_{n}_steps.pkl") if norm else None
            points.append(ResumePoint(os.path.join(ck, f), vn, None, n))
    # a kill can cut a checkpoint short: SB3 writes the model, then the normaliser, in place
    complete = [p for p in points if zipfile.is_zipfile(p.model)
                and (p.vecnormalize is None or _complete_pickle(p.vecnormalize))]
    if not complete:
        raise RunDirError(f"{path!r} has nothing to resume from (no model.zip of an interrupted run, no complete "
                          f"checkpoints/{cfg['algo']}_<steps>_steps.zip" + (" with its normaliser)" if norm else ")"))
    return max(complete, key=lambda p: (p.sb3_timesteps, p.replay_buffer is not None))
