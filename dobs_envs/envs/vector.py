"""Native Gymnasium ``VectorEnv`` of the centralised environments (a thin adapter over the core).

``gym.make_vec("dobs_envs/Tracking-v0", num_envs=1024)`` (``vectorization_mode``
``"vector_entry_point"``, the default for these ids) builds a :class:`DObsVectorEnv`:
``num_envs`` copies in one :class:`~dobs_envs.envs.env_core.EnvCore`, advanced by one
compiled call per step. Copy ``c`` is the centralised env of the same id
(:class:`~dobs_envs.envs.centralized.CentralizedEnv`): same spaces, same
observations, rewards and episodes for the same seed (tested bit for bit).

- **Episode length**: ``max_episode_steps`` (from the registry, or given to ``make_vec``)
  control steps, then ``truncated``; ``max_cycles``/``horizon`` are not options here. As
  under ``gym.make``'s ``TimeLimit``, the termination penalty charges the scenario's ``t_end``.
- **Autoreset**: ``metadata["autoreset_mode"] = AutoresetMode.NEXT_STEP``. The step that ends
  a copy's episode returns its terminal observation; the next ``step`` resets that copy
  (its action is ignored) and returns the first observation of the new episode with reward
  0 and ``terminated = truncated = False``.
- **Seeding**: ``reset(seed=s)`` seeds copy ``c`` with ``s + c`` (a list seeds each copy);
  autoresets draw from the copy's own generator, so seeded runs are reproducible.
  ``reset(options={"reset_mask": mask})`` resets only the masked copies.
- **Infos** (the same keys from ``reset`` on, numeric arrays over the copies, each with its
  ``"_<key>"`` mask, all True): ``tracking_error (B,)``, ``estimation_errors (B, N)``,
  ``gamma (B, N)``, ``gamma_s (B, N)`` (and the task error, e.g. ``disagreement``), and
  ``termination_reason (B,)`` int8 codes of :data:`~dobs_envs.envs.env_core.REASONS` (0 none,
  1 state_bound_exceeded, 2 non_finite_state, 3 horizon; 0 for copies still running or
  just reset).
- ``threads`` (default: one per CPU core) advance disjoint ranges of at least 128 copies
  concurrently (the compiled step releases the GIL; same results for any number of threads).
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from gymnasium.vector import VectorEnv
from gymnasium.vector.utils import batch_space
from gymnasium.vector.vector_env import AutoresetMode

from ..linalg.validation import as_numeric, check_seed
from ..registry import ENVIRONMENTS, EnvEntry
from .adapter import CoreAdapter, central_spaces
from .centralized import reject_horizon_options
from .options import RENDER_MODES
from .rendering import LivePlot

__all__ = ["DObsVectorEnv"] + [f"make_vec_{name}" for name in ENVIRONMENTS]



def _reset_mask(mask, B: int) -> np.ndarray:
    """``options["reset_mask"]``: a boolean array of shape ``(B,)`` (Gymnasium's convention)."""
    try:
        m = np.asarray(mask)
    except (TypeError, ValueError):
        m = np.array(None, dtype=object)
    if m.dtype.kind != "b" or m.shape != (B,):
        raise ValueError(f"options['reset_mask'] must be a boolean array of shape ({B},), got "
                         f"{getattr(m, 'dtype', type(mask)).__str__()} array of shape {m.shape}")
    return m

class DObsVectorEnv(VectorEnv):
    """``num_envs`` copies of a dobs_envs environment class as one Gymnasium ``VectorEnv`` (see module doc).

    Parameters
    ----------
    env_class : a :class:`~dobs_envs.envs.parallel_env.DObsParallelEnv` subclass (its options and hooks)
    num_envs : int
    max_episode_steps : truncation horizon in control steps (None: the class default, ``t_end``)
    threads : threads advancing disjoint ranges of copies (None: one per CPU core; 1: serial)
    **kwargs : the options of ``env_class``
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": list(RENDER_MODES), "render_fps": 20}

    def __init__(self, env_class, num_envs: int = 1, *, max_episode_steps: int | None = None, threads: int | None = None,
                 **kwargs):
        reject_horizon_options(kwargs)
        # as gym.make's TimeLimit over a never-truncating env: the termination penalty charges the
        # scenario's t_end, the episode is cut after max_episode_steps (default: t_end too)
        self.core = c = env_class.make_core(num_envs, threads=threads, horizon=math.inf, **kwargs)
        c.max_cycles = c.penalty_cycles if max_episode_steps is None else max_episode_steps
        self.num_envs = c.num_envs
        self.metadata = {**self.metadata, "name": env_class.metadata["name"]}
        self.render_mode = c.options.render_mode
        self.single_observation_space, self.single_action_space, self.agent_observation_slices = central_spaces(c)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        #: the core's outputs as the centralised copies', their actions as inputs
        self._adapter = CoreAdapter(c)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._live = None  # render_mode="human": copy 0's live window

    def reset(self, *, seed=None, options: dict | None = None):
        B = self.num_envs
        if isinstance(seed, (list, tuple, np.ndarray)):
            seeds = [check_seed(s, "seed") for s in seed]
            if len(seeds) != B:
                raise ValueError(f"seed must be None, an int or one seed per copy ({B}), got {len(seeds)}")
        else:
            seed = check_seed(seed, "seed")
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options must be None or a dict (keys 'reset_mask', 'x0', 'v0', 'x_r0'), got "
                             f"{type(options).__name__} {options!r}")
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is not None:
            mask = _reset_mask(mask, B)
        super().reset(seed=seed if isinstance(seed, int) else None)
        rows = np.arange(B) if mask is None else np.flatnonzero(mask)
        if seed is None:
            seeds = None
        elif isinstance(seed, int):
            seeds = [seed + int(r) for r in rows]
        else:
            seeds = [seeds[r] for r in rows]
        self.core.reset(rows, seeds, options)
        self._autoreset[rows] = False
        if self.render_mode == "human":
            self._show(force=True)
        return self._obs(), self._infos(np.zeros(B, dtype=np.int8))

    def step(self, actions):
        a = np.asarray(as_numeric(actions, "actions"), dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise ValueError(f"actions must have shape {self.action_space.shape} (copies, inputs), got {a.shape}")
        a = self._adapter.central_inputs(a)
        again = self._autoreset
        if again.any():
            a = a.copy()
            a[again] = 0.0  # ignored: those copies start a new episode instead
        res = self.core.advance(a)
        rew, term, trunc, reason = res.reward.copy(), res.terminated.copy(), res.truncated.copy(), res.reason.copy()
        if again.any():
            rows = np.flatnonzero(again)
            self.core.reset(rows)
            rew[rows], term[rows], trunc[rows], reason[rows] = 0.0, False, False, 0
        self._autoreset = term | trunc
        if self.render_mode == "human":
            self._show(force=bool(self._autoreset[0]))
        return self._obs(), rew, term, trunc, self._infos(reason)

    def _obs(self) -> np.ndarray:
        return self._adapter.central_observations()  # a new array

    def _infos(self, reason) -> dict:
        info = self._adapter.info_arrays()
        info["termination_reason"] = reason
        for k in list(info):
            info[f"_{k}"] = np.ones(self.num_envs, dtype=bool)
        return info

    def render(self):
        """Copy 0's error plot: an RGB image (``render_mode="rgb_array"``), or the live window redrawn
        (``"human"``; ``reset``/``step`` redraw it too) and None."""
        if self.render_mode is None or self.core.history is None:
            return None
        if self.render_mode == "human":
            self._show(force=True)
            return None
        from .rendering import error_plot

        t, te, ee = self.core.history
        return error_plot(np.asarray(t), np.asarray(te), np.asarray(ee), title=self.metadata["name"])

    def _show(self, force: bool) -> None:
        if self.core.history is None:
            return
        if self._live is None:
            self._live = LivePlot(self.metadata["name"], fps=self.metadata["render_fps"])
        self._live.update(*self.core.history, force=force)

    def close_extras(self, **kwargs):
        if self._live is not None:
            self._live.close()
        self.core.close()


def _vec_entry(entry: EnvEntry):
    """The ``vector_entry_point`` ``make_vec_<name>`` of a registry entry."""
    def make_vec(num_envs: int = 1, max_episode_steps: int | None = None, **kwargs):
        return DObsVectorEnv(entry.load_class(), num_envs, max_episode_steps=max_episode_steps, **kwargs)

    make_vec.__name__ = make_vec.__qualname__ = f"make_vec_{entry.name}"
    make_vec.__doc__ = (f"``gym.make_vec({entry.gym_id!r}, num_envs=...)``: :class:`DObsVectorEnv` over "
                        f"``{entry.entry_point}``.")
    return make_vec


for _entry in ENVIRONMENTS.values():
    globals()[f"make_vec_{_entry.name}"] = _vec_entry(_entry)
del _entry
