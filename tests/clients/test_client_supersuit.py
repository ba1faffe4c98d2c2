"""SuperSuit + SB3: parameter sharing over our PettingZoo envs with identical agent spaces (issue 9)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import require

ss = require("supersuit")
sb3 = require("stable_baselines3")
from stable_baselines3.common.vec_env import VecMonitor  # noqa: E402

from dobs_envs import random_network_v0, tracking_v0  # noqa: E402

BOTH = {"normalized_actions": True, "padded_observations": True}
HETERO = {"system_seed": 1, "generator_kwargs": {"inputs_per_controller": (1, 2)}}


def test_differing_spaces_are_refused_without_the_options():
    with pytest.raises(AssertionError, match="observation spaces not consistent"):
        ss.pettingzoo_env_to_vec_env_v1(random_network_v0.parallel_env())


@pytest.mark.parametrize("make", [
    lambda: tracking_v0.parallel_env(max_cycles=40, **BOTH),
    lambda: random_network_v0.parallel_env(max_cycles=40, **HETERO, **BOTH),
], ids=["tracking_v0", "random_network_v0"])
def test_ppo_parameter_sharing(make):
    env = make()
    n_agents = len(env.possible_agents)
    venv = ss.pettingzoo_env_to_vec_env_v1(env)
    venv = VecMonitor(ss.concat_vec_envs_v1(venv, 2, num_cpus=0, base_class="stable_baselines3"))
    assert venv.num_envs == 2 * n_agents
    assert np.all(venv.action_space.low == -1) and np.all(venv.action_space.high == 1)
    # no seed= here: SuperSuit's SB3 wrapper has no seed() (SB3 would call it)
    sb3.common.utils.set_random_seed(0)
    model = sb3.PPO("MlpPolicy", venv, n_steps=128, batch_size=128, n_epochs=2, verbose=0)
    # SB3's default logger leaves an empty temp directory
    model.set_logger(sb3.common.logger.Logger(folder=None, output_formats=[]))
    model.learn(3000)
    assert model.num_timesteps >= 3000
    lengths = [ep["l"] for ep in model.ep_info_buffer]
    assert len(lengths) >= 2 * n_agents and set(lengths) == {40}  # episodes ended by max_cycles, then reset
    venv.close()
