"""Train SB3 agents on the centralised Gymnasium envs or (parameter-shared) on the PettingZoo envs.

- centralised: PPO, SAC, TD3 on ``dobs_envs/<Name>-v0`` (one agent acting for all
  controller nodes) or any Gymnasium id;
- multi-agent: PPO and SAC with one policy shared by every controller node (one VecEnv
  slot per (copy, agent)).

The dobs_envs environments train on :class:`agents.core_vec_env.CoreVecEnv` (all copies in
one batched core, :func:`build_vec_env`).

Budgets (``timesteps``) are *environment* steps: for multi-agent training SB3 counts
one sample per agent, so the SB3 budget is ``timesteps * n_agents``.

A run directory holds ``model.zip``, ``vecnormalize.pkl`` (when observations or
rewards are normalised), ``config.json`` (everything needed to rebuild the env and
the policy inputs; ``status`` running / interrupted / complete and ``timesteps_done``)
and ``checkpoints/`` (``<algo>_<sb3 steps>_steps.zip`` with its normaliser). :func:`load_agent`
reads it (or one checkpoint) back. Ctrl-C saves the run as interrupted (:class:`TrainingInterrupted`)
and :func:`resume` continues it from its last save.
"""
from __future__ import annotations

import json
import math
import os
import pickle
import re
import signal
import threading
import time
import zipfile
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from dobs_envs.registry import get as registry_entry

from .config import ACTIVATIONS, ENVS, MULTI_AGENT_ALGOS, env_key, gym_factory, load_hyperparams, parallel_factory
from .core_vec_env import CoreVecEnv
from .seeds import BC_DEMONSTRATION_OFFSET, resume_seed
from .vec_env import ParallelVecEnv, SlotEncoder

__all__ = ["train", "resume", "resume_point", "load_agent", "TrainedAgent", "TrainingInterrupted", "RunDirError",
           "read_run_config", "run_files", "build_vec_env", "core_of", "TqdmCallback", "set_threads",
           "Recipe", "resolve_recipe"]

_EXTRA_KEYS = ("n_envs", "n_timesteps", "policy", "normalize", "agent_id", "env_kwargs", "noise_type", "noise_std",
               "normalize_actions", "residual_scale", "bc")


def set_threads(threads: int | None = 1) -> None:
    """``torch.set_num_threads`` (1 by default: small MLPs on 2-core machines are ~10x
    faster single-threaded)."""
    import torch

    if threads:
        torch.set_num_threads(int(threads))


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC, TD3

    table = {"ppo": PPO, "sac": SAC, "td3": TD3}
    try:
        return table[algo.lower()]
    except KeyError:
        raise ValueError(f"unknown algorithm {algo!r}; choose from {sorted(table)}") from None


def _schedule(value):
    """rl-zoo3's schedule strings: ``"lin_3e-4"`` is a linear decay from 3e-4 to 0 over training."""
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            v0 = float(value[4:])
        except ValueError:
            raise ValueError(f"schedule {value!r} must be 'lin_<number>', e.g. 'lin_3e-4'") from None
        return lambda progress_remaining: progress_remaining * v0
    return value


def _policy_kwargs(pk: dict | None) -> dict:
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
class Recipe:
    """What :func:`train` derives from the hyperparameter files (and overrides) for one run.

    ``algo_kwargs``: the algorithm's constructor arguments as written (``lin_`` schedules
    as strings, ``policy_kwargs.activation_fn`` a name); ``normalize``: ``False`` or the
    ``VecNormalize`` arguments (``gamma`` included); ``train_env_kwargs``: the recipe's
    training-only env options; ``bc``: the warm start's ``{episodes, noise, epochs, lr}``
    (``bc`` variant); ``action_noise_sigma``: TD3/SAC Gaussian action noise.
    """

    policy: str
    algo_kwargs: dict
    n_envs: int
    n_timesteps: int
    normalize: Any
    normalize_actions: bool
    agent_id: bool
    train_env_kwargs: dict
    residual_scale: float | None
    bc: dict | None
    action_noise_sigma: float | None
    hyperparams: dict

    def as_dict(self) -> dict:
        """Everything but the merged ``hyperparams`` (plain data)."""
        return {k: v for k, v in self.__dict__.items() if k != "hyperparams"}


def resolve_recipe(algo: str, env_name: str, *, multi_agent: bool = False, hybrid: str | None = None,
                   overrides: dict | None = None) -> Recipe:
    """The :class:`Recipe` of ``algo`` on ``env_name`` (see :func:`agents.config.load_hyperparams`)."""
    algo = algo.lower()
    hp = load_hyperparams(algo, env_name, multi_agent=multi_agent, overrides=overrides, variant=hybrid)
    return recipe_from_hyperparams(algo, env_name, hp, multi_agent=multi_agent, hybrid=hybrid)


