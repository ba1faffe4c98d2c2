"""Stable-Baselines3 ``VecEnv`` s of the agents: :mod:`~agents.vecenv.batched_core` (``CoreVecEnv``: every copy of a
dobs_envs environment in one batched compiled core), :mod:`~agents.vecenv.parallel` (``ParallelVecEnv``: copies of
any PettingZoo parallel env, one slot per (copy, agent)) and :mod:`~agents.vecenv.slots` (``SlotEncoder``: the
shared slot encoding both use). Which one a training run steps is :mod:`agents.training.env_factory`'s choice."""
