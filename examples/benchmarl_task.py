"""A BenchMARL task family built from the dobs_envs PettingZoo environments.

BenchMARL (https://github.com/facebookresearch/BenchMARL) defines tasks as a ``Task`` enum
plus a ``TaskClass`` that builds the TorchRL environment; this module is such a pair for the
five registered dobs_envs environments (the four tasks and ``tracking_lossy``), wrapped by TorchRL's own ``PettingZooWrapper``. Parameter
sharing (BenchMARL's default, one group ``controller`` holding every controller node) needs
identical agent spaces, so the default task config turns on ``normalized_actions`` and
``padded_observations``. Usage (one MAPPO iteration; see tests/clients_heavy/test_benchmarl.py)::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig
    from benchmarl_task import DobsEnvsTask

    config = ExperimentConfig.get_from_yaml()
    config.max_n_frames = 6_000      # one iteration; BenchMARL's default budget is 3 M frames
    config.loggers = ["csv"]         # the default also logs to wandb
    experiment = Experiment(task=DobsEnvsTask.TRACKING.get_task(), algorithm_config=MappoConfig.get_from_yaml(),
                            model_config=MlpConfig.get_from_yaml(), critic_model_config=MlpConfig.get_from_yaml(),
                            seed=0, config=config)
    experiment.run()

``DobsEnvsTask.TRACKING.get_task({"max_cycles": 100, ...})`` takes any environment options.
"""
from __future__ import annotations

import copy
import importlib
from typing import Callable, Dict, List, Optional

from benchmarl.environments.common import Task, TaskClass
from torchrl.data import Composite
from torchrl.envs import EnvBase, PettingZooWrapper

from dobs_envs.registry import ENVIRONMENTS

#: environment options under every task config: identical agent spaces (parameter sharing)
DEFAULT_CONFIG = {"normalized_actions": True, "padded_observations": True}


class DobsEnvsClass(TaskClass):
    """Builds ``dobs_envs.<name>_v0.parallel_env(**config)`` wrapped by TorchRL's ``PettingZooWrapper``."""

    def _parallel_env(self):
        module = importlib.import_module(ENVIRONMENTS[self.name.lower()].module)
        return module.parallel_env(**copy.deepcopy(self.config))

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: Optional[int],
                    device) -> Callable[[], EnvBase]:
        return lambda: PettingZooWrapper(env=self._parallel_env(), seed=seed, device=device,
                                         categorical_actions=True, return_state=False)

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        """The episode length in control steps (``max_cycles``, or the horizon's)."""
        steps = self._parallel_env().max_cycles
        if steps is None:
            raise ValueError(f"task {self.name}: BenchMARL needs a finite episode; got horizon=inf, pass max_cycles")
        return int(steps)

    def group_map(self, env: EnvBase) -> Dict[str, List[str]]:
        return env.group_map

    def _group_keys(self, env: EnvBase, keep: str) -> Composite:
        spec = env.observation_spec.clone()
        for group in self.group_map(env):
            for key in list(spec[group].keys()):
                if key != keep:
                    del spec[group][key]
        return spec

    def observation_spec(self, env: EnvBase) -> Composite:
        return self._group_keys(env, "observation")

    def info_spec(self, env: EnvBase) -> Optional[Composite]:
        return self._group_keys(env, "info")

    def state_spec(self, env: EnvBase) -> Optional[Composite]:
        return None

    def action_mask_spec(self, env: EnvBase) -> Optional[Composite]:
        return None

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec

    @staticmethod
    def env_name() -> str:
        return "dobs_envs"


class DobsEnvsTask(Task):
    """The dobs_envs environments as BenchMARL tasks (``DobsEnvsTask.TRACKING.get_task(config)``)."""

    TRACKING = None
    TRACKING_LOSSY = None
    DISTURBANCE_REJECTION = None
    HETERO_MAS = None
    RANDOM_NETWORK = None

    @staticmethod
    def associated_class():
        return DobsEnvsClass

    def get_task(self, config: Optional[dict] = None) -> TaskClass:
        """The task with ``config`` (environment options) over :data:`DEFAULT_CONFIG`."""
        return DobsEnvsClass(name=self.name, config={**DEFAULT_CONFIG, **(config or {})})
