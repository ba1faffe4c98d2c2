"""The jitted trainers' recipe validators (agents/training/jax/validate.py): what each accepts and refuses (the
message names the key), and that the three recipe readers (PPO, SAC, TD3) refuse through them alike."""
from __future__ import annotations

import math

import numpy as np
import pytest

from agents.training.jax import validate as v


@pytest.mark.parametrize("fn, good, bad", [
    (v.pos_int, [(1, 1), (np.int64(7), 7)], [0, -1, True, 2.0, "3", None]),
    (v.non_negative_int, [(0, 0), (np.int32(5), 5)], [-1, False, 1.5, "0"]),
    (v.number, [(0, 0.0), (2.5, 2.5), (3, 3.0)], [-0.1, math.nan, True, "1", None]),
])
def test_scalar_validators(fn, good, bad):
    for value, expected in good:
        out = fn("key_x", value)
        assert out == expected and type(out) is type(expected)
    for value in bad:
        with pytest.raises(ValueError, match="key_x"):
            fn("key_x", value)


def test_schedule_and_number_bound():
    assert v.schedule("lr", "lin_1.0e-3") == (1e-3, True) and v.schedule("lr", 3e-4) == (3e-4, False)
    for bad in ("lin_x", "exp_0.1", True, None):
        with pytest.raises(ValueError, match="lr must be a number or 'lin_<number>'"):
            v.schedule("lr", bad)
    assert v.number("c", 1.0, low=1.0) == 1.0
    with pytest.raises(ValueError, match="c must be a number >= 1"):
        v.number("c", 0.5, low=1.0)


def test_normalize_dtype_and_env_kwargs():
    keys = ("norm_obs", "norm_reward")
    assert v.vec_normalize(True, keys) == {} and v.vec_normalize(None, keys) == {"norm_obs": False,
                                                                                 "norm_reward": False}
    assert v.vec_normalize({"norm_obs": True}, keys) == {"norm_obs": True}
    with pytest.raises(ValueError, match=r"normalize keys \['clip'\]"):
        v.vec_normalize({"clip": 1}, keys)
    with pytest.raises(ValueError, match="normalize must be true/false"):
        v.vec_normalize("yes", keys)
    assert v.float_dtype("float64") == "float64"
    with pytest.raises(ValueError, match="dtype must be"):
        v.float_dtype("float16")
    given = {"state_bound": 30}
    out = v.train_env_kwargs(given)
    assert out == given and out is not given and v.train_env_kwargs(None) == {}
    with pytest.raises(ValueError, match="env_kwargs may not set 'dtype'"):
        v.train_env_kwargs({"dtype": "float64"})


@pytest.mark.parametrize("reader", ["ppo", "sac", "td3"])
@pytest.mark.parametrize("change, message", [({"n_envs": True}, "n_envs must be a positive integer"),
                                             ({"learning_rate": "cos_1"}, "learning_rate must be a number"),
                                             ({"normalize": {"bogus": 1}}, "normalize keys"),
                                             ({"env_kwargs": {"normalized_actions": True}}, "env_kwargs may not")])
def test_recipe_readers_refuse_through_the_validators(reader, change, message):
    import importlib

    pytest.importorskip("jax")
    pytest.importorskip("optax")
    mod = importlib.import_module(f"agents.training.jax.{reader}")
    with pytest.raises(ValueError, match=message):
        getattr(mod, f"{reader}_config")(change)
