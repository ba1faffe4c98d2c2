"""Train SB3 agents on the centralised Gymnasium envs or (parameter-shared) on the PettingZoo envs.

- centralised: PPO, SAC, TD3, CrossQ on ``dobs_envs/<Name>-v0`` (one agent acting for all
  controller nodes) or any Gymnasium id;
- multi-agent: PPO and SAC with one policy shared by every controller node (one VecEnv
  slot per (copy, agent)).

This module is the training loop: :func:`train` (a new run) and :func:`resume` (an interrupted
one) build the run from its recipe (:mod:`agents.training.recipes`), its VecEnv
(:func:`agents.training.env_factory.build_vec_env`: the dobs_envs environments train on
:class:`agents.vecenv.batched_core.CoreVecEnv`, all copies in one batched core) and the algorithm's
implementation (:mod:`agents.training.algos`), learn, and save the run directory (:mod:`agents.training.runs`);
:func:`agents.training.loading.load_agent` reads it back.

Budgets (``timesteps``) are *environment* steps: for multi-agent training SB3 counts
one sample per agent, so the SB3 budget is ``timesteps * n_agents``.

A run directory holds ``model.zip``, ``vecnormalize.pkl`` (when observations or
rewards are normalised), ``config.json`` (everything needed to rebuild the env and
the policy inputs; ``status`` running / interrupted / complete and ``timesteps_done``;
``library`` and ``library_version``, the implementation that trained it; ``provenance``, the source revision
and the machine: :mod:`agents.training.provenance`)
and ``checkpoints/`` (``<algo>_<sb3 steps>_steps.zip`` with its normaliser); see :mod:`agents.training.runs`.
Ctrl-C saves the run as interrupted (:class:`TrainingInterrupted`) and :func:`resume` continues it
from its last save.
"""
from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import dataclass
from typing import Any

from ..config.envs import gym_factory
from ..config.hyperparam_files import MULTI_AGENT_ALGOS
from ..vecenv.batched_core import CoreVecEnv
from .algos import AlgoBackend, BackendUnavailable, backend, backend_of
from .env_factory import build_vec_env
from .provenance import run_provenance
from .recipes import Recipe, recipe_from_hyperparams, resolve_recipe
from .runs import (COMPLETE, INTERRUPTED, RUNNING, RunDirError, clear_run, default_run_dir, load_or_refuse,
                   read_run_config, resume_point, save_atomic, write_json_atomic)
from .seeds import BC_DEMONSTRATION_OFFSET, resume_seed
from .xla import XLA_ONE_THREAD, PJRT_THREADS, xla_threads  # noqa: F401 (the documented import path)

__all__ = ["train", "resume", "TrainingInterrupted", "TrainResult", "TqdmCallback", "set_threads", "xla_threads"]


def set_threads(threads: int | None = 1) -> None:
    """``torch.set_num_threads`` (1 by default: small MLPs on 2-core machines are ~10x
    faster single-threaded), and with ``threads=1`` XLA single-threaded too (SBX, the ``jax``
    extra): without it every training process of the benchmark runs a thread pool the size of the
    machine, and two workers on two cores contend. XLA's pool is sized by ``PJRT_NPROC`` (set to 1
    unless the user set it; jaxlib 0.10 ignores ``--xla_cpu_multi_thread_eigen=false``, which is
    added to ``XLA_FLAGS`` too, keeping flags the user set). Both take effect only if JAX has not
    computed anything yet in this process; the benchmark's workers call this before building a model.
    Side by side on tracking (two SBX runs of 8 copies at once on 2 cores, 2026-12-03, both orders):
    CrossQ +7 % and +12 % env-steps/s with one XLA thread, SAC -7 % and +23 % (noise of the shared
    machine; ``benchmarks/offpolicy_throughput.py --xla-threads``)."""
    import torch

    if threads:
        torch.set_num_threads(int(threads))
    xla_threads(threads)


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


@dataclass
class _Setup:
    """What :func:`train` and :func:`resume` build before learning."""
    venv: Any
    n_agents: int
    config: dict


