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
from typing import Any

import numpy as np

__all__ = ["make_curve_callback", "paper_costs"]


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


def make_curve_callback(env_name: str, env_kwargs: dict, seeds, every: int, *, n_agents: int = 1,
                        path: str | None = None):
    """SB3 callback recording ``(env_steps, [J_policy / J_paper per seed])`` every ``every`` env steps.

    ``n_agents``: SB3 samples per environment step (parameter-shared training). The
    points are in ``callback.points`` and, when ``path`` is given, written there as JSON
    after every evaluation (an interrupted run keeps its curve).
    """
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    from ..config.envs import gym_factory, parallel_factory
    from ..evaluate import run_episode
    from .loading import TrainedAgent

    seeds = [int(s) for s in seeds]
    if every < 1:
        raise ValueError(f"every must be >= 1 environment step, got {every!r}")
    ref = paper_costs(env_name, env_kwargs, seeds)

    class EvalCurveCallback(BaseCallback):
        agent_config: dict | None = None

        def __init__(self):
            super().__init__()
            self.points: list[dict[str, Any]] = []
            self._next = 0
            self._envs = None

        def _env(self, multi: bool):
            if self._envs is None:
                self._envs = {}
            if multi not in self._envs:
                fac = parallel_factory(env_name, env_kwargs) if multi else gym_factory(env_name, env_kwargs)
                self._envs[multi] = fac()
            return self._envs[multi]

        def evaluate(self) -> None:
            cfg = self.agent_config
            if cfg is None:
                raise RuntimeError("EvalCurveCallback needs agent_config (set by agents.training.train.train)")
            venv = self.model.get_env()
            vn = venv if isinstance(venv, VecNormalize) else None
            agent = TrainedAgent.from_model(self.model, vn, cfg)
            env = self._env(agent.multi_agent)
            pol = agent.policy_for(env)
            costs = np.array([run_episode(env, pol, s, parallel=agent.multi_agent).cost for s in seeds])
            steps = int(self.num_timesteps // max(1, n_agents))
            self.points.append({"env_steps": steps, "cost_ratio": (costs / ref).tolist()})
            if path is not None:
                with open(path, "w") as fh:
                    json.dump({"seeds": seeds, "paper_cost": ref.tolist(), "points": self.points}, fh)

        def _on_step(self) -> bool:
            if self.num_timesteps // max(1, n_agents) >= self._next:
                self.evaluate()
                self._next += every
            return True

        def _on_training_end(self) -> None:
            last = self.points[-1]["env_steps"] if self.points else -1
            if last != self.num_timesteps // max(1, n_agents):
                self.evaluate()
            for e in (self._envs or {}).values():
                e.close()

    return EvalCurveCallback()
