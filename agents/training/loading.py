"""Trained agents loaded for evaluation: :func:`load_agent` reads a run directory (or its ``model.zip``,
or one of its checkpoints) into a :class:`TrainedAgent`, which acts on the task's own environment.

Observations are normalised with the statistics saved with the model (``vecnormalize.pkl``); a
multi-agent (parameter-shared) agent acts through :class:`agents.vecenv.slots.SlotEncoder` (the padding and
one-hot agent id of training); a residual agent is composed with the paper's controller. The model is
loaded by the implementation the run records (``config.json`` ``library``; :func:`agents.training.algos.backend_of`).
``model.zip`` and ``vecnormalize.pkl`` are read without running code from them (:mod:`agents.training.run_pickles`:
a refused class raises :class:`agents.training.run_pickles.PickleRefused`, a :class:`RunDirError`; SBX networks are
read as arrays into a fresh policy).

A jitted run (``dobs-envs train --trainer jax``, :mod:`agents.training.jax.run`) loads as a :class:`JaxTrainedAgent`:
its exported ``policy.npz`` + ``policy.json`` acted by :class:`agents.training.jax.numpy_policy.NumpyPolicy` (numpy
only, read with ``allow_pickle=False``) on the task's compiled Gymnasium env.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..vecenv.slots import SlotEncoder
from .algos import BackendUnavailable, backend_of
from .run_pickles import load_vecnormalize
from .runs import RunDirError, load_or_refuse, run_files

__all__ = ["TrainedAgent", "JaxTrainedAgent", "load_agent", "evaluate_model", "slot_policy"]


class TrainedAgent:
    """A saved run loaded for evaluation: normalises observations like in training.

    ``central_policy()`` -> ``obs -> action`` (Gymnasium env);
    ``parallel_policy(env)`` -> ``{agent: obs} -> {agent: action}`` (PettingZoo env,
    shared policy, same padding/one-hot as :class:`agents.vecenv.parallel.ParallelVecEnv`).
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
        try:
            algo_backend = backend_of(self.algo, self.config.get("library"))
        except BackendUnavailable as exc:
            raise RunDirError(f"{files.run_dir!r}: {exc}") from None
        # the pickles first, checked without running code from them (agents.training.run_pickles), then the model
        vn = files.vecnormalize
        self.vecnorm = None if vn is None else load_vecnormalize(vn)  # without its venv: only obs_rms is used
        recipe = _run_recipe(files)
        self.model = load_or_refuse(files.model, lambda: algo_backend.load_run_model(files.model, recipe,
                                                                                    device=device))
        if self.vecnorm is not None:
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
        A residual agent is composed with the paper's controller (:class:`agents.training.hybrid.ResidualPolicy`)."""
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
        return slot_policy(self.encoder_for(env), lambda obs: self.predict(obs, deterministic))


def slot_policy(encoder: SlotEncoder, act: Callable) -> Callable:
    """``{agent: obs} -> {agent: action}`` of a shared policy ``act`` (``(K, width) -> (K, act_dim)`` on the slot
    observations) through ``encoder`` (padding, one-hot id, each agent's bounds); agents absent from the
    observations get no action."""

    def policy(observations: dict) -> dict:
        acts = act(encoder.encode_all(observations))
        return {a: u for a, u in encoder.decode_all(acts).items() if a in observations}

    return policy


class JaxTrainedAgent:
    """A jitted run loaded for evaluation: ``policy_for(env)`` is its
    :class:`agents.training.jax.numpy_policy.NumpyPolicy` (``obs -> input`` of the task's Gymnasium env, its
    default ``normalized_actions=False``); ``name`` ``"PPO (JAX)"``. A shared-policy run (``config.json``
    ``multi_agent``, :mod:`agents.training.jax.run_marl`) acts on the PettingZoo env through
    :class:`agents.vecenv.slots.SlotEncoder` as an SB3 shared run does (the run's ``agent_id`` and
    ``normalize_actions``); ``name`` ``"PPO (JAX, shared)"``."""

    hybrid = None

    def __init__(self, path: str, config: dict):
        import os

        from .jax.numpy_policy import NumpyPolicy

        self.path, self.config, self.algo = path, config, config["algo"]
        self.multi_agent = bool(config.get("multi_agent"))
        self.model_path = os.path.join(path, "policy.npz")
        # arrays read with allow_pickle=False; a damaged or refused file is a RunDirError naming it
        self.policy = load_or_refuse(self.model_path, lambda: NumpyPolicy(path))
        if self.policy.meta.get("env_id") != config.get("env_id"):
            raise RunDirError(f"{path!r}: policy.json's env_id {self.policy.meta.get('env_id')!r} is not the run's "
                              f"{config.get('env_id')!r} (config.json)")

    @property
    def name(self) -> str:
        return f"{self.algo.upper()} (JAX{', shared' if self.multi_agent else ''})"

    def policy_for(self, env, deterministic: bool = True) -> Callable:
        """The exported deterministic policy (``deterministic`` must be True: no stochastic policy is exported)."""
        if not deterministic:
            raise ValueError("a jitted run exports its deterministic policy only")
        if self.multi_agent:
            agents = list(env.possible_agents)
            enc = SlotEncoder(agents, {a: env.observation_space(a) for a in agents},
                              {a: env.action_space(a) for a in agents}, agent_id=bool(self.config.get("agent_id")),
                              rescale_actions=bool(self.config.get("normalize_actions")))
            if enc.observation_space.shape != (self.policy.obs_dim,):
                raise ValueError(f"the exported policy expects slot observations of shape ({self.policy.obs_dim},), "
                                 f"the env gives {enc.observation_space.shape}")
            return slot_policy(enc, self.policy)
        shape = getattr(env.observation_space, "shape", None)
        if shape != (self.policy.obs_dim,):
            raise ValueError(f"the exported policy expects observations of shape ({self.policy.obs_dim},), the env "
                             f"gives {shape}")
        return self.policy


