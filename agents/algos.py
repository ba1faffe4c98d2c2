"""The algorithm backends: which library and class implement each algorithm name.

This module is the one place that knows which library trains ``"ppo"``, ``"sac"`` and
``"td3"``: the class lookup, the constructor arguments made from a :class:`agents.recipes.Recipe`,
the logger a model gets, how a model is saved and loaded, and the library name and version that
:func:`agents.train.train` records in a run's ``config.json`` (``library``, ``library_version``).

Every backend here is Stable-Baselines3 (torch). The rest of ``agents/`` relies only on the
Stable-Baselines3 model API (``learn``, ``predict``, ``num_timesteps``, ``set_random_seed``,
``save_replay_buffer`` / ``load_replay_buffer``, ``observation_space`` / ``action_space``) and on
SB3's common layer (``VecEnv``, ``VecNormalize``, callbacks), which sb3-contrib and SBX (Stable
Baselines Jax) implement and share as well.

Adding an implementation
------------------------
One :class:`AlgoBackend` in :data:`BACKENDS`, e.g. sb3-contrib's TQC::

    AlgoBackend("tqc", library="sb3-contrib", module="sb3_contrib", class_name="TQC")

or SBX's CrossQ (a Jax library: activation names become flax functions, so it needs a
``flax_policy_kwargs`` written next to :func:`torch_policy_kwargs`)::

    AlgoBackend("crossq", library="sbx-rl", module="sbx", class_name="CrossQ", policy_kwargs=flax_policy_kwargs)

plus its recipe file ``agents/hyperparams/<name>.yaml`` and the name in
:data:`agents.config.ALGOS` (and :data:`agents.config.MULTI_AGENT_ALGOS` when it may be
parameter-shared). Names are lowercase letters and digits: they appear in the checkpoint
file names ``<name>_<steps>_steps.zip``. A run directory is loaded by the backend of its
``config.json`` ``algo`` only if the ``library`` recorded there is that backend's (runs
written before the field existed were trained with :data:`LEGACY_LIBRARY`), so a change of
implementation never silently loads a model with another library.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import re
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .config import ACTIVATIONS

if TYPE_CHECKING:
    from .recipes import Recipe

__all__ = ["AlgoBackend", "BACKENDS", "LEGACY_LIBRARY", "backend", "schedule", "torch_policy_kwargs",
           "SCHEDULE_KEYS"]

#: the library of every run whose ``config.json`` records none (written before ``library`` was recorded)
LEGACY_LIBRARY = "stable-baselines3"

#: constructor arguments that may be rl-zoo3 schedule strings (``lin_<x>``)
SCHEDULE_KEYS = ("learning_rate", "clip_range")


def schedule(value):
    """rl-zoo3's schedule strings: ``"lin_3e-4"`` is a linear decay from 3e-4 to 0 over training.

    Parameters
    ----------
    value : a constructor argument of the recipe (``float`` or ``"lin_<number>"``).

    Returns
    -------
    ``value`` unchanged, or for ``lin_<v0>`` the callable ``progress_remaining -> progress_remaining * v0``
    (the schedule convention of Stable-Baselines3 and the libraries built on it).
    """
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            v0 = float(value[4:])
        except ValueError:
            raise ValueError(f"schedule {value!r} must be 'lin_<number>', e.g. 'lin_3e-4'") from None
        return lambda progress_remaining: progress_remaining * v0
    return value


def torch_policy_kwargs(pk: dict | None) -> dict:
    """A recipe's ``policy_kwargs`` for a torch policy: ``activation_fn`` named (``"tanh"``,
    :data:`agents.config.ACTIVATIONS`) becomes the ``torch.nn`` class (``nn.Tanh``)."""
    import torch.nn as nn

    pk = dict(pk or {})
    act = pk.get("activation_fn")
    if isinstance(act, str):
        name = ACTIVATIONS.get(act.lower())
        if name is None:
            raise ValueError(f"unknown activation_fn {act!r}; choose from {sorted(ACTIVATIONS)}")
        pk["activation_fn"] = getattr(nn, name)
    return pk


@dataclass(frozen=True)
class AlgoBackend:
    """The implementation of one algorithm name: ``module.class_name`` of the installed ``library``.

    Attributes
    ----------
    name : the algorithm's name in recipes, ``config.json`` ``algo`` and checkpoint file names.
    library : the distribution (``pip`` name) that implements it, recorded in ``config.json``.
    module, class_name : where the algorithm's class is (imported on first use, not with this module).
    policy_kwargs : the recipe's ``policy_kwargs`` (activation names) -> the class's
        (:func:`torch_policy_kwargs` for torch libraries).
    """

    name: str
    library: str
    module: str
    class_name: str
    policy_kwargs: Callable[[dict | None], dict] = torch_policy_kwargs

    def __post_init__(self):
        if not re.fullmatch(r"[a-z0-9]+", self.name):
            raise ValueError(f"algorithm name {self.name!r}: lowercase letters and digits only "
                             f"(checkpoint files are <name>_<steps>_steps.zip)")

    def load_class(self):
        """The algorithm's class (imports ``module``)."""
        return getattr(importlib.import_module(self.module), self.class_name)

    def library_version(self) -> str:
        """The installed version of :attr:`library` (its ``__version__`` when it has no package metadata)."""
        try:
            return importlib.metadata.version(self.library)
        except importlib.metadata.PackageNotFoundError:
            return str(getattr(importlib.import_module(self.module.split(".")[0]), "__version__", "unknown"))

    def provenance(self) -> dict:
        """What ``config.json`` records about the implementation: ``{"library", "library_version"}``."""
        return {"library": self.library, "library_version": self.library_version()}

    def constructor_kwargs(self, recipe: Recipe, venv) -> dict:
        """The class's keyword arguments from ``recipe.algo_kwargs``: ``policy_kwargs`` translated,
        ``lin_`` schedules made callables, Gaussian action noise of ``recipe.action_noise_sigma``
        on ``venv``'s action space."""
        from stable_baselines3.common.noise import NormalActionNoise

        algo_kw = dict(recipe.algo_kwargs)
        algo_kw["policy_kwargs"] = self.policy_kwargs(algo_kw.get("policy_kwargs"))
        for key in SCHEDULE_KEYS:
            if key in algo_kw:
                algo_kw[key] = schedule(algo_kw[key])
        if recipe.action_noise_sigma is not None:
            d = venv.action_space.shape[0]
            algo_kw["action_noise"] = NormalActionNoise(np.zeros(d), recipe.action_noise_sigma * np.ones(d))
        return algo_kw

    def make(self, recipe: Recipe, venv, *, seed: int, verbose: int = 0, tensorboard: str | None = None):
        """A new model of ``recipe`` on ``venv`` (an unknown constructor argument raises the class's
        ``TypeError ... unexpected keyword argument``)."""
        return self.load_class()(recipe.policy, venv, seed=seed, verbose=verbose, tensorboard_log=tensorboard,
                                 **self.constructor_kwargs(recipe, venv))

    def load(self, path: str, *, device: str = "cpu", **kwargs):
        """The model saved in ``path``; ``kwargs`` as for SB3's ``load`` (``env`` to continue training on,
        ``custom_objects`` from :meth:`custom_objects`, attributes such as ``verbose``)."""
        return self.load_class().load(path, device=device, **kwargs)

    def custom_objects(self, recipe: Recipe, venv) -> dict:
        """The saved attributes :meth:`load` must rebuild from ``recipe`` when training continues: the
        schedules (saved as closures, not unpickled)."""
        kw = self.constructor_kwargs(recipe, venv)
        return {k: kw[k] for k in SCHEDULE_KEYS if k in kw}

    def save(self, model, path: str) -> None:
        """Save ``model`` to exactly ``path`` (give it a suffix: SB3 appends ``.zip`` to a path without one)."""
        model.save(path)

    def quiet_logger(self, model) -> None:
        """Without TensorBoard, give the model a logger that writes nowhere but stdout (``verbose >= 1``):
        SB3's default creates an empty ``SB3-<date>`` directory in the temp dir for every run."""
        if getattr(model, "tensorboard_log", None) is not None:
            return  # SB3 logs into the TensorBoard directory (no temp directory)
        from stable_baselines3.common.logger import HumanOutputFormat, Logger

        model.set_logger(Logger(folder=None,
                                output_formats=[HumanOutputFormat(sys.stdout)] if model.verbose >= 1 else []))


#: the implementation of each algorithm name (the names of :data:`agents.config.ALGOS`)
BACKENDS: dict[str, AlgoBackend] = {b.name: b for b in (
    AlgoBackend("ppo", library="stable-baselines3", module="stable_baselines3", class_name="PPO"),
    AlgoBackend("sac", library="stable-baselines3", module="stable_baselines3", class_name="SAC"),
    AlgoBackend("td3", library="stable-baselines3", module="stable_baselines3", class_name="TD3"),
)}


def backend(algo: Any) -> AlgoBackend:
    """The :class:`AlgoBackend` of the algorithm name ``algo`` (any case); ``ValueError`` for an unknown one."""
    b = BACKENDS.get(algo.lower()) if isinstance(algo, str) else None
    if b is None:
        raise ValueError(f"unknown algorithm {algo!r}; choose from {sorted(BACKENDS)}")
    return b
