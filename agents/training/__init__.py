"""Training an agent and reading a trained one back.

:mod:`~agents.training.train` (the driver: ``train``, ``resume``), :mod:`~agents.training.algos` (the algorithm
backends: SB3, SBX, sb3-contrib), :mod:`~agents.training.recipes` (a run's recipe from the hyperparameter files),
:mod:`~agents.training.env_factory` (the VecEnv a run trains on), :mod:`~agents.training.runs` (run directories),
:mod:`~agents.training.run_pickles` (their pickles read as data), :mod:`~agents.training.loading` (a saved run acting
and evaluated on its task), :mod:`~agents.training.hybrid` (residual RL and the behaviour-cloning warm start),
:mod:`~agents.training.curves` (learning curves) and :mod:`~agents.training.seeds` (the disjoint seed ranges).
Importing this package imports none of them (no torch, SB3 or JAX)."""
