"""RLlib (ray[rllib], the real client): one PPO iteration on our PettingZoo env through
RLlib's own ``ParallelPettingZooEnv``, with ONE module shared by every agent
(``normalized_actions=True, padded_observations=True`` give the agents identical spaces) and,
without those options, one module per agent."""
from __future__ import annotations

import numpy as np
import pytest
import ray
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, LEARNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME
from ray.tune.registry import register_env

from dobs_envs import hetero_mas_v0, tracking_v0

MODULES = {"tracking": tracking_v0, "hetero_mas": hetero_mas_v0}


@pytest.fixture(scope="module", autouse=True)
def ray_local():
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, configure_logging=False)
    # registered in this Ray session: a registration made before any ray.init is handed to the first session
    # only, and the documentation's RLlib block (tests/clients_heavy/test_docs_blocks.py) starts and stops one
    # first, which left this test's env unknown ("Environment `dobs_envs_parallel` doesn't exist", CI)
    register_env("dobs_envs_parallel", _make)
    yield
    ray.shutdown()


def _make(config: dict):
    config = dict(config)
    module = MODULES[config.pop("env")]
    return ParallelPettingZooEnv(module.parallel_env(**config))



def _one_iteration(env_config: dict, policies: dict, mapping):
    config = (
        PPOConfig()
        .environment("dobs_envs_parallel", env_config=env_config)
        .env_runners(num_env_runners=0, rollout_fragment_length=40)
        .learners(num_learners=0)
        .multi_agent(policies=set(policies), policy_mapping_fn=mapping)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={p: RLModuleSpec() for p in policies}))
        .training(train_batch_size_per_learner=40, minibatch_size=20, num_epochs=1)
        .debugging(seed=0)
    )
    algo = config.build_algo()
    try:
        result = algo.train()
        modules = set(algo.env_runner.module.keys())  # the MultiRLModule that sampled
    finally:
        algo.stop()
    return result, modules


@pytest.mark.parametrize("env", sorted(MODULES))
def test_rllib_ppo_one_shared_module(env):
    """Every agent mapped to one policy: RLlib needs identical spaces, which the two options give."""
    env_config = {"env": env, "max_cycles": 10, "normalized_actions": True, "padded_observations": True}
    probe = _make(env_config)
    agents = list(probe.par_env.possible_agents)
    for space in (probe.par_env.observation_space, probe.par_env.action_space):
        assert all(space(a) == space(agents[0]) for a in agents)
    probe.close()

    result, modules = _one_iteration(env_config, {"shared": None}, lambda aid, *args, **kwargs: "shared")
    assert modules == {"shared"}
    assert result[ENV_RUNNER_RESULTS][NUM_ENV_STEPS_SAMPLED_LIFETIME] >= 40
    assert set(result[LEARNER_RESULTS]) - {"__all_modules__"} == {"shared"}
    assert np.isfinite(float(result[LEARNER_RESULTS]["shared"]["total_loss"]))
    assert len(agents) > 1


def test_rllib_ppo_one_module_per_agent():
    """The env's own (heterogeneous) spaces: one module per agent."""
    env_config = {"env": "tracking", "max_cycles": 10}
    agents = tracking_v0.parallel_env().possible_agents
    result, modules = _one_iteration(env_config, {a: None for a in agents}, lambda aid, *args, **kwargs: aid)
    assert modules == set(agents)
    assert result[ENV_RUNNER_RESULTS][NUM_ENV_STEPS_SAMPLED_LIFETIME] >= 40
    for a in agents:
        assert np.isfinite(float(result[LEARNER_RESULTS][a]["total_loss"]))
