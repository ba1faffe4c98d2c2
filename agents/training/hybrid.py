"""Hybrid baselines: the paper's controller combined with learning (labelled as hybrids, not pure RL).

Residual RL (Johannink et al., 2019; Silver et al., 2018)
---------------------------------------------------------
The agent outputs a bounded correction ``a`` in ``[-1, 1]`` per input component and the
plant receives

    u = u_paper(obs) + scale * b * a

where ``u_paper`` is the paper's separation controller acting on the *same observation*
(:class:`baselines.policies.SeparationPolicy`: ``u^k = K^k xhat_k + r^k`` on tracking),
``b`` the env's action bound and ``scale`` the residual authority (the recipe's
``residual_scale``). The environment clips ``u`` to its bounds as for any policy. At
``a = 0`` the agent *is* the paper controller, so learning starts from a policy that
never fails. :class:`ResidualPolicy` is the composition (evaluation acts on the
unmodified env); :class:`ResidualGymWrapper` (centralised) and
:class:`ResidualParallelEnv` (parameter-shared, one agent per controller node) expose
the correction as the action for training.

Behaviour-cloning warm start
----------------------------
:func:`behaviour_cloning_dataset` rolls out the paper controller on the *training*
env with Gaussian perturbations of the applied input (DART, Laskey et al., 2017: the
labels stay the clean controller's action, the states cover its neighbourhood);
:func:`pretrain_ppo` then fits PPO's Gaussian mean to the labels (mean squared error in
the agent's ``[-1, 1]`` action units) and its value network to the discounted returns
of the same rollouts. The observation and reward normalisers (``VecNormalize``) are
initialised from the rollouts first and the network is trained on the normalised data,
so RL continues from a policy that acts like the paper controller under exactly the
normaliser it will see.
"""
from __future__ import annotations

from typing import Any, Callable

import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = ["ResidualPolicy", "ResidualGymWrapper", "ResidualParallelEnv", "behaviour_cloning_dataset",
           "pretrain_ppo", "HYBRIDS"]

#: hybrid kinds (the ``hybrid`` argument of :func:`agents.training.train.train`)
HYBRIDS = ("residual", "bc")


def _check_scale(scale) -> float:
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"residual_scale must be a positive finite number (fraction of the action bound), got {scale!r}")
    return float(scale)


class ResidualPolicy:
    """``u = u_paper(obs) + scale * b * clip(correction(obs), -1, 1)``.

    Parameters
    ----------
    env : the dobs_envs environment the policy acts on: a PettingZoo parallel env
        (``parallel=True``; observations and actions are dicts) or a centralised
        Gymnasium env (``parallel=False``; arrays).
    correction : ``obs -> a`` in the same convention (dict or array), values in [-1, 1];
        ``None`` gives the paper controller alone.
    scale : residual authority as a fraction of the action bound.
    """

    def __init__(self, env, correction: Callable | None, scale: float, *, parallel: bool):
        from baselines.policies import CentralizedSeparationPolicy, SeparationPolicy

        self.scale = _check_scale(scale)
        self.parallel = bool(parallel)
        self.correction = correction
        if self.parallel:
            self.base = SeparationPolicy(env)
            self._amp = {a: self.scale * np.asarray(env.action_space(a).high, dtype=np.float64)
                         for a in env.possible_agents}
        else:
            self.base = CentralizedSeparationPolicy(env)
            self._amp = self.scale * np.asarray(env.unwrapped.action_space.high, dtype=np.float64)

    def reset(self) -> None:
        self.base.reset()
        if hasattr(self.correction, "reset"):
            self.correction.reset()

    def combine(self, obs, correction):
        """The applied input for observation ``obs`` and correction ``correction`` (advances the paper
        controller's internal state by one control period)."""
        u0 = self.base(obs)
        if self.parallel:
            return {a: u0[a] + self._amp[a] * np.clip(np.asarray(correction[a], dtype=np.float64), -1.0, 1.0)
                    for a in u0}
        return u0 + self._amp * np.clip(np.asarray(correction, dtype=np.float64), -1.0, 1.0)

    def __call__(self, obs):
        if self.correction is None:
            return self.base(obs)
        return self.combine(obs, self.correction(obs))


