"""Reference policies acting through the environment API (the same observations RL agents get).

The paper's separation-based controllers read, from each agent's observation,
the estimate ``xhat_{links[k]}`` its observer node sends over the C-O link
(component ``"xhat"``) and, for tracking, its reference command ``r^k``
(component ``"r"``); see :mod:`dobs_envs.envs.observation` for the layout.

- :class:`SeparationPolicy` -- ``policy(observations) -> actions`` for the
  PettingZoo parallel environments:

  * ``"feedback"`` (Theorem lfthm, eq. linearfeedback): ``u^k = K^k xhat``
  * ``"tracking"`` (Theorem reftrackthm): ``u^k = K^k xhat + r^k``
  * ``"sliding_mode"`` (Theorem smthm, eq. idealslidinglaw): ``u^k = K^k xhat - beta^k h((B^k)^T P xhat)``
  * ``"adaptive_sliding_mode"`` (Theorem adsmthm, eqs. hepsfunc, adlawbeta):
    ``u^k = K^k xhat - beta^k h_eps((B^k)^T P xhat)`` with ``beta^k`` kept
    internally and advanced once per call by the exact solution of the
    leakage law over one control period (as :mod:`dobs_envs.control.laws`); call
    :meth:`SeparationPolicy.reset` at every episode start.
  * ``"open_loop"`` (NE1): the scenario's prescribed input ``u(t)``, with ``t``
    counted internally from the control period (reset it per episode).

- :class:`CentralizedSeparationPolicy` -- ``policy(obs) -> action`` for the
  Gymnasium environments (``dobs_envs/Tracking-v0`` ...): splits the
  concatenated observation into the agents' observations, acts, and stacks the
  inputs.

Actions are float64 (the environments accept any float dtype and simulate in
float64; out-of-range values would be clipped by the environment). The policies compute
the inputs ``u`` and hand them over in the environment's action format
(``DObsParallelEnv.actions_from_inputs``: scaled and padded with ``normalized_actions``).
"""
from __future__ import annotations

import numpy as np

from dobs_envs.control import SeparationController

__all__ = ["SeparationPolicy", "CentralizedSeparationPolicy", "ZeroPolicy"]


def _unwrap(env):
    base = getattr(env, "unwrapped", env)
    while not hasattr(base, "scenario") and hasattr(base, "env"):
        base = base.env
    if not hasattr(base, "scenario"):
        raise TypeError(f"{type(env).__name__} is not a dobs_envs environment (no .scenario)")
    return base


class SeparationPolicy:
    """The scenario's paper controller acting on the agents' observations.

    Parameters
    ----------
    env : a dobs_envs parallel environment (or a wrapper of one). Its
        observation must contain the ``"xhat"`` component (and ``"r"`` for tracking).
    kind : controller law (default: the scenario's ``controller``; the tracking
        environment's is ``"tracking"``, the disturbance-rejection one's
        ``"adaptive_sliding_mode"``, the heterogeneous-MAS one's ``"feedback"``).
    """

    information = "own observer node"

    KINDS = ("open_loop", "feedback", "tracking", "sliding_mode", "adaptive_sliding_mode")

    def __init__(self, env, kind: str | None = None):
        base = _unwrap(env)
        sc = base.scenario
        kind = kind or sc.controller
        if kind not in self.KINDS:
            raise ValueError(f"kind must be one of {self.KINDS}, got {kind!r}")
        if kind == "open_loop":
            if sc.prescribed_input is None:
                raise ValueError("'open_loop' policy needs the scenario's prescribed_input")
            self._law = None
        else:
            if sc.K is None:
                raise ValueError(f"{kind!r} policy needs the scenario's feedback gain K")
            if kind in ("sliding_mode", "adaptive_sliding_mode") and sc.P is None:
                raise ValueError(f"{kind!r} policy needs the scenario's sliding-mode matrix P")
            # the laws themselves live in dobs_envs.control.laws (one implementation)
            self._law = SeparationController.from_scenario(sc, kind)
        self.kind = kind
        self._env = base
        self.agents = list(base.possible_agents)
        self.period = float(base.control_period)
        self._slices = tuple(base.channel_slices)
        self._widths = np.array([sl.stop - sl.start for sl in self._slices])
        self._m = int(self._widths.sum())
        self._xhat, self._r = {}, {}
        for a in self.agents:
            lay = base.observation_layout(a)
            if kind != "open_loop":
                if "xhat" not in lay:
                    raise ValueError(f"the {kind!r} policy reads 'xhat' from the observation; agent {a!r}'s observation has {list(lay)}")
                self._xhat[a] = lay["xhat"]
            if kind == "tracking":
                if "r" not in lay:
                    raise ValueError(f"the tracking policy reads 'r' from the observation; agent {a!r}'s observation has {list(lay)}")
                self._r[a] = lay["r"]
        self._signal = sc.prescribed_input
        self.reset()

    @property
    def beta(self) -> np.ndarray:
        """Current adaptive gains ``beta^k`` (one per controller node)."""
        return self._cstate.beta[0]

    @property
    def beta0(self) -> float:
        """Initial adaptive gain ``beta^k(0)``."""
        return self._law.beta0

    def reset(self) -> None:
        """Start of an episode: ``beta^k = beta^k(0)``, open-loop clock ``t = 0``."""
        self._cstate = self._law.initial_state(1) if self._law is not None else None
        self._steps = 0

    def __call__(self, observations: dict) -> dict:
        acts = self._env.actions_from_inputs(self.inputs(observations))
        return {a: acts[a] for a in observations}

    def inputs(self, observations: dict) -> np.ndarray:
        """The inputs ``u (m,)`` of the law for ``observations`` (advances the law's state)."""
        if self.kind == "open_loop":
            u = self._signal(self._steps * self.period)
            self._steps += 1
            return np.asarray(u, dtype=np.float64)
        # every input row j gets the estimate of the controller node owning it
        xs = np.stack([np.asarray(observations[a][self._xhat[a]], dtype=np.float64) for a in self.agents])
        xl = np.repeat(xs, self._widths, axis=0)[None]
        r = None
        if self.kind == "tracking":
            r = np.concatenate([np.asarray(observations[a][self._r[a]], dtype=np.float64) for a in self.agents])[None]
        u, self._cstate = self._law.act_rows(xl, r, self._cstate, self.period)
        self._steps += 1
        return u[0]


class CentralizedSeparationPolicy:
    """:class:`SeparationPolicy` for the centralised Gymnasium environments: ``policy(obs) -> action``."""

    def __init__(self, env, kind: str | None = None):
        genv = getattr(env, "unwrapped", env)
        if not hasattr(genv, "parallel_env"):
            raise TypeError(f"{type(env).__name__} is not a centralised dobs_envs Gymnasium environment")
        self.genv = genv
        self.policy = SeparationPolicy(genv.parallel_env, kind)

    def reset(self) -> None:
        self.policy.reset()

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        g = self.genv
        u = self.policy.inputs({a: obs[sl] for a, sl in zip(g.agents, g.agent_observation_slices)})
        return u / g.core.action_scale  # the centralised action (normalized_actions: u / bound)


class ZeroPolicy:
    """``u = 0`` for every agent (open loop; a lower baseline)."""

    def __init__(self, env):
        base = _unwrap(env)
        self._w = {a: base.action_space(a).shape[0] for a in base.possible_agents}

    def reset(self) -> None:
        pass

    def __call__(self, observations: dict) -> dict:
        return {a: np.zeros(self._w[a]) for a in observations}