def recipe_from_hyperparams(algo: str, env_name: str, hp: dict, *, multi_agent: bool = False,
                            hybrid: str | None = None) -> Recipe:
    """The :class:`Recipe` of the merged hyperparameters ``hp`` (a run's ``config.json``
    ``hyperparams``, or :func:`agents.config.load_hyperparams`)."""
    residual_scale = None
    if hybrid == "residual":
        residual_scale = hp.get("residual_scale")
        if residual_scale is None:
            raise ValueError(f"the residual recipe of {algo} on {env_name!r} needs 'residual_scale' in the "
                             f"hyperparameters")
    norm = hp.get("normalize") or False
    if norm:
        norm = dict(norm) if isinstance(norm, dict) else {}
        norm.setdefault("gamma", hp.get("gamma", 0.99))
    bc = None
    if hybrid == "bc":
        b = dict(hp.get("bc") or {})
        bc = {"episodes": int(b.get("episodes", 20)), "noise": float(b.get("noise", 0.1)),
              "epochs": int(b.get("epochs", 30)), "lr": float(b.get("lr", 1e-3))}
    sigma = None
    if hp.get("noise_type") and algo in ("td3", "sac"):
        sigma = float(hp.get("noise_std", 0.1))
    algo_kw = {k: v for k, v in hp.items() if k not in _EXTRA_KEYS}
    algo_kw["policy_kwargs"] = dict(algo_kw.get("policy_kwargs") or {})
    return Recipe(policy=hp.get("policy", "MlpPolicy"), algo_kwargs=algo_kw, n_envs=int(hp.get("n_envs", 1)),
                  n_timesteps=int(hp.get("n_timesteps", 100000)), normalize=norm,
                  normalize_actions=bool(hp.get("normalize_actions", False)) and residual_scale is None,
                  agent_id=bool(hp.get("agent_id", False)) and multi_agent,
                  train_env_kwargs=dict(hp.get("env_kwargs") or {}), residual_scale=residual_scale, bc=bc,
                  action_noise_sigma=sigma, hyperparams=hp)


def build_vec_env(env, *, multi_agent: bool = False, n_envs: int = 1, seed: int | None = None,
                  env_kwargs: dict | None = None, agent_id: bool = False, normalize_actions: bool = False,
                  residual_scale: float | None = None):
    """Monitored VecEnv for training (not normalised).

    ``env`` is a name (see :mod:`agents.config`) or a constructor. The dobs_envs
    environments (by name) run as one batched core, :class:`agents.core_vec_env.CoreVecEnv`
    + ``VecMonitor``: centralised (one slot per copy, episodes of the Gymnasium id's
    ``max_episode_steps`` unless ``max_cycles``/``horizon`` are given) or parameter-shared
    (one slot per (copy, agent)). Foreign Gymnasium ids and residual envs use ``DummyVecEnv``
    + ``Monitor`` (centralised) or :class:`ParallelVecEnv` + ``VecMonitor`` (multi-agent).
    ``normalize_actions``: the agent acts in ``[-1, 1]`` (Gymnasium's ``RescaleAction`` / the
    adapters' ``rescale_actions``). ``residual_scale``: the agent's action is a residual
    correction (:mod:`agents.hybrid`), already in ``[-1, 1]``.
    """
    from .hybrid import residual_factory

    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    core = core_of(env, n_envs, env_kwargs, multi_agent) if residual_scale is None else None
    if core is not None:
        venv = VecMonitor(CoreVecEnv(core, shared=multi_agent, agent_id=agent_id and multi_agent,
                                     rescale_actions=normalize_actions))
        if seed is not None:
            venv.seed(seed)
        return venv
    if multi_agent:
        fac = parallel_factory(env, env_kwargs)
        if residual_scale is not None:
            fac, normalize_actions = residual_factory(fac, residual_scale, parallel=True), False
        venv = VecMonitor(ParallelVecEnv([fac for _ in range(n_envs)], agent_id=agent_id,
                                         rescale_actions=normalize_actions))
        if seed is not None:
            venv.seed(seed)
        return venv
    if callable(env):
        fac = lambda: env(**(env_kwargs or {}))  # noqa: E731
    else:
        fac = gym_factory(env, env_kwargs)
    if residual_scale is not None:
        fac, normalize_actions = residual_factory(fac, residual_scale, parallel=False), False
    if normalize_actions:
        from gymnasium.wrappers import RescaleAction

        inner = fac
        fac = lambda: RescaleAction(inner(), np.float32(-1.0), np.float32(1.0))  # noqa: E731
    return make_vec_env(fac, n_envs=n_envs, seed=seed, vec_env_cls=DummyVecEnv)


