"""The environment registry (dobs_envs.registry) and the import layering it supports."""
import importlib
import subprocess
import sys

import gymnasium as gym
import pytest

import dobs_envs
from dobs_envs import registry
from dobs_envs.envs import COMMON_OPTIONS, centralized

NAMES = list(registry.ENVIRONMENTS)


def test_default_control_period_matches_the_env_options():
    assert COMMON_OPTIONS["dt"] == registry.DEFAULT_DT
    assert COMMON_OPTIONS["substeps"] == registry.DEFAULT_SUBSTEPS


@pytest.mark.parametrize("name", NAMES)
def test_entry_matches_the_environment(name):
    e = registry.get(name)
    mod = importlib.import_module(e.module)
    assert mod.raw_env is e.load_class()
    env = mod.parallel_env()
    assert env.metadata["name"] == e.module.rsplit(".", 1)[1]
    assert env.control_period == pytest.approx(registry.DEFAULT_CONTROL_PERIOD)
    # max_episode_steps is derived from the default scenario's horizon: t_end / period
    assert env.scenario.t_end == e.t_end
    assert e.max_episode_steps == round(env.scenario.t_end / env.control_period) == env.max_cycles


@pytest.mark.parametrize("name", NAMES)
def test_gym_registration_reads_the_registry(name):
    e = registry.get(name)
    spec = gym.spec(e.gym_id)
    assert spec.max_episode_steps == e.max_episode_steps
    assert spec.entry_point == e.gym_entry_point == dobs_envs.GYM_IDS[e.gym_id][0]
    assert callable(getattr(centralized, f"make_{name}"))
    # the docstring table of centralized states the same numbers
    row = [ln for ln in centralized.__doc__.splitlines() if ln.startswith(f"``{e.gym_id}``")]
    assert len(row) == 1 and f"{e.max_episode_steps} ({e.t_end:g} s)" in row[0]


def test_agents_config_reads_the_registry():
    from agents.config import envs as config

    assert config.ENVS == {n: (e.gym_id, e.module) for n, e in registry.ENVIRONMENTS.items()}


def test_unknown_name():
    with pytest.raises(KeyError, match="registered names"):
        registry.get("tracking_v0")


def _run(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout


def test_importing_the_package_is_cheap():
    out = _run("import sys, dobs_envs; print(sorted(m for m in sys.modules if m.startswith('dobs_envs')))")
    assert out.strip() == "['dobs_envs', 'dobs_envs.registry']"


def test_env_layer_imports_neither_baselines_nor_reproduce():
    # action_bound="auto" calibrates with the paper's control laws (dobs_envs.control)
    out = _run("import sys\n"
               "from dobs_envs import tracking_v0\n"
               "env = tracking_v0.parallel_env(action_bound='auto', max_cycles=5)\n"
               "print(sorted(m for m in sys.modules if m.split('.')[0] in ('baselines', 'agents')"
               " or m == 'dobs_envs.reproduce'))")
    assert out.strip() == "[]"


@pytest.mark.parametrize("name", NAMES)
def test_fault_free_names_the_counterpart_of_a_faulted_env(name):
    """``fault_free`` is set exactly for the envs with communication faults on by default and names a registered
    env without them (that the two are the same task: tests/test_baselines_faults.py)."""
    e = registry.get(name)
    faults = importlib.import_module(e.module).parallel_env(max_cycles=1).options.faults
    assert (faults is not None) == (e.fault_free is not None)
    if e.fault_free is not None:
        ff = registry.get(e.fault_free)
        assert ff.fault_free is None and ff.t_end == e.t_end
        assert importlib.import_module(ff.module).parallel_env(max_cycles=1).options.faults is None
