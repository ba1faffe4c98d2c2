"""The options dataclasses: the single list of names and defaults, the docstrings, validation."""
import ast
import math
import re

import gymnasium as gym
import numpy as np
import pytest

import dobs_envs  # noqa: F401
from dobs_envs import registry, tracking_v0
from dobs_envs.envs import EnvOptions, HeteroMASOptions, RandomNetworkOptions
from dobs_envs.envs.parallel_env import COMMON_OPTIONS

CLASSES = [registry.get(name).load_class() for name in registry.ENVIRONMENTS]


def _documented_arguments(cls) -> dict:
    """``{name: default}`` of the ``parallel_env(...)`` call in the class docstring's ``## Arguments``."""
    doc = cls.__doc__
    section = doc[doc.index("## Arguments"):]
    section = section[:section.index("## Version History")]
    call = re.search(r"parallel_env\((.*?)\)``", " ".join(section.split()))
    assert call, f"{cls.__name__}: no ``<module>.parallel_env(...)`` in its ## Arguments"
    tree = ast.parse(f"f({call.group(1)})", mode="eval")
    return {kw.arg: ast.literal_eval(kw.value) for kw in tree.body.keywords}


def _same(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and math.isclose(a, b, rel_tol=0, abs_tol=0)
    return a == b and type(a) is type(b)


@pytest.mark.parametrize("cls", CLASSES, ids=[c.__name__ for c in CLASSES])
def test_docstring_arguments_match_the_options_dataclass(cls):
    documented = _documented_arguments(cls)
    expected = cls.valid_options()
    assert list(documented) == list(expected), "names (in declaration order)"
    for name, default in expected.items():
        assert _same(documented[name], default), f"{cls.__name__}: {name}={documented[name]!r}, dataclass {default!r}"


def test_one_list_of_names():
    assert COMMON_OPTIONS == EnvOptions.defaults()
    assert list(HeteroMASOptions.names()[:len(EnvOptions.names())]) == list(EnvOptions.names())
    assert set(RandomNetworkOptions.names()) > set(EnvOptions.names())
    for name in ("scenario", "dt", "substeps", "max_cycles", "horizon", "observation", "obs_dtype", "Q", "R",
                 "action_bound", "init_noise", "state_bound", "termination_penalty", "reward", "cost_scale",
                 "render_mode", "disturbance", "disturbance_amplitude"):
        assert name in COMMON_OPTIONS


def test_unknown_keyword_is_worded_as_python():
    with pytest.raises(TypeError) as exc:
        tracking_v0.parallel_env(substep=10)
    msg = str(exc.value)
    assert msg.startswith("TrackingEnv.__init__() got an unexpected keyword argument 'substep'; valid arguments are:")
    assert "'substeps'" in msg
    with pytest.raises(TypeError, match=r"RandomNetworkEnv.__init__\(\) got an unexpected keyword argument 'scenario'"):
        registry.get("random_network").load_class()(scenario=None)
    with pytest.raises(TypeError, match="unexpected keyword argument 'foo'"):
        gym.make_vec("dobs_envs/Tracking-v0", num_envs=2, foo=1)


@pytest.mark.parametrize("kw,match", [
    ({"dt": 0.0}, "dt"), ({"substeps": 1.5}, "substeps"), ({"max_cycles": 0}, "max_cycles"),
    ({"horizon": -1.0}, "horizon"), ({"max_cycles": 5, "horizon": 1.0}, "either max_cycles"),
    ({"obs_dtype": "int8"}, "obs_dtype"), ({"action_bound": "big"}, "action_bound"),
    ({"action_bound": [1.0, -1.0]}, "action_bound"), ({"init_noise": -1}, "init_noise"),
    ({"state_bound": 1e200}, "state_bound"), ({"reward": "exp"}, "reward must be one of"),
    ({"cost_scale": True}, "cost_scale"), ({"render_mode": "ansi"}, "render_mode"),
    ({"disturbance": "wind"}, "disturbance"), ({"disturbance_amplitude": np.nan}, "disturbance_amplitude"),
    ({"observation": 3}, "observation")])
def test_validation_names_the_option(kw, match):
    with pytest.raises(ValueError, match=match):
        EnvOptions(**kw)


def test_options_are_frozen_and_normalised():
    o = EnvOptions(obs_dtype=np.float64, substeps=np.int64(10), observation=["xhat", "r"], action_bound=[1, 2])
    assert o.obs_dtype == "float64" and o.substeps == 10 and type(o.substeps) is int
    assert o.observation == ("xhat", "r") and o.action_bound.tolist() == [1.0, 2.0]
    with pytest.raises(AttributeError):
        o.dt = 1.0
    assert o.replace(dt=2e-3).dt == 2e-3
    with pytest.raises(ValueError, match="kind"):
        RandomNetworkOptions(kind="tree")


def test_extra_options_are_derived_from_the_dataclass():
    from dobs_envs.envs import HeteroMASEnv, RandomNetworkEnv, TrackingEnv

    assert TrackingEnv.EXTRA_OPTIONS == {}
    assert HeteroMASEnv.EXTRA_OPTIONS == {"q_rest": 0.1, "r": 1.0, "rho": 1e-3}
    assert set(RandomNetworkEnv.EXTRA_OPTIONS) == set(RandomNetworkOptions.names()) - set(EnvOptions.names())
