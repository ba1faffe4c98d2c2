"""SB3 ``VecEnv`` adapter for PettingZoo parallel environments (parameter sharing).

Every ``(env copy, agent)`` pair is one VecEnv *slot*: with ``C`` copies and the
agents ``a_0..a_{M-1}`` (``possible_agents`` order, fixed), slot ``c * M + j`` is
agent ``a_j`` of copy ``c``. One SB3 policy therefore acts for every agent
(parameter sharing), and SB3 sees ``C * M`` independent single-agent streams.

Written here instead of SuperSuit, whose SB3 path is broken (``seed`` raises
AttributeError, time-limit truncation is reported as termination so SB3 does not
bootstrap, processes hang at exit).

Semantics
---------
- **Autoreset.** When a copy's episode ends (every agent terminated or truncated,
  or the env has no live agents left), each of its slots reports ``done=True``,
  ``info["terminal_observation"]`` (that agent's last observation, encoded like any
  observation) and the copy is reset; the returned observation is the first one of
  the new episode (SB3 convention).
- **Truncation vs termination.** ``info["TimeLimit.truncated"]`` is True only when
  the agent was truncated and *not* terminated, so SB3 bootstraps the value of
  time-limit ends and does not bootstrap real terminations. Our environments are
  team environments: agents end together. If a PettingZoo env ends some agents
  before others, the copy is ended for all of them at that step; agents that had
  neither flag set are reported as truncated (their return is bootstrapped).
- **Seeding.** :meth:`seed` (or ``reset`` after :meth:`seed`) resets copy ``c``
  with ``seed + c``; autoresets after that use the copy's own RNG, so a seeded run
  is reproducible. :meth:`seed` returns one seed per slot (the copy's seed).
- **Heterogeneous agents.** Observations are flattened and zero-padded to the
  largest agent observation; with ``agent_id=True`` a one-hot agent index is
  appended (so a shared policy can tell agents apart). The shared action space is
  a Box of the largest action size; agent ``a`` uses the first ``dim(a)``
  components (the rest are ignored) and its actions are clipped to its own bounds.
  The shared bounds are the element-wise union of the bounds of the agents that
  have that component (see :class:`SlotEncoder`). With ``rescale_actions=True``
  the shared action space is ``[-1, 1]^d`` and each agent's first ``dim(a)``
  components are mapped affinely onto its own box (recommended for PPO, whose
  Gaussian policy starts near 0 with unit-scale noise).
- ``get_attr`` / ``set_attr`` / ``env_method`` address slots; each call is made
  once per distinct copy among the requested slots and the result is repeated for
  every requested slot of that copy (so ``env_method("reset")`` never resets a
  copy twice).
"""
from __future__ import annotations

import warnings
from typing import Any, Callable, Sequence

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from dobs_envs.linalg.validation import check_seed

from .slots import SlotEncoder

__all__ = ["ParallelVecEnv"]