class ResidualGymWrapper(gym.Wrapper):
    """Centralised residual env: action ``a in [-1, 1]^m`` is the correction of :class:`ResidualPolicy`."""

    def __init__(self, env: gym.Env, scale: float):
        super().__init__(env)
        self._res = ResidualPolicy(env, None, scale, parallel=False)
        m = env.action_space.shape[0]
        self.action_space = spaces.Box(-1.0, 1.0, (m,), dtype=np.float32)
        self._obs = None

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._res.reset()
        self._obs = obs
        return obs, info

    def step(self, action):
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape or not np.all(np.isfinite(a)):
            raise ValueError(f"residual action must be a finite array of shape {self.action_space.shape}, got {a!r}")
        out = self.env.step(self._res.combine(self._obs, a))
        self._obs = out[0]
        return out


class ResidualParallelEnv:
    """PettingZoo parallel residual env: agent ``k``'s action ``Box(-1, 1)`` is its channel's correction.

    Everything else (observations, rewards, spaces of observations, agents, seeding)
    is the wrapped env's; ``env`` is the wrapped env (so ``base_env`` finds it).
    """

    def __init__(self, env, scale: float):
        self.env = env
        self._res = ResidualPolicy(env, None, scale, parallel=True)
        self.possible_agents = list(env.possible_agents)
        self.metadata = dict(getattr(env, "metadata", {}))
        self.render_mode = getattr(env, "render_mode", None)
        self._act = {a: spaces.Box(-1.0, 1.0, env.action_space(a).shape, dtype=np.float32) for a in self.possible_agents}
        self._obs = None

    @property
    def agents(self):
        return self.env.agents

    @property
    def unwrapped(self):
        return self.env

    def observation_space(self, agent):
        return self.env.observation_space(agent)

    def action_space(self, agent):
        try:
            return self._act[agent]
        except KeyError:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}") from None

    def reset(self, seed=None, options=None):
        obs, infos = self.env.reset(seed=seed, options=options)
        self._res.reset()
        self._obs = obs
        return obs, infos

    def step(self, actions: dict):
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        out = self.env.step(self._res.combine(self._obs, actions))
        self._obs = out[0]
        return out

    def render(self):
        return self.env.render()

    def close(self):
        self.env.close()

    def state(self):
        return self.env.state()


# ---------------------------------------------------------------------- behaviour cloning
def behaviour_cloning_dataset(make_env: Callable[[], gym.Env], episodes: int, seed: int, *,
                              noise: float = 0.1) -> dict[str, np.ndarray]:
    """Rollouts of the paper controller on the centralised env ``make_env()``.

    The applied input is the controller's plus ``N(0, (noise * b)^2)`` (clipped by the env);
    the label is the controller's clean input in ``[-1, 1]`` units (``u / b``).

    Returns
    -------
    dict with ``obs (T, d)``, ``act (T, m)`` in [-1, 1], ``rew (T,)``, ``done (T,)``
    (episode ends), ``episodes``.
    """
    from baselines.policies import CentralizedSeparationPolicy

    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes!r}")
    env = make_env()
    pol = CentralizedSeparationPolicy(env)
    b = np.asarray(env.unwrapped.action_space.high, dtype=np.float64)
    rng = np.random.default_rng(seed)
    O, A, R, D = [], [], [], []
    for k in range(episodes):
        obs, _ = env.reset(seed=int(seed) + k)
        pol.reset()
        done = False
        while not done:
            u = pol(obs)
            O.append(np.asarray(obs, dtype=np.float32))
            A.append(np.clip(u / b, -1.0, 1.0))
            obs, r, term, trunc, _ = env.step(u + noise * b * rng.standard_normal(b.shape))
            done = bool(term or trunc)
            R.append(float(r))
            D.append(done)
    env.close()
    return {"obs": np.asarray(O), "act": np.asarray(A, dtype=np.float32), "rew": np.asarray(R),
            "done": np.asarray(D, dtype=bool), "episodes": episodes}


