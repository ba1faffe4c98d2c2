"""BenchMARL (the real client): one MAPPO iteration on a custom task built from our env
(examples/benchmarl_task.py: a Task enum + TaskClass over TorchRL's PettingZooWrapper),
every controller node in one parameter-shared group."""
from __future__ import annotations

import os
import sys

import pytest
import torch
from benchmarl.algorithms import IppoConfig, MappoConfig
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _example():
    """examples/benchmarl_task.py imported by name, as a user would (BenchMARL pickles the task class)."""
    examples = os.path.join(REPO, "examples")
    if examples not in sys.path:
        sys.path.insert(0, examples)
    import benchmarl_task

    return benchmarl_task


def _experiment(algorithm, task, tmp_path) -> Experiment:
    cfg = ExperimentConfig.get_from_yaml()
    cfg.max_n_iters = 1
    cfg.max_n_frames = None
    cfg.on_policy_collected_frames_per_batch = 40
    cfg.on_policy_n_envs_per_worker = 2
    cfg.on_policy_minibatch_size = 20
    cfg.on_policy_n_minibatch_iters = 2
    cfg.evaluation = False
    cfg.render = False
    cfg.loggers = []
    cfg.checkpoint_interval = 0
    cfg.checkpoint_at_end = False
    cfg.create_json = False
    cfg.save_folder = str(tmp_path)
    cfg.sampling_device = cfg.train_device = cfg.buffer_device = "cpu"
    return Experiment(task=task, algorithm_config=algorithm.get_from_yaml(), model_config=MlpConfig.get_from_yaml(),
                      critic_model_config=MlpConfig.get_from_yaml(), seed=0, config=cfg)


@pytest.mark.parametrize("algorithm,task_name", [(MappoConfig, "TRACKING"), (IppoConfig, "TRACKING"),
                                                (MappoConfig, "TRACKING_LOSSY")],
                         ids=["mappo", "ippo", "mappo-tracking_lossy"])
def test_benchmarl_one_iteration_shared_group(algorithm, task_name, tmp_path):
    """One iteration on the task (TRACKING_LOSSY: communication faults, each controller observing the
    held C-O estimate, held O-O copies and the received mask)."""
    task = getattr(_example().DobsEnvsTask, task_name).get_task({"max_cycles": 10})
    experiment = _experiment(algorithm, task, tmp_path)
    assert list(experiment.group_map) == ["controller"] and len(experiment.group_map["controller"]) == 5
    before = [p.detach().clone() for p in experiment.policy.parameters()]
    experiment.run()
    assert experiment.n_iters_performed == 1 and experiment.total_frames >= 40
    after = list(experiment.policy.parameters())
    assert any(not torch.equal(b, a) for b, a in zip(before, after))  # the shared policy was trained
    assert all(torch.isfinite(a).all() for a in after)


def test_benchmarl_task_episode_length():
    module = _example()
    task = module.DobsEnvsTask.HETERO_MAS.get_task()
    assert task.max_steps(None) == 600  # the registered 30 s horizon at 0.05 s per control step
    with pytest.raises(ValueError, match="max_cycles"):
        module.DobsEnvsTask.TRACKING.get_task({"horizon": float("inf")}).max_steps(None)