def _run_recipe(files):
    """The :class:`agents.training.recipes.Recipe` of a run (its ``config.json``): what the model's rebuilt objects
    come from."""
    from .recipes import recipe_from_hyperparams

    cfg = files.config
    try:
        return recipe_from_hyperparams(cfg["algo"], str(cfg["env"]), dict(cfg.get("hyperparams") or {}),
                                       multi_agent=bool(cfg["multi_agent"]), hybrid=cfg.get("hybrid"))
    except (TypeError, ValueError) as exc:
        raise RunDirError(f"{files.run_dir}/config.json: its hyperparams are not a recipe ({exc})") from None


def load_agent(path: str, device: str = "cpu") -> TrainedAgent | JaxTrainedAgent:
    """Load a run directory written by :func:`agents.training.train.train` (or its ``model.zip``, or one of its
    checkpoints ``<run>/checkpoints/<algo>_<steps>_steps.zip`` with the normaliser saved next to it), or a jitted
    run's directory (:func:`agents.training.jax.run.train_jax`: a :class:`JaxTrainedAgent`)."""
    from . import jax as jax_trainer
    from .runs import _run_dir_of, read_run_config

    cfg = read_run_config(path)
    if cfg.get("trainer") == jax_trainer.TRAINER:
        return JaxTrainedAgent(_run_dir_of(path)[0], cfg)
    return TrainedAgent(path, device=device)


def evaluate_model(path: str, episodes: int, seed: int, *, progress: bool = True,
                   allow_custom_env: bool = False) -> dict:
    """Evaluate a saved run directory (``dobs-envs evaluate``) on its own environment.

    ``path`` is a run directory, its ``model.zip`` or one of its checkpoints
    (``<run>/checkpoints/<algo>_<steps>_steps.zip``, evaluated with the normaliser saved with it);
    the summary names the model file (``model``).

    The environment named in the run's ``config.json`` must be a registered one
    (:func:`agents.config.envs.check_env_name`); a ``module:attr`` name is refused unless
    ``allow_custom_env`` (a file must never make us import code). ``model.zip`` and
    ``vecnormalize.pkl`` are read without running code from them (:mod:`agents.training.run_pickles`; a refused
    class raises :class:`agents.training.run_pickles.PickleRefused`).
    """
    from baselines.references import base_env

    from ..config.envs import check_env_name, gym_factory, parallel_factory
    from ..evaluate import evaluate_policy, summarise
    from .runs import read_run_config

    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    cfg = read_run_config(path)
    check_env_name(cfg.get("env"), multi_agent=bool(cfg.get("multi_agent")), allow_custom=allow_custom_env,
                   what="the run's environment (config.json 'env')")
    agent = load_agent(path)
    cfg = agent.config
    # the task's own env (a recipe's training-only options, cfg["train_env_kwargs"], do not apply)
    env = (parallel_factory if agent.multi_agent else gym_factory)(cfg["env"], cfg.get("env_kwargs"))()
    pol = agent.policy_for(env)
    try:
        base_env(env)
    except TypeError:
        # not a dobs_envs environment (e.g. Pendulum-v1): returns only
        rets = []
        for k in range(episodes):
            obs, _ = env.reset(seed=seed + k)
            R, done = 0.0, False
            while not done:
                obs, r, term, trunc, _ = env.step(pol(obs))
                R += float(r)
                done = term or trunc
            rets.append(R)
        env.close()
        return {"policy": agent.name, "model": agent.model_path, "episodes": episodes,
                "seeds": list(range(seed, seed + episodes)),
                "return_mean": float(np.mean(rets)), "return_std": float(np.std(rets))}
    res = evaluate_policy(env, pol, episodes, seed, parallel=agent.multi_agent, progress=progress, desc=agent.name)
    env.close()
    return {"policy": agent.name, "model": agent.model_path, **summarise(res)}
