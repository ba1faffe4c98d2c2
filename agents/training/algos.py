"""The algorithm backends: which library and class implement each algorithm name.

This module is the one place that knows which library trains ``"ppo"``, ``"sac"``, ``"td3"`` and
``"crossq"``: the class lookup, the constructor arguments made from a :class:`agents.training.recipes.Recipe`
(action noise included), the logger a model gets, how a model is saved and loaded, and the library
name and version that :func:`agents.training.train.train` records in a run's ``config.json`` (``library``,
``library_version``).

Implementations (:data:`BACKENDS`, in order of preference; chosen by measurement,
``benchmarks/offpolicy_throughput.py``):

- ``ppo``: Stable-Baselines3 (torch);
- ``sac``, ``td3``: SBX (Stable Baselines Jax, ``sbx-rl``, the ``jax`` extra), else Stable-Baselines3;
- ``crossq``: SBX, else sb3-contrib (torch).

:func:`backend` gives the first implementation whose library imports; when the preferred one does
not, the process prints one line on stderr (once) naming the extra that installs it. A run is
loaded and resumed by the implementation its ``config.json`` records (:func:`backend_of`; runs
written before the field existed were trained with :data:`LEGACY_LIBRARY`), never by another
library; a run of a library that is not installed raises :class:`BackendUnavailable` naming the
extra to install.

The rest of ``agents/`` relies only on the Stable-Baselines3 model API (``learn``, ``predict``,
``num_timesteps``, ``set_random_seed``, ``save_replay_buffer`` / ``load_replay_buffer``,
``observation_space`` / ``action_space``) and on SB3's common layer (``VecEnv``, ``VecNormalize``,
callbacks, action noise), which sb3-contrib and SBX implement and share.

Adding an implementation
------------------------
One :class:`AlgoBackend` in :data:`BACKENDS`, e.g. sb3-contrib's TQC::

    AlgoBackend("tqc", library="sb3-contrib", module="sb3_contrib", class_name="TQC")

plus its recipe file ``agents/config/hyperparams/<name>.yaml`` and the name in
:data:`agents.config.hyperparam_files.ALGOS` (and :data:`agents.config.hyperparam_files.MULTI_AGENT_ALGOS` when it may
be parameter-shared). Names are lowercase letters and digits: they appear in the checkpoint file names
``<name>_<steps>_steps.zip``.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import re
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..config.hyperparam_files import ACTIVATIONS, NOISE_TYPES, OFF_POLICY_ALGOS

if TYPE_CHECKING:
    from .recipes import Recipe

__all__ = ["AlgoBackend", "BACKENDS", "LEGACY_LIBRARY", "BackendUnavailable", "backend", "backend_of",
           "schedule", "torch_policy_kwargs", "flax_policy_kwargs", "make_action_noise", "SCHEDULE_KEYS"]

#: the library of every run whose ``config.json`` records none (written before ``library`` was recorded)
LEGACY_LIBRARY = "stable-baselines3"

#: constructor arguments that may be rl-zoo3 schedule strings (``lin_<x>``)
SCHEDULE_KEYS = ("learning_rate", "clip_range")


class BackendUnavailable(ValueError):
    """The library that implements an algorithm (or that trained a run) is not installed; the message
    names the ``pip`` extra that installs it."""


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


def _activation_name(act: str) -> str:
    name = ACTIVATIONS.get(act.lower())
    if name is None:
        raise ValueError(f"unknown activation_fn {act!r}; choose from {sorted(ACTIVATIONS)}")
    return name


def torch_policy_kwargs(pk: dict | None) -> dict:
    """A recipe's ``policy_kwargs`` for a torch policy: ``activation_fn`` named (``"tanh"``,
    :data:`agents.config.hyperparam_files.ACTIVATIONS`) becomes the ``torch.nn`` class (``nn.Tanh``)."""
    import torch.nn as nn

    pk = dict(pk or {})
    act = pk.get("activation_fn")
    if isinstance(act, str):
        pk["activation_fn"] = getattr(nn, _activation_name(act))
    return pk


def flax_policy_kwargs(pk: dict | None) -> dict:
    """A recipe's ``policy_kwargs`` for a Jax (flax) policy of SBX: ``activation_fn`` named (``"relu"``)
    becomes the ``flax.linen`` function (``flax.linen.relu``; the same function as ``torch.nn.ReLU``)."""
    import flax.linen as fnn

    pk = dict(pk or {})
    act = pk.get("activation_fn")
    if isinstance(act, str):
        _activation_name(act)  # the same names as for torch
        pk["activation_fn"] = getattr(fnn, act.lower())
    return pk


def _episode_length(venv, default: int = 1000) -> int:
    """Steps of one training episode of ``venv`` (the batched core's ``max_cycles``, a Gymnasium
    ``TimeLimit``'s ``max_episode_steps``), ``default`` when it has none."""
    inner = venv.unwrapped if hasattr(venv, "unwrapped") else venv
    core = getattr(inner, "core", None)
    n = getattr(core, "max_cycles", None)
    if n is None:
        try:
            spec = venv.get_attr("spec", [0])[0]
            n = getattr(spec, "max_episode_steps", None)
        except Exception:  # noqa: BLE001 -- a VecEnv without Gymnasium specs
            n = None
    return int(n) if n is not None and np.isfinite(n) and n > 0 else int(default)


def make_action_noise(noise_type: str, sigma: float, venv, seed: int | None = None):
    """The exploration noise ``noise_type`` of :data:`agents.config.hyperparam_files.NOISE_TYPES` (added to the actions
    of TD3 / SAC / CrossQ, in the agent's action units), one independent process per environment copy of ``venv``.

    - ``normal``: white Gaussian noise ``N(0, sigma^2)`` per step (SB3's ``NormalActionNoise``);
    - ``ornstein-uhlenbeck``: SB3's ``OrnsteinUhlenbeckActionNoise`` (``theta = 0.15``, ``dt = 0.01``:
      correlation time ~ 1 / (theta dt) = 667 steps; stationary std ``sigma / sqrt(2 theta dt)``, about
      18 ``sigma``) -- rl-zoo3's ``ornstein-uhlenbeck``;
    - ``pink``: pink (1/f) noise of std ``sigma`` (Eberhard et al., ICLR 2023; ``pink-noise-rl``'s
      ``PinkActionNoise``), one signal per episode of the env (``seq_len`` = episode length), reset at the
      end of every episode. Not an rl-zoo3 noise type: accepted in overrides and agents-only sections.

    Returns an SB3 ``ActionNoise`` (a ``VectorizedActionNoise`` when ``venv`` has several copies).
    """
    from stable_baselines3.common.noise import (NormalActionNoise, OrnsteinUhlenbeckActionNoise,
                                                VectorizedActionNoise)

    if noise_type not in NOISE_TYPES:
        raise ValueError(f"noise_type must be one of {NOISE_TYPES}, got {noise_type!r}")
    d, n = venv.action_space.shape[0], venv.num_envs
    zeros, sig = np.zeros(d), float(sigma) * np.ones(d)
    if noise_type == "normal":
        one = lambda i: NormalActionNoise(zeros, sig)  # noqa: E731
    elif noise_type == "ornstein-uhlenbeck":
        one = lambda i: OrnsteinUhlenbeckActionNoise(zeros, sig)  # noqa: E731
    else:
        try:
            from pink import PinkActionNoise
        except ImportError:
            raise BackendUnavailable("noise_type 'pink' needs the pink-noise-rl package of the rl extra: "
                                     "pip install 'dobs-envs[rl]'") from None
        seq_len, ss = _episode_length(venv), np.random.SeedSequence(seed)
        rngs = [np.random.default_rng(s) for s in ss.spawn(n)]
        one = lambda i: PinkActionNoise(float(sigma), seq_len, d, rng=rngs[i])  # noqa: E731
    if n == 1:
        return one(0)
    vec = VectorizedActionNoise(one(0), n)  # its copies of one process would be identical (pink: same rng state)
    vec.noises = [one(i) for i in range(n)]
    return vec


_NOTICES: set = set()


def _notice(text: str) -> None:
    """``text`` on stderr, once per process (all fallbacks share one notice)."""
    if not _NOTICES:
        print(f"dobs-envs: {text}", file=sys.stderr, flush=True)
    _NOTICES.add(text)


@dataclass(frozen=True)
class AlgoBackend:
    """The implementation of one algorithm name: ``module.class_name`` of the installed ``library``.

    Attributes
    ----------
    name : the algorithm's name in recipes, ``config.json`` ``algo`` and checkpoint file names.
    library : the distribution (``pip`` name) that implements it, recorded in ``config.json``.
    module, class_name : where the algorithm's class is (imported on first use, not with this module).
    policy_kwargs : the recipe's ``policy_kwargs`` (activation names) -> the class's
        (:func:`torch_policy_kwargs` for torch libraries, :func:`flax_policy_kwargs` for SBX).
    extra : the ``dobs-envs`` extra that installs ``library``.
    """

    name: str
    library: str
    module: str
    class_name: str
    policy_kwargs: Callable[[dict | None], dict] = torch_policy_kwargs
    extra: str = "rl"

    def __post_init__(self):
        if not re.fullmatch(r"[a-z0-9]+", self.name):
            raise ValueError(f"algorithm name {self.name!r}: lowercase letters and digits only "
                             f"(checkpoint files are <name>_<steps>_steps.zip)")

    def load_class(self):
        """The algorithm's class (imports ``module``)."""
        return getattr(importlib.import_module(self.module), self.class_name)

    def unavailable(self) -> str | None:
        """Why :attr:`module` cannot be imported (``"ModuleNotFoundError: ..."``), None when it can."""
        try:
            self.load_class()
        except Exception as exc:  # noqa: BLE001 -- a broken Jax install fails with other errors than ImportError
            return f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0][:160]}"
        return None

    def install_hint(self) -> str:
        return f"pip install 'dobs-envs[{self.extra}]'"

    def library_version(self) -> str:
        """The installed version of :attr:`library` (its ``__version__`` when it has no package metadata)."""
        try:
            return importlib.metadata.version(self.library)
        except importlib.metadata.PackageNotFoundError:
            return str(getattr(importlib.import_module(self.module.split(".")[0]), "__version__", "unknown"))

    def provenance(self) -> dict:
        """What ``config.json`` records about the implementation: ``{"library", "library_version"}``."""
        return {"library": self.library, "library_version": self.library_version()}

    def constructor_kwargs(self, recipe: Recipe, venv, seed: int | None = None) -> dict:
        """The class's keyword arguments from ``recipe.algo_kwargs``: ``policy_kwargs`` translated,
        ``lin_`` schedules made callables, the recipe's action noise (:func:`make_action_noise`, seeded
        by ``seed``) on ``venv``'s action space."""
        algo_kw = dict(recipe.algo_kwargs)
        algo_kw["policy_kwargs"] = self.policy_kwargs(algo_kw.get("policy_kwargs"))
        for key in SCHEDULE_KEYS:
            if key in algo_kw:
                algo_kw[key] = schedule(algo_kw[key])
        if recipe.action_noise_sigma is not None and venv is not None:  # None: loading for evaluation
            algo_kw["action_noise"] = make_action_noise(recipe.action_noise_type or "normal",
                                                        recipe.action_noise_sigma, venv, seed)
        return algo_kw

    def make(self, recipe: Recipe, venv, *, seed: int, verbose: int = 0, tensorboard: str | None = None):
        """A new model of ``recipe`` on ``venv`` (an unknown constructor argument raises the class's
        ``TypeError ... unexpected keyword argument``)."""
        return self.load_class()(recipe.policy, venv, seed=seed, verbose=verbose, tensorboard_log=tensorboard,
                                 **self.constructor_kwargs(recipe, venv, seed))

    def load(self, path: str, *, device: str = "cpu", **kwargs):
        """The model saved in ``path``; ``kwargs`` as for SB3's ``load`` (``env`` to continue training on,
        ``custom_objects`` (:meth:`load_run_model` gives them), attributes such as ``verbose``)."""
        return self.load_class().load(path, device=device, **kwargs)

    def rebuilt_objects(self, recipe: Recipe, venv=None) -> dict:
        """The attributes of a saved model that JSON cannot hold, rebuilt from ``recipe`` (its run's ``config.json``)
        instead of unpickled from ``model.zip`` (:func:`agents.training.run_pickles.model_custom_objects`): the policy
        class of ``recipe.policy``, ``policy_kwargs``, the schedules, the recipe's buffer classes and
        action noise (on ``venv``; None without one: evaluation draws no noise). ``lr_schedule`` is None: SB3
        derives it from ``learning_rate`` when the model is set up."""
        kw = self.constructor_kwargs(recipe, venv)
        cls = self.load_class()
        policy = cls.policy_aliases.get(recipe.policy) if isinstance(recipe.policy, str) else None
        if policy is None:
            raise ValueError(f"{self.class_name} has no policy {recipe.policy!r} (it has {sorted(cls.policy_aliases)})")
        import inspect

        defaults = {k: p.default for k, p in inspect.signature(cls.__init__).parameters.items()
                    if p.default is not inspect.Parameter.empty}  # what SB3 saved when the recipe gave none
        keys = ("policy_kwargs", "learning_rate", "clip_range", "clip_range_vf", "rollout_buffer_class",
                "rollout_buffer_kwargs", "replay_buffer_class", "replay_buffer_kwargs", "action_noise")
        return {"policy_class": policy, "lr_schedule": None, **{k: kw[k] if k in kw else defaults.get(k) for k in keys}}

    def load_run_model(self, path: str, recipe: Recipe, *, venv=None, device: str = "cpu", **kwargs):
        """The model saved in ``path`` by a run of ``recipe``, nothing unpickled but plain data
        (:func:`agents.training.run_pickles.model_custom_objects`; raises
        :class:`agents.training.run_pickles.PickleRefused` for a payload it does not rebuild); ``venv``, ``kwargs`` as
        for :meth:`load`."""
        from .run_pickles import graft_sbx, model_custom_objects, sbx_payloads

        custom = model_custom_objects(path, self.rebuilt_objects(recipe, venv), library=self.library)
        payloads = sbx_payloads(path) if self.library == "sbx-rl" else {}  # read before anything is built
        if venv is not None:
            kwargs["env"] = venv
        model = self.load(path, device=device, custom_objects=custom, **kwargs)
        if payloads:
            graft_sbx(model, path, payloads, optimizer=venv is not None)
        return model

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


