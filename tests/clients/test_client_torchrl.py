"""TorchRL: ``PettingZooWrapper`` over our parallel envs and ``GymEnv`` by id (issue 9)."""
from __future__ import annotations

import warnings

import gymnasium as gym
import pytest
from conftest import require

torchrl_envs = require("torchrl.envs")
torch = require("torch")
from torchrl.envs.utils import check_env_specs  # noqa: E402

import dobs_envs  # noqa: E402,F401
from dobs_envs import random_network_v0, tracking_v0  # noqa: E402

BOTH = {"normalized_actions": True, "padded_observations": True}
HETERO = {"system_seed": 1, "generator_kwargs": {"inputs_per_controller": (1, 2)}}


def _wrap(penv):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "tested with PettingZoo 1.24.3"
        return torchrl_envs.PettingZooWrapper(env=penv)


def test_pettingzoo_wrapper_rollout_across_episode_ends():
    env = _wrap(tracking_v0.parallel_env(max_cycles=5))
    assert env.group_map == {"controller": [f"controller_{k}" for k in range(5)]}
    td = env.rollout(17, break_when_any_done=False)  # three episode ends (steps 5, 10, 15), two resets
    done = td["next", "controller", "done"][:, 0, 0]
    assert done.nonzero().flatten().tolist() == [4, 9, 14]
    reason = td["next", "controller", "info", "termination_reason"][:, 0]
    assert reason[done].tolist() == [3.0, 3.0, 3.0] and not reason[~done].any()  # code 3: horizon
    rew = td["next", "controller", "reward"]
    assert torch.equal(rew, rew[:, :1].expand_as(rew))  # the team reward
    check_env_specs(env)


def test_pettingzoo_wrapper_termination_code():
    env = _wrap(tracking_v0.parallel_env(state_bound=15.0, normalized_actions=True))

    def push(td):  # every input at its bound
        td["controller", "action"] = torch.ones(5, 1)
        return td

    td = env.rollout(400, policy=push)  # stops at the first end: the state bound
    assert td["next", "controller", "terminated"][-1].all() and len(td) < 400
    assert td["next", "controller", "info", "termination_reason"][-1].tolist() == [1.0] * 5


@pytest.mark.parametrize("kw", [{}, HETERO], ids=["default", "channel_widths_1_2"])
def test_shared_specs_with_the_options(kw):
    """With both options the agents' specs stack into one tensor spec (one shared module), as
    opposed to a lazily stacked heterogeneous spec without them."""
    env = _wrap(random_network_v0.parallel_env(max_cycles=4, **kw, **BOTH))
    act = env.full_action_spec["controller", "action"]
    obs = env.observation_spec["controller", "observation"]
    M = max(e.shape[0] for e in [random_network_v0.parallel_env(**kw).action_space(a)
                                 for a in random_network_v0.parallel_env(**kw).possible_agents])
    assert act.shape == (3, M) and len(obs.shape) == 2 and obs.shape[0] == 3
    assert torch.all(act.space.low == -1) and torch.all(act.space.high == 1)
    check_env_specs(env)
    env.rollout(9, break_when_any_done=False)
    plain = _wrap(random_network_v0.parallel_env(max_cycles=4, **kw))
    assert -1 in plain.observation_spec["controller", "observation"].shape  # heterogeneous widths


def test_gym_env_by_id():
    # TorchRL first passes frameskip=...; our TypeError is worded as Python's, so it retries without it
    with pytest.raises(TypeError, match="got an unexpected keyword argument 'frameskip'"):
        gym.make("dobs_envs/Tracking-v0", frameskip=1)
    env = torchrl_envs.GymEnv("dobs_envs/Tracking-v0")
    td = env.rollout(3)
    assert td["next", "observation"].shape == (3, 155)
    check_env_specs(env)
    env = torchrl_envs.GymEnv("dobs_envs/Tracking-v0", max_episode_steps=5, normalized_actions=True)
    td = env.rollout(12, break_when_any_done=False)
    assert td["next", "truncated"].flatten().nonzero().flatten().tolist() == [4, 9]
    assert torch.all(env.action_spec.space.high == 1)
