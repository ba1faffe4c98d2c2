"""What a named environment is, independently of its API: :class:`TaskSpec` (class-level hooks).

An environment class (``TrackingEnv``, ...) fixes its options dataclass, the default
scenario, the checks a user scenario must pass, the default action bounds and the task
error; :meth:`TaskSpec.make_core` turns keyword options into a batched
:class:`~dobs_envs.envs.env_core.EnvCore` of ``B`` copies. Every adapter -- PettingZoo
(:class:`~dobs_envs.envs.parallel_env.DObsParallelEnv`, which is a ``TaskSpec``), Gymnasium single
and vector envs, the SB3 ``VecEnv`` -- builds its core this way, so the named environments
are defined once.
"""
from __future__ import annotations

from .env_core import EnvCore, resolve_scenario
from .options import EnvOptions

__all__ = ["TaskSpec"]


class TaskSpec:
    """Class-level description of an environment (subclass hooks; see module docstring)."""

    #: the options dataclass of the class (its fields are the keyword arguments)
    Options = EnvOptions
    #: options of ``Options`` this class does not accept
    REJECT_OPTIONS: tuple = ()
    #: default action bound (per input component) of user scenarios without one: "auto" (calibrated)
    DEFAULT_ACTION_BOUND = "auto"
    #: the class's options beyond :class:`EnvOptions` with their defaults (derived from ``Options``)
    EXTRA_OPTIONS: dict = {}

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        common = EnvOptions.defaults()
        cls.EXTRA_OPTIONS = {k: v for k, v in cls.Options.defaults().items() if k not in common}

    @classmethod
    def _default_scenario(cls, opts):
        raise TypeError(f"{cls.__name__} needs a scenario= (a Scenario or a YAML/JSON path)")

    @classmethod
    def _check_scenario(cls, sc, opts, given: frozenset) -> None:
        """Subclasses reject scenarios their task does not fit."""

    @classmethod
    def _default_action_bound(cls, sc, opts, given: frozenset):
        return sc.metadata.get("action_bound", cls.DEFAULT_ACTION_BOUND)

    @classmethod
    def _task_error(cls, sc, opts):
        """``(task_error(x (B, n)) -> (B,), info key)`` of the task, or ``(None, None)`` (tracking error)."""
        return None, None

    @classmethod
    def valid_options(cls) -> dict:
        """Option name -> default of this environment class."""
        return {k: v for k, v in cls.Options.defaults().items() if k not in cls.REJECT_OPTIONS}

    @classmethod
    def make_core(cls, num_envs: int = 1, *, threads: int | None = 1, **kwargs) -> EnvCore:
        """The batched core of ``num_envs`` copies of this environment with options ``kwargs``
        (``threads``: see :class:`~dobs_envs.envs.env_core.EnvCore`)."""
        opts = cls.Options.from_kwargs(cls.__name__, kwargs, reject=cls.REJECT_OPTIONS)
        given = frozenset(kwargs)
        sc = resolve_scenario(opts.scenario)
        if sc is None:
            sc = cls._default_scenario(opts)
        from ..scenarios.scenario import Scenario

        if not isinstance(sc, Scenario):
            raise TypeError(f"scenario must be a Scenario or a path to a YAML/JSON scenario file, got {type(sc).__name__}")
        cls._check_scenario(sc, opts, given)
        fn, key = cls._task_error(sc, opts)
        return EnvCore(sc, opts, num_envs, default_action_bound=cls._default_action_bound(sc, opts, given),
                       task_error=fn, task_error_key=key, threads=threads, env_name=cls.__name__)

