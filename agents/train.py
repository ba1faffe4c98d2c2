"""The import path of the training entry points before issue 38 (``from agents.train import train``, and the
names this module re-exported for users' scripts); they live in :mod:`agents.training` (:mod:`~agents.training.train`,
:mod:`~agents.training.loading`, :mod:`~agents.training.recipes`, :mod:`~agents.training.runs`,
:mod:`~agents.training.env_factory`)."""
from .training.env_factory import build_vec_env, core_of
from .training.loading import TrainedAgent, load_agent
from .training.recipes import Recipe, recipe_from_hyperparams, resolve_recipe
from .training.runs import (COMPLETE, INTERRUPTED, RUNNING, ResumePoint, RunDirError, RunFiles, default_run_dir,
                            read_run_config, resume_point, run_files)
from .training.train import TqdmCallback, TrainingInterrupted, TrainResult, resume, set_threads, train

__all__ = ["train", "resume", "resume_point", "load_agent", "TrainedAgent", "TrainingInterrupted", "RunDirError",
           "read_run_config", "run_files", "build_vec_env", "core_of", "TqdmCallback", "set_threads",
           "Recipe", "resolve_recipe", "recipe_from_hyperparams", "TrainResult", "default_run_dir", "RunFiles",
           "ResumePoint", "RUNNING", "INTERRUPTED", "COMPLETE"]
