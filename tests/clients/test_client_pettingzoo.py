"""PettingZoo's own render test on every environment (it starts with render_mode="human")."""
from __future__ import annotations

import warnings

import pytest
from pettingzoo.test import render_test

from dobs_envs import disturbance_rejection_v0, hetero_mas_v0, random_network_v0, tracking_lossy_v0, tracking_v0

MODULES = [tracking_v0, tracking_lossy_v0, disturbance_rejection_v0, hetero_mas_v0, random_network_v0]


@pytest.mark.parametrize("mod", MODULES, ids=[m.__name__.rsplit(".", 1)[1] for m in MODULES])
def test_render_test(mod):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "human" on a headless machine: the documented warning
        render_test(mod.env)