def _sb3(name: str, cls: str) -> AlgoBackend:
    return AlgoBackend(name, library="stable-baselines3", module="stable_baselines3", class_name=cls)


def _sbx(name: str, cls: str) -> AlgoBackend:
    return AlgoBackend(name, library="sbx-rl", module="sbx", class_name=cls, policy_kwargs=flax_policy_kwargs,
                       extra="jax")


#: the implementations of each algorithm name (the names of :data:`agents.config.hyperparam_files.ALGOS`), preferred
#: first. SBX first for the off-policy algorithms: measured side by side on tracking
#: (benchmarks/offpolicy_throughput.py; figures in the README and the recipe files).
BACKENDS: dict[str, tuple[AlgoBackend, ...]] = {
    "ppo": (_sb3("ppo", "PPO"),),
    "sac": (_sbx("sac", "SAC"), _sb3("sac", "SAC")),
    "td3": (_sbx("td3", "TD3"), _sb3("td3", "TD3")),
    "crossq": (_sbx("crossq", "CrossQ"),
               AlgoBackend("crossq", library="sb3-contrib", module="sb3_contrib", class_name="CrossQ")),
}
assert set(OFF_POLICY_ALGOS) <= set(BACKENDS)


def _check_name(algo: Any) -> str:
    if not isinstance(algo, str) or algo.lower() not in BACKENDS:
        raise ValueError(f"unknown algorithm {algo!r}; choose from {sorted(BACKENDS)}")
    return algo.lower()