def _setup(env, name: str, algo_backend: AlgoBackend, *, multi_agent: bool, hybrid: str | None, recipe: Recipe,
           timesteps: int, seed: int, env_kwargs: dict | None, checkpoint_freq: int | None) -> _Setup:
    """The training VecEnv (normalised when the recipe says so, not yet loaded from a save) and the
    run's configuration (``config.json``) from the ``recipe``, trained by ``algo_backend``."""
    algo = algo_backend.name
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
        "env": name, "algo": algo, **algo_backend.provenance(),  # library, library_version
        "multi_agent": multi_agent, "hybrid": hybrid, "residual_scale": residual_scale,
        "bc": None, "seed": seed, "timesteps": timesteps, "n_agents": n_agents, "agent_id": agent_id,
        "normalize_actions": norm_act, "action_low": act_low, "action_high": act_high,
        "env_kwargs": user_kw, "train_env_kwargs": kw, "normalize": bool(norm), "checkpoint_freq": ckpt,
        "hyperparams": dict(recipe.hyperparams), "provenance": run_provenance(),
    }
    return _Setup(venv=venv, n_agents=n_agents, config=config)


def _learn(model, venv, config: dict, out: str, *, progress: bool, callbacks: list | None,
           previous_seconds: float = 0.0) -> TrainResult:
    """Learn up to the run's budget (continuing from ``model.num_timesteps``), save the run; on SIGINT
    save it as interrupted and raise :class:`TrainingInterrupted`."""
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    algo, multi_agent, n_agents = config["algo"], config["multi_agent"], config["n_agents"]
    algo_backend = backend_of(algo, config.get("library"))
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
    write_json_atomic(os.path.join(out, "config.json"), config)  # a run killed outright resumes from its checkpoints
    algo_backend.quiet_logger(model)
    t0 = time.perf_counter()
    with _StopOnSigint() as stop:  # kept through the saves: no Ctrl-C cuts them short
        model.learn(total_timesteps=sb3_steps - start, callback=CallbackList(callbacks + [stop.callback()]),
                    tb_log_name=f"{algo}{'_ma' if multi_agent else ''}", reset_num_timesteps=start == 0)
        stop.saving = True
        seconds = previous_seconds + time.perf_counter() - t0
        done = int(model.num_timesteps)
        interrupted = stop.requested and done < sb3_steps
        save_atomic(lambda tmp: algo_backend.save(model, tmp), os.path.join(out, "model.zip"))
        if config["normalize"]:
            save_atomic(venv.save, os.path.join(out, "vecnormalize.pkl"))
        replay = os.path.join(out, "replay_buffer.pkl")
        if interrupted and getattr(model, "replay_buffer", None) is not None:
            save_atomic(model.save_replay_buffer, replay)  # off-policy: resume with the same buffer
        elif os.path.exists(replay):
            os.remove(replay)  # complete: only a resumable run needs it
        config.update(status=INTERRUPTED if interrupted else COMPLETE, timesteps_done=done // n_agents,
                      sb3_timesteps=done, model_sb3_timesteps=done, train_seconds=seconds)
        write_json_atomic(os.path.join(out, "config.json"), config)
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
        ``{episodes, noise, epochs, lr}``); see :mod:`agents.training.hybrid`. The recipe is
        looked up with the variant (``<env>-residual``, ``<env>-bc``).
    callbacks : extra SB3 callbacks (e.g. :class:`agents.training.curves.EvalCurveCallback`).
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
    algo_backend = backend(algo)  # the preferred implementation that imports (a fallback says so on stderr)
    s = _setup(env, name, algo_backend, multi_agent=multi_agent, hybrid=hybrid, recipe=recipe, timesteps=timesteps,
               seed=seed, env_kwargs=env_kwargs, checkpoint_freq=checkpoint_freq)
    out = out or default_run_dir(name, algo, multi_agent, seed)
    os.makedirs(out, exist_ok=True)
    clear_run(out)
    model = algo_backend.make(recipe, s.venv, seed=seed, verbose=verbose, tensorboard=tensorboard)
    if hybrid == "bc":
        bc = recipe.bc
        kw = s.config["train_env_kwargs"]
        data = behaviour_cloning_dataset(gym_factory(env, kw), bc["episodes"], seed=BC_DEMONSTRATION_OFFSET + seed,
                                         noise=bc["noise"])
        s.config["bc"] = pretrain_ppo(model, data, epochs=bc["epochs"], lr=bc["lr"], seed=seed)
    return _learn(model, s.venv, s.config, out, progress=progress, callbacks=callbacks)


