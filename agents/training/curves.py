"""Learning curves: the cost ratio of the agent being trained, evaluated at fixed points of training.

:func:`make_curve_callback` returns an SB3 callback that, every ``every`` environment
steps (and at the end of training), evaluates the *current* deterministic policy on the
task's own environment (not the training env: a recipe's training-only options do not
apply) over ``len(seeds)`` seeded episodes and records ``J_policy / J_paper`` per
episode, the paper controller's cost on the same seeds being computed once.
The benchmark aggregates the curves over training runs (at each point a run's score is the mean
of its cost ratios; IQM and a CI resampling whole runs, :mod:`agents.stats`).
"""
from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from .seeds import TUNING

__all__ = ["make_curve_callback", "run_curve_callback", "paper_costs", "CURVE_SEED", "CURVE_POINTS", "CURVE_EPISODES"]

#: a training run's own learning-curve episodes (``dobs-envs train``, both trainers) use seeds ``CURVE_SEED + k``
#: (the tuning range, as the benchmark's curves)
CURVE_SEED = TUNING.start
#: its learning-curve points after the initial one (fewer when the run has fewer updates)
CURVE_POINTS = 10
#: its learning-curve episodes per point
CURVE_EPISODES = 3


def paper_costs(env_name: str, env_kwargs: dict, seeds, *, parallel: bool = True) -> np.ndarray:
    """The paper controller's episode cost ``J = -return`` on each of ``seeds``."""
    from baselines.policies import SeparationPolicy

    from ..config.envs import parallel_factory
    from ..evaluate import run_episode

    env = parallel_factory(env_name, env_kwargs)()
    pol = SeparationPolicy(env)
    out = np.array([run_episode(env, pol, int(s), parallel=True).cost for s in seeds])
    env.close()
    return out


def make_curve_callback(env_name: str, env_kwargs: dict, seeds, every: int | None, *, n_agents: int | None = 1,
                        path: str | None = None):
    """SB3 callback recording ``(env_steps, [J_policy / J_paper per seed])`` every ``every`` env steps.

    ``n_agents``: SB3 samples per environment step (parameter-shared training). The
    points are in ``callback.points`` and, when ``path`` is given, written there as JSON
    after every evaluation (an interrupted run keeps its curve).

    ``every=None, n_agents=None``: both from the run's configuration when training starts (set by
    :func:`agents.training.train.train` / ``resume``): ``every`` is its budget over :data:`CURVE_POINTS`; a resumed
    run keeps the points ``path`` holds up to the env steps it resumes from (on the same seeds) and goes on from
    the next multiple of ``every``.
    """
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    from ..config.envs import gym_factory, parallel_factory
    from ..evaluate import run_episode
    from .loading import TrainedAgent

    seeds = [int(s) for s in seeds]
    if every is not None and every < 1:
        raise ValueError(f"every must be >= 1 environment step, got {every!r}")
    if (every is None) != (n_agents is None):
        raise ValueError("every and n_agents are both given or both taken from the run (None)")
    ref = paper_costs(env_name, env_kwargs, seeds)

    class EvalCurveCallback(BaseCallback):
        agent_config: dict | None = None

        def __init__(self):
            super().__init__()
            self.points: list[dict[str, Any]] = []
            self._every, self._n_agents = every, n_agents
            self._next = 0
            self._envs = None

        def _on_training_start(self) -> None:
            if self._every is not None:
                return
            cfg = self._config()
            self._n_agents = int(cfg["n_agents"])
            self._every = max(1, int(cfg["timesteps"]) // CURVE_POINTS)
            done = int(cfg.get("timesteps_done") or 0)
            if done > 0:  # a resumed run
                self.points = _kept_points(path, seeds, done)
                self._next = (done // self._every + 1) * self._every

        def _config(self) -> dict:
            if self.agent_config is None:
                raise RuntimeError("EvalCurveCallback needs agent_config (set by agents.training.train.train)")
            return self.agent_config

        def _env(self, multi: bool):
            if self._envs is None:
                self._envs = {}
            if multi not in self._envs:
                fac = parallel_factory(env_name, env_kwargs) if multi else gym_factory(env_name, env_kwargs)
                self._envs[multi] = fac()
            return self._envs[multi]

        def evaluate(self) -> None:
            cfg = self._config()
            venv = self.model.get_env()
            vn = venv if isinstance(venv, VecNormalize) else None
            agent = TrainedAgent.from_model(self.model, vn, cfg)
            env = self._env(agent.multi_agent)
            pol = agent.policy_for(env)
            costs = np.array([run_episode(env, pol, s, parallel=agent.multi_agent).cost for s in seeds])
            steps = int(self.num_timesteps // max(1, self._n_agents))
            self.points.append({"env_steps": steps, "cost_ratio": (costs / ref).tolist()})
            if path is not None:
                with open(path, "w") as fh:
                    json.dump({"seeds": seeds, "paper_cost": ref.tolist(), "points": self.points}, fh)

        def _on_step(self) -> bool:
            if self.num_timesteps // max(1, self._n_agents) >= self._next:
                self.evaluate()
                self._next += self._every
            return True

        def _on_training_end(self) -> None:
            last = self.points[-1]["env_steps"] if self.points else -1
            if last != self.num_timesteps // max(1, self._n_agents):
                self.evaluate()
            for e in (self._envs or {}).values():
                e.close()

    return EvalCurveCallback()


def _kept_points(path: str | None, seeds: list[int], resume_from: int | None) -> list[dict[str, Any]]:
    """The points of the curve file ``path`` at env steps <= ``resume_from`` (none when it is absent, unreadable or
    on other seeds: the curve then starts again from the resumed run's first point)."""
    if resume_from is None or path is None or not os.path.isfile(path):
        return []
    try:
        with open(path) as fh:
            doc = json.load(fh)
        if [int(s) for s in doc["seeds"]] != seeds:
            return []
        return [p for p in doc["points"] if int(p["env_steps"]) <= int(resume_from)]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def run_curve_callback(env_name: str, out: str):
    """``dobs-envs train``'s learning curve of an SB3 run (new or resumed): ``out/curve.json``
    (:func:`make_curve_callback`'s format, what the jitted trainer writes too) with :data:`CURVE_EPISODES` episodes
    from :data:`CURVE_SEED` on the task's own env, at the start, every budget / :data:`CURVE_POINTS` env steps and at
    the end; ``None`` for an env that is not one of this package's tasks (no paper controller to compare with)."""
    from ..config.envs import ENVS

    if env_name not in ENVS:
        return None
    return make_curve_callback(env_name, {}, range(CURVE_SEED, CURVE_SEED + CURVE_EPISODES), None, n_agents=None,
                               path=os.path.join(out, "curve.json"))