def backend(algo: Any) -> AlgoBackend:
    """The :class:`AlgoBackend` that trains the algorithm ``algo`` (any case): the first of
    ``BACKENDS[algo]`` whose library imports. A fallback prints one line on stderr (once per
    process) naming the missing library and its extra. ``ValueError`` for an unknown name;
    :class:`BackendUnavailable` when no implementation imports."""
    choices = BACKENDS[_check_name(algo)]
    reasons = []
    for b in choices:
        why = b.unavailable()
        if why is None:
            if reasons:
                first = choices[0]
                _notice(f"{first.library} is not importable ({reasons[0]}); {b.name} trains with {b.library} "
                        f"instead ({first.install_hint()} for {first.library})")
            return b
        reasons.append(why)
    raise BackendUnavailable(f"no implementation of {algo!r} can be imported: "
                             + "; ".join(f"{b.library} ({r}; {b.install_hint()})" for b, r in zip(choices, reasons)))


def backend_of(algo: Any, library: str | None) -> AlgoBackend:
    """The implementation of ``algo`` by ``library`` (a run's ``config.json`` ``algo`` and ``library``;
    None: :data:`LEGACY_LIBRARY`). ``ValueError`` when no backend of ``algo`` is that library (the
    message starts ``trained with '<library>'``); :class:`BackendUnavailable` (one line, naming the
    extra to install) when it is known but not importable."""
    library = LEGACY_LIBRARY if library is None else library
    for b in BACKENDS[_check_name(algo)]:
        if b.library == library:
            why = b.unavailable()
            if why is not None:
                raise BackendUnavailable(f"the run was trained with {library!r}, which cannot be imported here "
                                         f"({why}): {b.install_hint()}")
            return b
    raise ValueError(f"trained with {library!r}; {algo!r} is implemented here by "
                     f"{' or '.join(repr(b.library) for b in BACKENDS[algo.lower()])}")