def _init_normaliser(vecnorm, data: dict, gamma: float) -> None:
    """Initialise ``VecNormalize``'s running statistics from the rollouts (as if it had seen them)."""
    if vecnorm.norm_obs:
        vecnorm.obs_rms.update(data["obs"].astype(np.float64))
    if vecnorm.norm_reward:
        ret, rets = 0.0, []
        for r, d in zip(data["rew"], data["done"]):
            ret = ret * gamma + r  # VecNormalize's discounted running return
            rets.append(ret)
            if d:
                ret = 0.0
        vecnorm.ret_rms.update(np.asarray(rets))


def _discounted_returns(rew: np.ndarray, done: np.ndarray, gamma: float) -> np.ndarray:
    out = np.empty_like(rew)
    g = 0.0
    for t in range(len(rew) - 1, -1, -1):
        if done[t]:
            g = 0.0
        g = rew[t] + gamma * g
        out[t] = g
    return out


def pretrain_ppo(model, data: dict, *, epochs: int = 30, batch_size: int = 256, lr: float = 1e-3,
                 seed: int = 0) -> dict[str, float]:
    """Fit ``model`` (an SB3 PPO with a Gaussian MLP policy) to the rollouts ``data``.

    The actor's mean is regressed on the labels, the critic on the discounted returns
    (normalised like PPO's rewards will be). ``model.get_env()`` must be a
    ``VecNormalize`` (its statistics are initialised from ``data``) or an unnormalised VecEnv.

    Returns the final actor and critic mean squared errors.
    """
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    venv = model.get_env()
    gamma = float(model.gamma)
    obs, rew = data["obs"], data["rew"].astype(np.float64)
    if isinstance(venv, VecNormalize):
        _init_normaliser(venv, data, gamma)
        obs = venv.normalize_obs(obs)
        rew = venv.normalize_reward(rew)
    target_v = _discounted_returns(rew, data["done"], gamma)
    pol = model.policy
    dev = pol.device
    X = torch.as_tensor(np.asarray(obs, dtype=np.float32), device=dev)
    Y = torch.as_tensor(data["act"], device=dev)
    V = torch.as_tensor(target_v.astype(np.float32), device=dev)
    params = [p for n, p in pol.named_parameters() if n != "log_std"]
    opt = torch.optim.Adam(params, lr=lr)
    gen = torch.Generator().manual_seed(int(seed))
    n = X.shape[0]
    la = lv = float("nan")
    for _ in range(int(epochs)):
        perm = torch.randperm(n, generator=gen)
        for i in range(0, n, batch_size):
            idx = perm[i:i + batch_size]
            feats = pol.extract_features(X[idx], pol.pi_features_extractor)
            lat_pi, lat_vf = pol.mlp_extractor(feats)
            mean = pol.action_net(lat_pi)
            value = pol.value_net(lat_vf).squeeze(-1)
            loss_a = torch.mean((mean - Y[idx]) ** 2)
            loss_v = torch.mean((value - V[idx]) ** 2)
            opt.zero_grad()
            (loss_a + 0.5 * loss_v).backward()
            opt.step()
            la, lv = loss_a.item(), loss_v.item()
    return {"actor_mse": la, "critic_mse": lv, "samples": int(n)}


def residual_factory(make: Callable[[], Any], scale: float, *, parallel: bool) -> Callable[[], Any]:
    """Factory of the residual training env around ``make()``."""
    if parallel:
        return lambda: ResidualParallelEnv(make(), scale)
    return lambda: ResidualGymWrapper(make(), scale)
