"""Reference policies that bracket the paper's separation-based controller.

Same calling convention as :mod:`baselines.policies`: construct with the
environment, call :meth:`reset` at every episode start, then
``policy(observations) -> actions`` (PettingZoo parallel envs, dict per agent).
:class:`Centralized` turns any of them into ``policy(obs) -> action`` for the
centralised Gymnasium environments.

- :class:`OraclePolicy` -- **full-state oracle**. The paper's law of the scenario
  (``u^k = K^k x (+ r^k)``, or the sliding-mode laws) applied to the *true* state
  ``x`` instead of the estimate ``xhat_{links[k]}``: the best any separation-based
  controller with the same ``K`` can hope for. It **cheats on purpose**: it reads
  ``x`` from the environment's global :meth:`state` (privileged information no
  controller node has).
- :class:`DecentralizedPolicy` -- **decentralised control without communication**.
  Controller ``k`` runs, by itself, the Lemma-2 local observer of its linked node
  ``i = links[k]`` *without* the consensus term ``H_i`` of eq. (zidynamic), i.e. the
  distributed observer with the O-O graph removed::

      z' = Ebar_i z + Fbar_i y_i + (I - Gbar_i C_i) B^k u^k,   xhat = z + Gbar_i y_i,

  from ``z(0) = 0``, fed only with its own measurement ``y_i`` (observation
  component ``"y"``) and its own input ``u^k`` (the other controllers' inputs are
  unknown to it), and applies the paper's law (same ``K^k``, ``r^k``, sliding-mode
  gains) to that local estimate. The strongly detectable part ``T_id^T x``
  converges; the ``T_iu`` part is an open-loop model prediction, so this is what
  the paper's O-O communication buys. Between samples the observer is integrated
  exactly (matrix exponential) with ``u^k`` held and ``y_i`` interpolated linearly
  between the two samples (``y`` is only available at the control instants).
- :class:`ZeroInputPolicy` -- ``u = 0`` (the open-loop plant).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from .policies import ZeroPolicy

__all__ = ["OraclePolicy", "DecentralizedPolicy", "ZeroInputPolicy", "Centralized", "base_env"]


def base_env(env):
    """The dobs_envs parallel environment behind ``env`` (parallel env, Gymnasium env or wrapper)."""
    e = env
    for _ in range(16):
        if hasattr(e, "scenario") and hasattr(e, "possible_agents"):
            return e
        if hasattr(e, "parallel_env"):
            e = e.parallel_env
        elif hasattr(e, "unwrapped") and e.unwrapped is not e:
            e = e.unwrapped
        elif hasattr(e, "env"):
            e = e.env
        else:
            break
    raise TypeError(f"{type(env).__name__} is not a dobs_envs environment (no .scenario)")


def _separation(env, kind):
    from .policies import SeparationPolicy

    return SeparationPolicy(env, kind)


class _EstimateSubstitution:
    """Runs the paper's :class:`~baselines.policies.SeparationPolicy` with the
    ``"xhat"`` component of each observation replaced by another estimate."""

    def __init__(self, env, kind=None):
        self.env = base_env(env)
        self.inner = _separation(self.env, kind)
        self.kind = self.inner.kind
        self.agents = list(self.env.possible_agents)
        self._xhat = {}
        for a in self.agents:
            lay = self.env.observation_layout(a)
            if "xhat" not in lay:
                raise ValueError(f"agent {a!r}'s observation has no 'xhat' component ({list(lay)})")
            self._xhat[a] = lay["xhat"]
        #: estimate each controller acted on at the last call (agent -> (n,))
        self.estimates: dict = {}

    def reset(self) -> None:
        self.inner.reset()
        self.estimates = {}

    def _act_on(self, observations: dict, estimates: dict) -> dict:
        obs = {}
        for a, o in observations.items():
            o = np.array(o, dtype=np.float64, copy=True)
            o[self._xhat[a]] = estimates[a]
            obs[a] = o
        self.estimates = {a: np.asarray(v, dtype=np.float64).copy() for a, v in estimates.items()}
        return self.inner(obs)


class OraclePolicy(_EstimateSubstitution):
    """Full-state oracle: the paper's law with ``xhat`` replaced by the true ``x``.

    Cheats on purpose (reads ``x`` from ``env.state()``); an upper bound for
    separation-based control with the same gains. ``kind`` as in
    :class:`~baselines.policies.SeparationPolicy`.
    """

    name = "oracle (full state)"
    information = "full state"

    def __init__(self, env, kind=None):
        super().__init__(env, kind)
        self._x = self.env.state_layout()["x"]

    def __call__(self, observations: dict) -> dict:
        x = np.asarray(self.env.state(), dtype=np.float64)[self._x]
        return self._act_on(observations, {a: x for a in observations})


class DecentralizedPolicy(_EstimateSubstitution):
    """No communication: each controller's own consensus-free local observer (see module doc)."""

    name = "decentralised (no communication)"
    information = "own measurement, no communication"

    def __init__(self, env, kind=None):
        super().__init__(env, kind)
        e = self.env
        sc, p = e.scenario, e.params
        T = float(e.control_period)
        self.period = T
        n = p.n_states
        self._y, self._obs = {}, {}
        self._Phi, self._Gb, self._low, self._high = {}, {}, {}, {}
        for k, a in enumerate(self.agents):
            lay = e.observation_layout(a)
            if "y" not in lay:
                raise ValueError(f"the decentralised policy needs the 'y' component in agent {a!r}'s observation ({list(lay)})")
            self._y[a] = lay["y"]
            i = e.links[k]
            p_i = lay["y"].stop - lay["y"].start
            E = np.asarray(p.E_bar[i])
            F = np.asarray(p.F_bar[i])[:, :p_i]
            Gb = np.asarray(p.G_bar[i])[:, :p_i]
            Ci = np.asarray(p.C[i])[:p_i]
            Bk = np.asarray(sc.B)[:, e.channel_slices[k]]
            Bu = (np.eye(n) - Gb @ Ci) @ Bk  # eq. (barB_i) restricted to its own channel
            mk = Bk.shape[1]
            # augmented state (z, y, dy/dt, u): z' = E z + F y + Bu u, y' = dy/dt, (dy/dt)' = 0, u' = 0
            dim = n + 2 * p_i + mk
            M = np.zeros((dim, dim))
            M[:n, :n] = E
            M[:n, n:n + p_i] = F
            M[:n, n + 2 * p_i:] = Bu
            M[n:n + p_i, n + p_i:n + 2 * p_i] = np.eye(p_i)
            Phi = expm(M * T)[:n]
            # z(T) = Pz z + Py y0 + Pg (y1 - y0)/T + Pu u
            self._Phi[a] = (Phi[:, :n], Phi[:, n:n + p_i], Phi[:, n + p_i:n + 2 * p_i] / T, Phi[:, n + 2 * p_i:])
            self._Gb[a] = Gb
            sp = e.action_space(a)
            self._low[a], self._high[a] = np.asarray(sp.low, float), np.asarray(sp.high, float)
        self.reset()

    def reset(self) -> None:
        super().reset()
        self._z = None
        self._prev_y = None
        self._prev_u = None

    def __call__(self, observations: dict) -> dict:
        ys = {a: np.asarray(o, dtype=np.float64)[self._y[a]] for a, o in observations.items()}
        if self._z is None:
            self._z = {a: np.zeros(self.env.n_states) for a in self.agents}  # z_i(0) = 0 (paper)
        else:
            for a in observations:
                Pz, Py, Pg, Pu = self._Phi[a]
                y0 = self._prev_y[a]
                self._z[a] = Pz @ self._z[a] + Py @ y0 + Pg @ (ys[a] - y0) + Pu @ self._prev_u[a]
        xhat = {a: self._z[a] + self._Gb[a] @ ys[a] for a in observations}
        acts = self._act_on(observations, xhat)
        # the input the plant receives (the environment clips to the action bounds)
        self._prev_u = {a: np.clip(np.asarray(u, dtype=np.float64), self._low[a], self._high[a]) for a, u in acts.items()}
        self._prev_y = ys
        return acts


