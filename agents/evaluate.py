"""Seeded evaluation of any policy (RL agent or analytic) on the dobs_envs environments.

A policy is evaluated on episodes ``k = 0..K-1`` reset with seed ``seed + k``; the
environments draw the initial state (and disturbance) from that seed, so every
policy sees the same initial conditions. The Gymnasium envs wrap the same
PettingZoo env, so centralised and per-agent policies can be compared directly
(:func:`evaluate_policy` records ``x(0)`` of every episode to make that checkable).

Per-episode metrics (read from the underlying simulation, identical for all policies):

- ``return``: sum of the team reward ``-(e'Qe + u'Ru) * period``;
- ``final_tracking_error``: the task error at the last step: ``||x - x_r||`` (tracking),
  ``||x||`` (stabilisation), the position disagreement ``||p - pbar 1||`` (hetero_mas
  rendezvous) -- the environment's ``task_error()`` (what its ``render()`` plots);
- ``rms_estimation_error``: RMS over time and observer nodes of ``||xhat_i - x||`` of the
  environment's distributed observer (it runs whatever the policy does);
- ``control_effort``: ``int ||u||^2 dt`` of the applied (clipped) input;
- ``cost``: ``-return``, the episode's LQ cost J (with the termination penalty);
- ``transient_cost``: the part of ``cost`` incurred in the first ``TRANSIENT_S`` (2 s);
- ``steady_state_error``: RMS of the task error over the last ``STEADY_S`` (5 s) of the
  episode;
- ``failed``: the episode terminated early (state bound exceeded or non-finite state);
- ``rms_policy_estimation_error`` (policies exposing ``estimates``, e.g. the
  decentralised baseline): RMS error of the estimates the policy acted on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

__all__ = ["EpisodeResult", "evaluate_policy", "summarise", "METRICS"]

METRICS = ("return", "cost", "transient_cost", "steady_state_error", "final_tracking_error",
           "rms_estimation_error", "control_effort", "failed")

#: window of the transient cost (first seconds) and of the steady-state error (last seconds)
TRANSIENT_S = 2.0
STEADY_S = 5.0


def _base(env):
    from baselines.references import base_env

    return base_env(env)


@dataclass
class EpisodeResult:
    seed: int
    ret: float
    length: int
    failed: bool
    final_tracking_error: float
    rms_estimation_error: float
    control_effort: float
    rms_policy_estimation_error: float | None
    transient_cost: float
    steady_state_error: float
    x0: np.ndarray
    t: np.ndarray = field(repr=False)
    tracking_error: np.ndarray = field(repr=False)
    estimation_error: np.ndarray = field(repr=False)  # mean over nodes of ||xhat_i - x|| per step

    @property
    def cost(self) -> float:
        return -self.ret

    def as_dict(self) -> dict:
        return {"seed": self.seed, "return": self.ret, "cost": self.cost, "transient_cost": self.transient_cost,
                "steady_state_error": self.steady_state_error, "length": self.length, "failed": self.failed,
                "final_tracking_error": self.final_tracking_error, "rms_estimation_error": self.rms_estimation_error,
                "control_effort": self.control_effort, "rms_policy_estimation_error": self.rms_policy_estimation_error,
                "x0": [float(v) for v in self.x0]}


def _task_error(base) -> float:
    return float(base.task_error())


def run_episode(env, policy: Callable, seed: int, *, parallel: bool) -> EpisodeResult:
    """One episode of ``policy`` on ``env`` (parallel: dict API; else Gymnasium API)."""
    base = _base(env)
    if hasattr(policy, "reset"):
        policy.reset()
    out = env.reset(seed=int(seed))
    obs = out[0]
    period = float(base.control_period)
    xs = base.state_layout()["x"]
    x0 = np.asarray(base.state(), dtype=np.float64)[xs].copy()
    ts, te, ee = [0.0], [_task_error(base)], [float(np.mean(base.estimation_errors() ** 2))]
    ret, effort, failed, n = 0.0, 0.0, False, 0
    rewards = []
    pol_err2, pol_cnt = 0.0, 0
    agent0 = base.possible_agents[0]
    has_est = hasattr(policy, "estimates")
    while True:
        act = policy(obs)
        if has_est and getattr(policy, "estimates", None):
            x = np.asarray(base.state(), dtype=np.float64)[xs]
            for v in policy.estimates.values():
                pol_err2 += float(np.sum((np.asarray(v) - x) ** 2))
                pol_cnt += 1
        if parallel:
            obs, rew, term, trunc, _ = env.step(act)
            r = float(rew[agent0])
            done_term = any(term.values())
            done = done_term or any(trunc.values()) or not base.agents
        else:
            obs, r, done_term, truncated, _ = env.step(act)
            r = float(r)
            done = done_term or truncated
        n += 1
        ret += r
        rewards.append(r)
        effort += float(np.sum(base.applied_input ** 2)) * period
        ts.append(n * period)
        te.append(_task_error(base))
        ee.append(float(np.mean(base.estimation_errors() ** 2)))
        if done:
            failed = bool(done_term)
            break
    ee_arr = np.sqrt(np.asarray(ee))
    n_tr = max(1, int(round(TRANSIENT_S / period)))
    n_ss = max(1, int(round(STEADY_S / period)))
    te_arr = np.asarray(te)
    return EpisodeResult(
        seed=int(seed), ret=ret, length=n, failed=failed, final_tracking_error=te[-1],
        rms_estimation_error=float(math.sqrt(np.mean(ee))), control_effort=effort,
        rms_policy_estimation_error=float(math.sqrt(pol_err2 / pol_cnt)) if pol_cnt else None,
        transient_cost=-float(np.sum(rewards[:n_tr])),
        steady_state_error=float(np.sqrt(np.mean(te_arr[-n_ss:] ** 2))),
        x0=x0, t=np.asarray(ts), tracking_error=np.asarray(te), estimation_error=ee_arr,
    )


def evaluate_policy(env, policy: Callable, episodes: int, seed: int, *, parallel: bool,
                    progress: bool = False, desc: str = "") -> list[EpisodeResult]:
    """Run ``policy`` for ``episodes`` episodes reset with seeds ``seed, seed + 1, ...``.

    The environments draw the initial state (and reference, disturbance, fault processes) from the
    reset seed, so two policies evaluated with the same ``seed`` and ``episodes`` see the same
    episodes: the ratio of their episode costs is the benchmark's cost ratio ``J / J_paper`` when
    the second policy is the paper's controller (:class:`baselines.policies.SeparationPolicy`).

    Parameters
    ----------
    env : PettingZoo ParallelEnv or Gymnasium Env
        A dobs_envs environment (``tracking_v0.parallel_env()``, ``gym.make("dobs_envs/Tracking-v0")``,
        or either wrapped); the metrics are read from the underlying simulation.
    policy : callable
        ``policy(observations) -> actions``: a dict per agent when ``parallel`` is true, else one
        array for the centralised Gymnasium view. A ``reset()`` method, if any, is called before
        every episode.
    episodes : int
        Number of episodes.
    seed : int
        Seed of the first episode. Use the tuning range (20000-29999, :mod:`agents.training.seeds`) while you
        develop a policy; the benchmark's evaluation range 10000-19999 is for final tables.
    parallel : bool
        ``True`` for the PettingZoo dict API, ``False`` for the Gymnasium API.
    progress : bool
        Show a progress bar.
    desc : str
        Label of the progress bar.

    Returns
    -------
    list of EpisodeResult
        One per episode, in seed order; ``result.cost`` is the episode's cost ``J`` (with the
        termination penalty), ``result.failed`` whether it left the state bound.
    """
    it = range(episodes)
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(it, desc=desc or "evaluate", unit="ep", leave=False)
    return [run_episode(env, policy, seed + k, parallel=parallel) for k in it]


def summarise(results: list[EpisodeResult]) -> dict[str, Any]:
    """Mean and std over episodes of every metric (``failure_rate`` for ``failed``)."""
    def ms(vals):
        a = np.asarray(vals, dtype=np.float64)
        return float(np.mean(a)), float(np.std(a))

    out: dict[str, Any] = {"episodes": len(results), "seeds": [r.seed for r in results]}
    for key, attr in (("return", "ret"), ("cost", "cost"), ("transient_cost", "transient_cost"),
                      ("steady_state_error", "steady_state_error"), ("final_tracking_error", "final_tracking_error"),
                      ("rms_estimation_error", "rms_estimation_error"), ("control_effort", "control_effort"),
                      ("length", "length")):
        out[f"{key}_mean"], out[f"{key}_std"] = ms([getattr(r, attr) for r in results])
    out["failure_rate"] = float(np.mean([r.failed for r in results]))
    pe = [r.rms_policy_estimation_error for r in results if r.rms_policy_estimation_error is not None]
    out["rms_policy_estimation_error_mean"] = float(np.mean(pe)) if pe else None
    return out