def core_of(env, n_envs: int, env_kwargs: dict | None, multi_agent: bool):
    """The batched core of ``n_envs`` copies of the dobs_envs environment named ``env``
    (None for constructors and foreign ids). Centralised training keeps the registered
    Gymnasium id's episodes: truncation after ``max_episode_steps`` (or the given
    ``max_cycles``/``horizon``), the termination penalty charging the scenario's ``t_end``."""
    if not isinstance(env, str):
        return None
    names = {gid: name for name, (gid, _) in ENVS.items()}
    name = env_key(env) if env_key(env) in ENVS else names.get(env)
    if name is None:
        return None
    entry = registry_entry(name)
    kw = dict(env_kwargs or {})
    if multi_agent:
        return entry.load_class().make_core(n_envs, **kw)
    mc, hz = kw.pop("max_cycles", None), kw.pop("horizon", None)
    core = entry.load_class().make_core(n_envs, horizon=math.inf, **kw)
    if hz is not None:
        mc = max(1, int(round(float(hz) / core.control_period)))
    core.max_cycles = entry.max_episode_steps if mc is None else int(mc)
    return core


class TqdmCallback:
    """Progress bar over environment steps (SB3's own needs ``rich``)."""

    def __new__(cls, total: int, desc: str = "train", scale: int = 1):
        from stable_baselines3.common.callbacks import BaseCallback
        from tqdm.auto import tqdm

        class _Cb(BaseCallback):
            def _on_training_start(self):
                self.bar = tqdm(total=total, desc=desc, unit="step", mininterval=1.0, dynamic_ncols=True)

            def _on_step(self):
                self.bar.n = min(total, self.num_timesteps // scale)
                self.bar.refresh() if self.bar.n % 512 == 0 else None
                return True

            def _on_training_end(self):
                self.bar.n = min(total, self.num_timesteps // scale)
                self.bar.close()

        return _Cb()


@dataclass
class TrainResult:
    path: str
    model: Any
    seconds: float
    config: dict


def default_run_dir(env: str, algo: str, multi_agent: bool, seed: int) -> str:
    name = env if isinstance(env, str) else getattr(env, "__name__", "env")
    name = name.replace("/", "_").replace(":", "_")
    return os.path.join("runs", f"{name}_{algo}{'_ma' if multi_agent else ''}_s{seed}")


#: ``config.json`` ``status`` of a run directory: written ``running`` when training starts,
#: ``interrupted`` when a SIGINT stopped it (model and normaliser saved), ``complete`` at the end
#: (runs written before the field existed are complete).
RUNNING, INTERRUPTED, COMPLETE = "running", "interrupted", "complete"
_CHECKPOINT = re.compile(r"^(?P<algo>[a-z0-9]+)_(?P<steps>\d+)_steps\.zip$")


class TrainingInterrupted(KeyboardInterrupt):
    """SIGINT stopped :func:`train` / :func:`resume`; the run was saved and can be resumed.

    A ``KeyboardInterrupt`` (callers that know nothing of it stop as on Ctrl-C).
    Attributes: ``path`` (the run directory), ``timesteps_done`` and ``timesteps`` (env steps).
    """

    def __init__(self, path: str, timesteps_done: int, timesteps: int):
        super().__init__(f"training interrupted after {timesteps_done} of {timesteps} env steps; "
                         f"model, normaliser and config saved in {path}")
        self.path, self.timesteps_done, self.timesteps = path, int(timesteps_done), int(timesteps)


class _StopOnSigint:
    """Context manager: the first SIGINT asks training to stop at the next environment step
    (:meth:`callback` then returns False, SB3 ends ``learn()`` cleanly); a second SIGINT during
    training raises ``KeyboardInterrupt`` at once; once ``saving`` is set (the final save, well
    under a second) SIGINT is ignored, so no save is cut short. Installed only in the main thread
    and over Python's default handler (a process that ignores SIGINT, such as a benchmark worker,
    keeps ignoring it)."""

    def __init__(self):
        self.requested = False
        self.saving = False
        self._installed = False

    def _handler(self, signum, frame):
        if self.saving:
            return
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __enter__(self):
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            signal.signal(signal.SIGINT, self._handler)
            self._installed = True
        return self

    def __exit__(self, *exc):
        if self._installed:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            self._installed = False
        return False

    def callback(self):
        from stable_baselines3.common.callbacks import BaseCallback

        stop = self

        class _StopCallback(BaseCallback):
            def _on_step(self) -> bool:
                return not stop.requested

        return _StopCallback()


def _clear_run(out: str) -> None:
    """Remove the files of a previous run in ``out`` (a new run replaces it: none of its models,
    normalisers or checkpoints may be mistaken for the new run's, e.g. by :func:`resume`)."""
    for f in ("config.json", "model.zip", "vecnormalize.pkl", "replay_buffer.pkl"):
        if os.path.isfile(os.path.join(out, f)):
            os.remove(os.path.join(out, f))
    ck = os.path.join(out, "checkpoints")
    if os.path.isdir(ck):
        for f in os.listdir(ck):
            if re.match(r"^[a-z0-9]+_(?:(?:vecnormalize|replay_buffer)_)?\d+_steps\.(?:zip|pkl)$", f):
                os.remove(os.path.join(ck, f))


def _write_json(path: str, obj: dict) -> None:
    """Write ``obj`` to ``path`` atomically (a torn config.json is never left behind)."""
    with open(path + ".tmp", "w") as fh:
        json.dump(obj, fh, indent=2, default=str)
    os.replace(path + ".tmp", path)


def _save_model(model, path: str) -> None:
    model.save(path + ".tmp")  # the suffix keeps SB3 from appending ".zip"
    os.replace(path + ".tmp", path)


def _save_pickle_atomic(save, path: str) -> None:
    save(path + ".tmp")
    os.replace(path + ".tmp", path)


@dataclass
class _Setup:
    """What :func:`train` and :func:`resume` build before learning."""
    venv: Any
    n_agents: int
    config: dict


def _setup(env, name: str, algo: str, *, multi_agent: bool, hybrid: str | None, recipe: Recipe, timesteps: int,
           seed: int, env_kwargs: dict | None, checkpoint_freq: int | None) -> _Setup:
    """The training VecEnv (normalised when the recipe says so, not yet loaded from a save) and the
    run's configuration (``config.json``) from the ``recipe``."""
    from stable_baselines3.common.vec_env import VecNormalize

    user_kw = dict(env_kwargs or {})
    kw = dict(recipe.train_env_kwargs)
    kw.update(user_kw)
    agent_id, residual_scale, norm_act = recipe.agent_id, recipe.residual_scale, recipe.normalize_actions
    venv = build_vec_env(env, multi_agent=multi_agent, n_envs=recipe.n_envs, seed=seed, env_kwargs=kw,
                         agent_id=agent_id, normalize_actions=norm_act, residual_scale=residual_scale)
    if norm_act and not multi_agent:  # the env's own bounds, for evaluation
        inner = venv.unwrapped
        inner_space = inner.env_action_space if isinstance(inner, CoreVecEnv) else inner.envs[0].unwrapped.action_space
        act_low, act_high = inner_space.low.tolist(), inner_space.high.tolist()
    else:
        act_low = act_high = None
    n_agents = venv.unwrapped.n_agents if multi_agent else 1
    norm = recipe.normalize
    if norm:
        venv = VecNormalize(venv, **norm)
    ckpt = timesteps // 4 if checkpoint_freq is None else int(checkpoint_freq)
    config = {
        "env": name, "algo": algo, "multi_agent": multi_agent, "hybrid": hybrid, "residual_scale": residual_scale,
        "bc": None, "seed": seed, "timesteps": timesteps, "n_agents": n_agents, "agent_id": agent_id,
        "normalize_actions": norm_act, "action_low": act_low, "action_high": act_high,
        "env_kwargs": user_kw, "train_env_kwargs": kw, "normalize": bool(norm), "checkpoint_freq": ckpt,
        "hyperparams": dict(recipe.hyperparams),
    }
    return _Setup(venv=venv, n_agents=n_agents, config=config)


def _algo_kwargs(recipe: Recipe, venv) -> dict:
    from stable_baselines3.common.noise import NormalActionNoise

    algo_kw = dict(recipe.algo_kwargs)
    algo_kw["policy_kwargs"] = _policy_kwargs(algo_kw.get("policy_kwargs"))
    for key in ("learning_rate", "clip_range"):
        if key in algo_kw:
            algo_kw[key] = _schedule(algo_kw[key])
    if recipe.action_noise_sigma is not None:
        d = venv.action_space.shape[0]
        algo_kw["action_noise"] = NormalActionNoise(np.zeros(d), recipe.action_noise_sigma * np.ones(d))
    return algo_kw


def _quiet_logger(model) -> None:
    """Without TensorBoard, give the model a logger that writes nowhere but stdout (``verbose >= 1``):
    SB3's default creates an empty ``SB3-<date>`` directory in the temp dir for every run."""
    if getattr(model, "tensorboard_log", None) is not None:
        return  # SB3 logs into the TensorBoard directory (no temp directory)
    import sys

    from stable_baselines3.common.logger import HumanOutputFormat, Logger

    model.set_logger(Logger(folder=None, output_formats=[HumanOutputFormat(sys.stdout)] if model.verbose >= 1 else []))


def _learn(model, venv, config: dict, out: str, *, progress: bool, callbacks: list | None,
           previous_seconds: float = 0.0) -> TrainResult:
    """Learn up to the run's budget (continuing from ``model.num_timesteps``), save the run; on SIGINT
    save it as interrupted and raise :class:`TrainingInterrupted`."""
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    algo, multi_agent, n_agents = config["algo"], config["multi_agent"], config["n_agents"]
    timesteps, ckpt = config["timesteps"], config["checkpoint_freq"]
    sb3_steps = timesteps * n_agents
    start = int(model.num_timesteps)
    callbacks = list(callbacks or [])
    if ckpt > 0:
        callbacks.append(CheckpointCallback(save_freq=max(ckpt * n_agents // venv.num_envs, 1),
                                            save_path=os.path.join(out, "checkpoints"), name_prefix=algo,
                                            save_vecnormalize=config["normalize"]))
    if progress:
        callbacks.append(TqdmCallback(timesteps, desc=f"{algo}{'-ma' if multi_agent else ''} {config['env']}",
                                      scale=n_agents))
    for cb in callbacks:  # callbacks that evaluate the live agent need its configuration
        if hasattr(cb, "agent_config"):
            cb.agent_config = config
    config.update(status=RUNNING, timesteps_done=start // n_agents, sb3_timesteps=start)
    _write_json(os.path.join(out, "config.json"), config)  # a run killed outright resumes from its checkpoints
    _quiet_logger(model)
    t0 = time.perf_counter()
    with _StopOnSigint() as stop:  # kept through the saves: no Ctrl-C cuts them short
        model.learn(total_timesteps=sb3_steps - start, callback=CallbackList(callbacks + [stop.callback()]),
                    tb_log_name=f"{algo}{'_ma' if multi_agent else ''}", reset_num_timesteps=start == 0)
        stop.saving = True
        seconds = previous_seconds + time.perf_counter() - t0
        done = int(model.num_timesteps)
        interrupted = stop.requested and done < sb3_steps
        _save_model(model, os.path.join(out, "model.zip"))
        if config["normalize"]:
            _save_pickle_atomic(venv.save, os.path.join(out, "vecnormalize.pkl"))
        replay = os.path.join(out, "replay_buffer.pkl")
        if interrupted and getattr(model, "replay_buffer", None) is not None:
            _save_pickle_atomic(model.save_replay_buffer, replay)  # off-policy: resume with the same buffer
        elif os.path.exists(replay):
            os.remove(replay)  # complete: only a resumable run needs it
        config.update(status=INTERRUPTED if interrupted else COMPLETE, timesteps_done=done // n_agents,
                      sb3_timesteps=done, model_sb3_timesteps=done, train_seconds=seconds)
        _write_json(os.path.join(out, "config.json"), config)
    venv.close()
    if interrupted:
        raise TrainingInterrupted(out, done // n_agents, timesteps)
    return TrainResult(path=out, model=model, seconds=seconds, config=config)


def train(env, algo: str = "ppo", *, multi_agent: bool = False, timesteps: int | None = None, seed: int = 0,
          out: str | None = None, tensorboard: str | None = None, progress: bool = True,
          checkpoint_freq: int | None = None, hyperparams: dict | None = None, env_kwargs: dict | None = None,
          threads: int | None = 1, verbose: int = 0, env_name: str | None = None,
          hybrid: str | None = None, callbacks: list | None = None) -> TrainResult:
    """Train ``algo`` on ``env`` and save the run directory (see module doc).

    Parameters
    ----------
    env : environment name (or, multi-agent, a ParallelEnv constructor; then pass
        ``env_name`` for the hyperparameter lookup and the config).
    timesteps : environment steps (default: the YAML ``n_timesteps``).
    hyperparams : overrides merged over the YAML entry.
    env_kwargs : options of the environment (the task; evaluation uses these). The
        recipe's ``env_kwargs`` (training-only options such as a tighter
        ``state_bound``) are merged under them for training only.
    hybrid : ``None`` (pure RL), ``"residual"`` (the action is a bounded correction of
        the paper's controller, ``residual_scale`` of the recipe) or ``"bc"``
        (behaviour-cloning warm start from the paper's controller, recipe key ``bc``:
        ``{episodes, noise, epochs, lr}``); see :mod:`agents.hybrid`. The recipe is
        looked up with the variant (``<env>-residual``, ``<env>-bc``).
    callbacks : extra SB3 callbacks (e.g. :class:`agents.curves.EvalCurveCallback`).
    checkpoint_freq : environment steps between checkpoints (default: timesteps // 4; 0 disables).
    threads : torch threads (None keeps torch's default).

    Interruption
    ------------
    In the main thread, a SIGINT (Ctrl-C) stops training at the next environment step, saves
    ``model.zip``, ``vecnormalize.pkl`` (and an off-policy replay buffer, ``replay_buffer.pkl``)
    and ``config.json`` with ``status: "interrupted"`` and ``timesteps_done``, then raises
    :class:`TrainingInterrupted`; :func:`resume` continues the run. A second SIGINT before the
    save aborts at once (``config.json`` stays ``"running"``; :func:`resume` starts from the last
    checkpoint); during the save (well under a second) SIGINT is ignored.
    """
    algo = algo.lower()
    if multi_agent and algo not in MULTI_AGENT_ALGOS:
        raise ValueError(f"multi-agent training supports {MULTI_AGENT_ALGOS}, not {algo!r}")
    from .hybrid import HYBRIDS, behaviour_cloning_dataset, pretrain_ppo

    if hybrid is not None and hybrid not in HYBRIDS:
        raise ValueError(f"hybrid must be None or one of {HYBRIDS}, got {hybrid!r}")
    if hybrid == "bc" and (algo != "ppo" or multi_agent):
        raise ValueError("the behaviour-cloning warm start is implemented for centralised PPO (algo='ppo')")
    name = env_name or (env if isinstance(env, str) else "default")
    recipe = resolve_recipe(algo, name, multi_agent=multi_agent, hybrid=hybrid, overrides=hyperparams)
    set_threads(threads)
    timesteps = int(timesteps if timesteps is not None else recipe.n_timesteps)
    s = _setup(env, name, algo, multi_agent=multi_agent, hybrid=hybrid, recipe=recipe, timesteps=timesteps,
               seed=seed, env_kwargs=env_kwargs, checkpoint_freq=checkpoint_freq)
    out = out or default_run_dir(name, algo, multi_agent, seed)
    os.makedirs(out, exist_ok=True)
    _clear_run(out)
    model = _algo_class(algo)(recipe.policy, s.venv, seed=seed, verbose=verbose,
                              tensorboard_log=tensorboard, **_algo_kwargs(recipe, s.venv))
    if hybrid == "bc":
        bc = recipe.bc
        kw = s.config["train_env_kwargs"]
        data = behaviour_cloning_dataset(gym_factory(env, kw), bc["episodes"], seed=BC_DEMONSTRATION_OFFSET + seed,
                                         noise=bc["noise"])
        s.config["bc"] = pretrain_ppo(model, data, epochs=bc["epochs"], lr=bc["lr"], seed=seed)
    return _learn(model, s.venv, s.config, out, progress=progress, callbacks=callbacks)


@dataclass(frozen=True)
class ResumePoint:
    """The latest save of a run: ``model`` (a .zip), its normaliser and replay buffer (None when
    absent) and the SB3 timesteps it holds."""
    model: str
    vecnormalize: str | None
    replay_buffer: str | None
    sb3_timesteps: int


def resume_point(path: str, cfg: dict | None = None) -> ResumePoint:
    """Where :func:`resume` continues the run in ``path``: the later of ``model.zip`` (saved on an
    interrupt; ``config.json`` ``model_sb3_timesteps``) and the last complete checkpoint (a valid
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
        m = _CHECKPOINT.match(f)
        if m and m["algo"] == cfg["algo"]:
            n = int(m["steps"])
            vn = os.path.join(ck, f"{cfg['algo']}_vecnormalize_{n}_steps.pkl") if norm else None
            points.append(ResumePoint(os.path.join(ck, f), vn, None, n))
    # a kill can cut a checkpoint short: SB3 writes the model, then the normaliser, in place
    complete = [p for p in points if zipfile.is_zipfile(p.model)
                and (p.vecnormalize is None or os.path.isfile(p.vecnormalize))]
    if not complete:
        raise RunDirError(f"{path!r} has nothing to resume from (no model.zip of an interrupted run, no complete "
                          f"checkpoints/{cfg['algo']}_<steps>_steps.zip" + (" with its normaliser)" if norm else ")"))
    return max(complete, key=lambda p: (p.sb3_timesteps, p.replay_buffer is not None))


def resume(path: str, *, progress: bool = True, threads: int | None = 1, verbose: int = 0,
           tensorboard: str | None = None, callbacks: list | None = None,
           allow_custom_env: bool = False) -> TrainResult:
    """Continue the interrupted run in ``path`` from :func:`resume_point` up to its budget, with the
    run's own configuration (``config.json``: env, algorithm, hyperparameters, seed, budget).

    The model, the normaliser statistics and (off-policy, after a SIGINT) the replay buffer are
    restored and SB3 keeps counting timesteps (schedules continue); the environments restart
    with fresh episodes (seed ``agents.seeds.resume_seed(seed, timesteps done)``), so the result is not bit-identical to an
    uninterrupted run. An off-policy run resumed from a checkpoint starts with an empty replay
    buffer. Interrupting again works as in :func:`train`.
    """
    from stable_baselines3.common.vec_env import VecNormalize

    from .config import check_env_name

    cfg = read_run_config(path, require_model=False)
    point = resume_point(path, cfg)
    name = check_env_name(cfg["env"], multi_agent=bool(cfg["multi_agent"]), allow_custom=allow_custom_env,
                          what="the run's environment (config.json 'env')")
    set_threads(threads)
    algo, n_agents = cfg["algo"], int(cfg["n_agents"])
    recipe = recipe_from_hyperparams(algo, name, dict(cfg["hyperparams"]), multi_agent=bool(cfg["multi_agent"]),
                                     hybrid=cfg.get("hybrid"))
    seed = resume_seed(int(cfg["seed"]), point.sb3_timesteps // n_agents)  # never an evaluation/tuning episode
    s = _setup(name, name, algo, multi_agent=bool(cfg["multi_agent"]), hybrid=cfg.get("hybrid"), recipe=recipe,
               timesteps=int(cfg["timesteps"]), seed=seed, env_kwargs=cfg.get("env_kwargs"),
               checkpoint_freq=int(cfg.get("checkpoint_freq", int(cfg["timesteps"]) // 4)))
    venv = s.venv
    if point.vecnormalize is not None:
        venv = _load_or_refuse(point.vecnormalize, lambda: VecNormalize.load(point.vecnormalize, venv.venv))
    kw = _algo_kwargs(recipe, venv)
    custom = {k: kw[k] for k in ("learning_rate", "clip_range") if k in kw}  # rebuilt, not unpickled closures
    model = _load_or_refuse(point.model, lambda: _algo_class(algo).load(
        point.model, env=venv, device="auto", custom_objects=custom, tensorboard_log=tensorboard, verbose=verbose))
    model.num_timesteps = point.sb3_timesteps
    model.set_random_seed(seed)
    if point.replay_buffer is not None:
        _load_or_refuse(point.replay_buffer, lambda: model.load_replay_buffer(point.replay_buffer))
    config = dict(cfg)
    config.setdefault("checkpoint_freq", s.config["checkpoint_freq"])
    config["resumes"] = list(cfg.get("resumes", [])) + [{"from": os.path.relpath(point.model, path),
                                                          "timesteps_done": point.sb3_timesteps // n_agents,
                                                          "replay_buffer": point.replay_buffer is not None}]
    return _learn(model, venv, config, path, progress=progress, callbacks=callbacks,
                  previous_seconds=float(cfg.get("train_seconds") or 0.0))


class RunDirError(ValueError):
    """A run directory that is missing, incomplete or corrupt."""


def _load_or_refuse(path: str, load: Callable):
    """``load()``, or a :class:`RunDirError` naming ``path`` when the file cannot be read (corrupt, truncated)."""
    try:
        return load()
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
    if os.path.isfile(path) and _CHECKPOINT.match(os.path.basename(path)):
        ck_dir = os.path.dirname(os.path.abspath(path))
        if os.path.basename(ck_dir) == "checkpoints":
            return os.path.dirname(ck_dir), path
    path = path[:-len("model.zip")] if path.endswith("model.zip") else path
    return path.rstrip("/") or ".", None


def read_run_config(path: str, *, require_model: bool = True) -> dict:
    """``config.json`` of a run directory (or of the directory holding ``model.zip`` or the
    checkpoint ``path``), validated; with ``require_model``, the model file must exist too."""
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
    if cfg["algo"] not in ("ppo", "sac", "td3"):
        raise RunDirError(f"{cfg_path}: unknown algo {cfg['algo']!r}")
    if require_model and ckpt is None and not os.path.isfile(os.path.join(run, "model.zip")):
        hint = ""
        if cfg.get("status") == RUNNING:
            hint = " (training was stopped before it saved a model: resume it with --resume, or evaluate a " \
                   "checkpoint, <run>/checkpoints/<algo>_<steps>_steps.zip)"
        raise RunDirError(f"{run!r} is not a finished run directory: model.zip is missing{hint}")
    return cfg


def run_files(path: str) -> RunFiles:
    """The files :func:`load_agent` reads for ``path`` (a run directory, its ``model.zip`` or a checkpoint)."""
    cfg = read_run_config(path)
    run, ckpt = _run_dir_of(path)
    norm = bool(cfg.get("normalize")) or (ckpt is None and os.path.exists(os.path.join(run, "vecnormalize.pkl")))
    if ckpt is None:
        model, vn = os.path.join(run, "model.zip"), os.path.join(run, "vecnormalize.pkl")
    else:
        m = _CHECKPOINT.match(os.path.basename(ckpt))
        if m["algo"] != cfg["algo"]:
            raise RunDirError(f"{ckpt!r} is a {m['algo']} checkpoint, the run trains {cfg['algo']}")
        model = ckpt
        vn = os.path.join(os.path.dirname(ckpt), f"{m['algo']}_vecnormalize_{m['steps']}_steps.pkl")
    if norm and not os.path.isfile(vn):
        raise RunDirError(f"{model!r} has no normaliser ({vn} is missing)")
    return RunFiles(run, cfg, model, vn if norm else None)


class TrainedAgent:
    """A saved run loaded for evaluation: normalises observations like in training.

    ``central_policy()`` -> ``obs -> action`` (Gymnasium env);
    ``parallel_policy(env)`` -> ``{agent: obs} -> {agent: action}`` (PettingZoo env,
    shared policy, same padding/one-hot as :class:`ParallelVecEnv`).
    """

    @classmethod
    def from_model(cls, model, vecnorm, config: dict) -> "TrainedAgent":
        """The agent being trained (``model``, its live ``VecNormalize`` or None), e.g. for
        learning curves: observations are normalised with the current statistics."""
        self = cls.__new__(cls)
        self.config, self.path, self.model_path, self.model = dict(config), None, None, model
        self.algo = config["algo"]
        self.multi_agent = bool(config["multi_agent"])
        self.vecnorm = vecnorm
        return self

    def normalize_obs(self, obs: np.ndarray) -> np.ndarray:
        if self.vecnorm is None or not getattr(self.vecnorm, "norm_obs", False):
            return obs
        return self.vecnorm.normalize_obs(obs)

    def __init__(self, path: str, device: str = "cpu"):
        files = run_files(path)
        self.config = files.config
        self.path = files.run_dir
        self.model_path = files.model
        self.algo = self.config["algo"]
        self.multi_agent = bool(self.config["multi_agent"])
        self.model = _load_or_refuse(files.model, lambda: _algo_class(self.algo).load(files.model, device=device))
        vn = files.vecnormalize
        self.vecnorm = None
        if vn is not None:
            def unpickle():
                with open(vn, "rb") as fh:
                    return pickle.load(fh)  # VecNormalize without its venv: only obs_rms is used

            self.vecnorm = _load_or_refuse(vn, unpickle)
            if not hasattr(self.vecnorm, "normalize_obs"):
                raise RunDirError(f"{vn} holds a {type(self.vecnorm).__name__}, not the run's VecNormalize")
            self.vecnorm.training = False
            self.vecnorm.norm_reward = False

    @property
    def hybrid(self) -> str | None:
        return self.config.get("hybrid")

    @property
    def name(self) -> str:
        tag = {"residual": " residual", "bc": " BC-warm-start"}.get(self.hybrid or "", "")
        return f"{self.algo.upper()}{tag}{' (shared)' if self.multi_agent else ''}"

    def policy_for(self, env, deterministic: bool = True) -> Callable:
        """The agent acting on the task's own env ``env`` (the PettingZoo env when the agent
        is multi-agent, else the centralised Gymnasium env): ``obs -> applied input``.
        A residual agent is composed with the paper's controller (:class:`agents.hybrid.ResidualPolicy`)."""
        if self.hybrid == "residual":
            from .hybrid import ResidualPolicy

            corr = self.parallel_policy(env, deterministic) if self.multi_agent else self.central_policy(deterministic)
            return ResidualPolicy(env, corr, float(self.config["residual_scale"]), parallel=self.multi_agent)
        return self.parallel_policy(env, deterministic) if self.multi_agent else self.central_policy(deterministic)

    @property
    def observation_space(self):
        return self.model.observation_space

    @property
    def action_space(self):
        return self.model.action_space

    def predict(self, obs, deterministic: bool = True) -> np.ndarray:
        obs = self.normalize_obs(np.asarray(obs, dtype=np.float32))
        act, _ = self.model.predict(obs, deterministic=deterministic)
        return act

    def central_policy(self, deterministic: bool = True) -> Callable:
        """``obs -> action`` in the env's own action space (undoes the [-1, 1] rescaling)."""
        lo, hi = self.action_space.low, self.action_space.high
        rescale = self.config.get("normalize_actions") and self.config.get("action_low") is not None
        if rescale:
            elo = np.asarray(self.config["action_low"], dtype=np.float64)
            ehi = np.asarray(self.config["action_high"], dtype=np.float64)

        def policy(obs):
            a = np.clip(self.predict(np.asarray(obs)[None], deterministic)[0], lo, hi)
            if rescale:
                a = elo + (a.astype(np.float64) + 1.0) * 0.5 * (ehi - elo)
            return a

        return policy

    def encoder_for(self, env) -> SlotEncoder:
        agents = list(env.possible_agents)
        if self.hybrid == "residual":  # corrections in [-1, 1] per input component
            from gymnasium import spaces

            acts = {a: spaces.Box(-1.0, 1.0, env.action_space(a).shape, dtype=np.float32) for a in agents}
        else:
            acts = {a: env.action_space(a) for a in agents}
        enc = SlotEncoder(agents, {a: env.observation_space(a) for a in agents},
                          acts, agent_id=self.config.get("agent_id", False),
                          rescale_actions=bool(self.config.get("normalize_actions", False)))
        if enc.observation_space.shape != self.observation_space.shape:
            raise ValueError(f"model expects observations of shape {self.observation_space.shape}, "
                             f"the env gives {enc.observation_space.shape}")
        return enc

    def parallel_policy(self, env, deterministic: bool = True) -> Callable:
        enc = self.encoder_for(env)

        def policy(observations: dict) -> dict:
            acts = self.predict(enc.encode_all(observations), deterministic)
            return {a: act for a, act in enc.decode_all(acts).items() if a in observations}

        return policy


def load_agent(path: str, device: str = "cpu") -> TrainedAgent:
    """Load a run directory written by :func:`train` (or its ``model.zip``, or one of its checkpoints
    ``<run>/checkpoints/<algo>_<steps>_steps.zip`` with the normaliser saved next to it)."""
    return TrainedAgent(path, device=device)