class ZeroInputPolicy(ZeroPolicy):
    """``u^k = 0`` for every controller node (the uncontrolled plant); :class:`baselines.policies.ZeroPolicy`
    under the benchmark's name."""

    name = "zero input"
    information = "none"


class Centralized:
    """``policy(obs) -> action`` on a centralised dobs_envs Gymnasium env from a
    per-agent policy class: ``Centralized(gym_env, OraclePolicy)``.

    Splits the concatenated observation with the env's ``agent_observation_slices``
    and concatenates the agents' inputs in agent order.
    """

    def __init__(self, env, policy_cls, *args, **kwargs):
        genv = getattr(env, "unwrapped", env)
        if not hasattr(genv, "parallel_env"):
            raise TypeError(f"{type(env).__name__} is not a centralised dobs_envs Gymnasium environment")
        self.genv = genv
        self.policy = policy_cls(genv.parallel_env, *args, **kwargs)
        self.name = getattr(self.policy, "name", policy_cls.__name__)

    def reset(self) -> None:
        self.policy.reset()

    def __call__(self, obs):
        g = self.genv
        acts = self.policy({a: obs[sl] for a, sl in zip(g.agents, g.agent_observation_slices)})
        return np.concatenate([np.asarray(acts[a], dtype=np.float64).reshape(-1) for a in g.agents])
