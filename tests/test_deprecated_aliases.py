"""Module paths the README documented before a rename keep working, with a DeprecationWarning."""
import warnings

import pytest

import dobs_envs.envs
from dobs_envs.envs import env_core


def test_envs_core_reasons_warns_and_is_env_core_s():
    with pytest.warns(DeprecationWarning, match=r"dobs_envs\.envs\.core is deprecated: use dobs_envs\.envs\.env_core\.REASONS"):
        from dobs_envs.envs.core import REASONS
    assert REASONS is env_core.REASONS is dobs_envs.envs.REASONS


def test_envs_core_renamed_function_and_unknown_names():
    import dobs_envs.envs.core as old

    with pytest.warns(DeprecationWarning, match="env_core.resolve_scenario"):
        assert old.load_scenario is env_core.resolve_scenario
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning for a name that does not exist
        with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
            old.no_such_name  # noqa: B018