def resume(path: str, *, progress: bool = True, threads: int | None = 1, verbose: int = 0,
           tensorboard: str | None = None, callbacks: list | None = None,
           allow_custom_env: bool = False) -> TrainResult:
    """Continue the interrupted run in ``path`` from :func:`resume_point` up to its budget, with the
    run's own configuration (``config.json``: env, algorithm, hyperparameters, seed, budget).

    The model, the normaliser statistics and (off-policy, after a SIGINT) the replay buffer are restored and SB3 keeps
    counting timesteps (schedules continue); the environments restart with fresh episodes (seed
    ``agents.training.seeds.resume_seed(seed, timesteps done)``), so the result is not bit-identical to an uninterrupted
    run. An off-policy run resumed from a checkpoint starts with an empty replay buffer. Interrupting again works as in
    :func:`train`.
    """
    from ..config.envs import check_env_name
    from .run_pickles import load_replay_buffer, load_vecnormalize

    cfg = read_run_config(path, require_model=False)
    point = resume_point(path, cfg)
    name = check_env_name(cfg["env"], multi_agent=bool(cfg["multi_agent"]), allow_custom=allow_custom_env,
                          what="the run's environment (config.json 'env')")
    set_threads(threads)
    algo, n_agents = cfg["algo"], int(cfg["n_agents"])
    recipe = recipe_from_hyperparams(algo, name, dict(cfg["hyperparams"]), multi_agent=bool(cfg["multi_agent"]),
                                     hybrid=cfg.get("hybrid"))
    seed = resume_seed(int(cfg["seed"]), point.sb3_timesteps // n_agents)  # never an evaluation/tuning episode
    try:  # the implementation that trained the run, never another library
        algo_backend = backend_of(algo, cfg.get("library"))
    except BackendUnavailable as exc:
        raise RunDirError(f"{path!r}: {exc}") from None
    s = _setup(name, name, algo_backend, multi_agent=bool(cfg["multi_agent"]), hybrid=cfg.get("hybrid"), recipe=recipe,
               timesteps=int(cfg["timesteps"]), seed=seed, env_kwargs=cfg.get("env_kwargs"),
               checkpoint_freq=int(cfg.get("checkpoint_freq", int(cfg["timesteps"]) // 4)))
    venv = s.venv
    if point.vecnormalize is not None:  # nothing but the normaliser's own data unpickled (agents.training.run_pickles)
        venv = load_vecnormalize(point.vecnormalize, venv.venv)
    model = load_or_refuse(point.model, lambda: algo_backend.load_run_model(  # rebuilt objects, not unpickled ones
        point.model, recipe, venv=venv, device="auto", tensorboard_log=tensorboard, verbose=verbose))
    model.num_timesteps = point.sb3_timesteps
    model.set_random_seed(seed)
    if point.replay_buffer is not None:
        load_or_refuse(point.replay_buffer, lambda: load_replay_buffer(model, point.replay_buffer))
    config = dict(cfg)
    config.setdefault("checkpoint_freq", s.config["checkpoint_freq"])
    config["resumes"] = list(cfg.get("resumes", [])) + [{"from": os.path.relpath(point.model, path),
                                                          "timesteps_done": point.sb3_timesteps // n_agents,
                                                          "replay_buffer": point.replay_buffer is not None}]
    return _learn(model, venv, config, path, progress=progress, callbacks=callbacks,
                  previous_seconds=float(cfg.get("train_seconds") or 0.0))