class ParallelVecEnv(VecEnv):
    """SB3 VecEnv over ``n_envs`` copies of a PettingZoo ``ParallelEnv`` (see module doc).

    Parameters
    ----------
    env_fns : one factory per copy, each returning a *new* ParallelEnv.
    agent_id : append a one-hot agent id to observations.
    rescale_actions : shared actions in ``[-1, 1]``, mapped onto each agent's bounds.
    """

    def __init__(self, env_fns: Sequence[Callable[[], Any]], agent_id: bool = False, rescale_actions: bool = False):
        if len(env_fns) < 1:
            raise ValueError("ParallelVecEnv needs at least one environment factory")
        self.envs = [fn() for fn in env_fns]
        if len({id(e) for e in self.envs}) != len(self.envs):
            raise ValueError("every env factory must return a new ParallelEnv instance")
        first = self.envs[0]
        agents = list(first.possible_agents)
        for e in self.envs[1:]:
            if list(e.possible_agents) != agents:
                raise ValueError("all environment copies must have the same possible_agents")
        self.encoder = SlotEncoder(agents, {a: first.observation_space(a) for a in agents},
                                   {a: first.action_space(a) for a in agents}, agent_id=agent_id,
                                   rescale_actions=rescale_actions)
        self.agents = agents
        self.n_agents = len(agents)
        self.n_copies = len(self.envs)
        self._closed = False
        self._actions = None
        # per-copy seeds for the next reset (None = no reseeding)
        self._copy_seeds: list[int | None] = [None] * self.n_copies
        super().__init__(self.n_copies * self.n_agents, self.encoder.observation_space, self.encoder.action_space)
        self._buf_obs = np.zeros((self.num_envs,) + self.observation_space.shape, dtype=np.float32)

    # ------------------------------------------------------------------ slot mapping
    def slot(self, copy: int, agent: int | str) -> int:
        j = self.agents.index(agent) if isinstance(agent, str) else int(agent)
        return copy * self.n_agents + j

    def slot_info(self, slot: int) -> tuple[int, str]:
        """``slot -> (copy index, agent name)``."""
        c, j = divmod(int(slot), self.n_agents)
        return c, self.agents[j]

    def _copies(self, indices: VecEnvIndices) -> list[int]:
        return [divmod(i, self.n_agents)[0] for i in self._get_indices(indices)]

    # ------------------------------------------------------------------ core API
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        seed = check_seed(seed, "seed")  # fractional or negative seeds are refused, never truncated
        if seed is None:
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        self._copy_seeds = [seed + c for c in range(self.n_copies)]
        return [self._copy_seeds[c] for c in range(self.n_copies) for _ in range(self.n_agents)]

    def _copy_options(self, c: int) -> dict:
        # SB3 keeps options per slot; a copy uses the options of its first slot
        return self._options[c * self.n_agents] if self._options else {}

    def _write_copy_obs(self, c: int, obs: dict, buf: np.ndarray) -> None:
        base = c * self.n_agents
        for j, a in enumerate(self.agents):
            buf[base + j] = self.encoder.encode(j, obs[a]) if a in obs else self.encoder.encode(j, np.zeros(0))

    def _reset_copy(self, c: int, seed=None, options=None):
        kw = {}
        if seed is not None:
            kw["seed"] = seed
        if options:
            kw["options"] = options
        out = self.envs[c].reset(**kw)
        obs, infos = out if isinstance(out, tuple) else (out, {})
        infos = infos or {}
        for j, a in enumerate(self.agents):
            self.reset_infos[c * self.n_agents + j] = dict(infos.get(a, {}))
        return obs

    def reset(self):
        for c in range(self.n_copies):
            obs = self._reset_copy(c, self._copy_seeds[c], self._copy_options(c))
            self._write_copy_obs(c, obs, self._buf_obs)
        self._copy_seeds = [None] * self.n_copies
        self._reset_seeds()
        self._reset_options()
        return self._buf_obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        actions = self._actions.reshape(self.num_envs, -1)
        self._actions = None
        M = self.n_agents
        rews = np.zeros(self.num_envs, dtype=np.float32)
        dones = np.zeros(self.num_envs, dtype=bool)
        infos: list[dict] = [{} for _ in range(self.num_envs)]
        for c, env in enumerate(self.envs):
            live = list(env.agents)
            act = {a: self.encoder.decode(j, actions[c * M + j]) for j, a in enumerate(self.agents) if a in live}
            obs, rew, term, trunc, info = env.step(act)
            info = info or {}
            for j, a in enumerate(self.agents):
                s = c * M + j
                rews[s] = float(rew.get(a, 0.0))
                infos[s] = dict(info.get(a, {}))
                if a in obs:
                    self._buf_obs[s] = self.encoder.encode(j, obs[a])
            ended = [bool(term.get(a, False) or trunc.get(a, False)) for a in self.agents if a in live]
            copy_done = (not env.agents) or any(ended)
            if copy_done:
                for j, a in enumerate(self.agents):
                    s = c * M + j
                    t_ = bool(term.get(a, False))
                    dones[s] = True
                    infos[s]["terminal_observation"] = self._buf_obs[s].copy()
                    # truncated only: bootstrap; agents ended by a teammate count as truncated
                    infos[s]["TimeLimit.truncated"] = not t_
                new_obs = self._reset_copy(c, None, None)
                self._write_copy_obs(c, new_obs, self._buf_obs)
            else:
                for j in range(M):
                    infos[c * M + j]["TimeLimit.truncated"] = False
        return self._buf_obs.copy(), rews, dones, infos

    def close(self) -> None:
        if self._closed:
            return
        for e in self.envs:
            try:
                e.close()
            except Exception as exc:  # pragma: no cover - best effort
                warnings.warn(f"closing a ParallelEnv copy failed: {exc!r}")
        self._closed = True

    @property
    def closed(self) -> bool:
        return self._closed

    # ------------------------------------------------------------------ attribute access
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        copies = self._copies(indices)
        if attr_name == "render_mode":  # optional in PettingZoo envs
            return [getattr(self.envs[c], "render_mode", None) for c in copies]
        vals = {c: getattr(self.envs[c], attr_name) for c in dict.fromkeys(copies)}
        return [vals[c] for c in copies]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        for c in dict.fromkeys(self._copies(indices)):
            setattr(self.envs[c], attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        copies = self._copies(indices)
        vals = {c: getattr(self.envs[c], method_name)(*method_args, **method_kwargs) for c in dict.fromkeys(copies)}
        return [vals[c] for c in copies]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        def wrapped(env) -> bool:
            seen = set()
            while env is not None and id(env) not in seen:
                if isinstance(env, wrapper_class):
                    return True
                seen.add(id(env))
                env = getattr(env, "env", None)
            return False

        copies = self._copies(indices)
        return [wrapped(self.envs[c]) for c in copies]

    # ------------------------------------------------------------------ rendering
    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.render_mode != "rgb_array":
            warnings.warn(f"render_mode is {self.render_mode!r}; get_images needs 'rgb_array'")
            return [None] * self.n_copies
        return [e.render() for e in self.envs]

    def render(self, mode: str | None = None):
        """Renders the copies (one image per copy, tiled by SB3 for ``rgb_array``)."""
        if self.render_mode == "human" and mode in (None, "human"):
            for e in self.envs:
                e.render()
            return None
        return super().render(mode=mode)
