"""The hyperparameter files: rl-zoo3's format read without evaluating anything, and the
recipes agents/ derives from them frozen (tests/data/recipes.json: unchanged by the move to that
format, issue 9; a deliberate recipe change edits that file in the same commit).

rl-zoo3's own reading of the same files is tested against the real client in
tests/clients/test_rl_zoo3.py."""
from __future__ import annotations

import json
import os

import pytest

from agents.config.hyperparam_files import (ALGOS, HYPERPARAMS_DIR, HyperparamsError, load_hyperparams,
                                            parse_kwargs_string, read_hyperparams_file)
from agents.config.envs import ENVS
from agents.training.algos import torch_policy_kwargs
from agents.training.recipes import resolve_recipe

FROZEN = os.path.join(os.path.dirname(__file__), "data", "recipes.json")


def _case(key: str):
    algo, env, *rest = key.split()
    variant = next((r for r in rest if r != "ma"), None)
    return algo, env, "ma" in rest, variant


def _plain(recipe) -> dict:
    d = recipe.as_dict()
    pk = torch_policy_kwargs(d["algo_kwargs"]["policy_kwargs"])
    if "activation_fn" in pk:
        pk["activation_fn"] = pk["activation_fn"].__name__
    d["algo_kwargs"]["policy_kwargs"] = pk
    return json.loads(json.dumps(d))


with open(FROZEN) as _fh:
    _RECIPES = json.load(_fh)["recipes"]


@pytest.mark.parametrize("key", sorted(_RECIPES))
def test_recipes_unchanged(key):
    """Every (algo, env, shared, hybrid) recipe equals the frozen one (see the file's ``_about``)."""
    algo, env, ma, variant = _case(key)
    assert _plain(resolve_recipe(algo, env, multi_agent=ma, hybrid=variant)) == _RECIPES[key]


def test_frozen_recipes_cover_every_env_and_mode():
    cases = {_case(k) for k in _RECIPES}
    for env in ENVS:
        for algo, ma, variant in [("ppo", False, None), ("ppo", True, None), ("ppo", False, "residual"),
                                  ("ppo", True, "residual"), ("ppo", False, "bc"), ("sac", False, None),
                                  ("sac", True, None), ("td3", False, None), ("crossq", False, None)]:
            assert (algo, env, ma, variant) in cases


@pytest.mark.parametrize("algo", ALGOS)
def test_shipped_files_are_valid(algo):
    table = read_hyperparams_file(os.path.join(HYPERPARAMS_DIR, f"{algo}.yaml"))
    assert "default" in table


def test_centralised_recipe_is_the_section_rl_zoo3_reads():
    """Each Gymnasium-id section is complete: the layered lookup gives that section alone."""
    table = read_hyperparams_file(os.path.join(HYPERPARAMS_DIR, "ppo.yaml"))
    for name, (gid, _) in ENVS.items():
        assert gid in table
        assert load_hyperparams("ppo", name) == table[gid]


@pytest.mark.parametrize("text, expected", [
    ("dict(net_arch=[64, 64], activation_fn=nn.Tanh, log_std_init=-3.0)",
     {"net_arch": [64, 64], "activation_fn": "tanh", "log_std_init": -3.0}),
    ("dict(net_arch=dict(pi=[32], vf=[64]), activation_fn=th.nn.ReLU, ortho_init=False)",
     {"net_arch": {"pi": [32], "vf": [64]}, "activation_fn": "relu", "ortho_init": False}),
    ("{'net_arch': (8,), 'activation_fn': torch.nn.ELU}", {"net_arch": (8,), "activation_fn": "elu"}),
])
def test_kwargs_strings_parse_without_evaluation(text, expected):
    assert parse_kwargs_string(text, "f.yaml, section 'default'", "policy_kwargs") == expected


@pytest.mark.parametrize("text", [
    "__import__('os').system('touch PWNED')",
    "dict(activation_fn=nn.Module)",
    "dict(optimizer_class=th.optim.Adam)",
    "dict(net_arch=[64] * 2)",
    "dict(x=(lambda: 1)())",
    "dict(**{'a': 1})",
    "dict(a=().__class__)",
    "eval('1')",
    "[1, 2]",
    "dict(a=",
    "dict(a=" + "[" * 2000 + "]" * 2000 + ")",
    "dict(a=1)\x00",
    "dict(a=" + "1, b=" * 3000 + "1)",
])
def test_kwargs_strings_refuse_code(text, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(HyperparamsError, match="policy_kwargs"):
        parse_kwargs_string(text, "f.yaml, section 'default'", "policy_kwargs")
    assert not (tmp_path / "PWNED").exists()


def _write(tmp_path, text: str) -> str:
    path = tmp_path / "ppo.yaml"
    path.write_text(text)
    return str(path)


BASE = """default: &default
  policy: MlpPolicy
  n_timesteps: 1000
  policy_kwargs: "dict(net_arch=[8], activation_fn=nn.Tanh)"
"""


@pytest.mark.parametrize("extra, match", [
    ('"dobs_envs/Tracking-v0":\n  n_envs: 2\n', r"lacks \['n_timesteps', 'policy', 'policy_kwargs'\].*<<: \*default"),
    ('"dobs_envs/Tracking-v0":\n  <<: *default\n  agent_id: true\n', "'agent_id' is read by agents/ only"),
    ("default-ma:\n  env_wrapper: [{my.module.Wrapper: {}}]\n", "env_wrapper .* not accepted"),
    ("default-ma:\n  env_wrapper: [{gymnasium.wrappers.RescaleAction: {min_action: 0, max_action: 1}}]\n",
     "env_wrapper .* not accepted"),
    ('"dobs_envs/Tracking-v0":\n  <<: *default\n  policy: my.module.Policy\n', "dotted names"),
    ("default-ma:\n  callback: my.module.Callback\n", "'callback' is an rl-zoo3 option"),
    ("default-ma:\n  normalize: \"__import__('os')\"\n", "normalize"),
    ('"dobs_envs/Tracking-v0":\n  <<: *default\n  policy_kwargs: {activation_fn: tanh}\n', "string form"),
    ("default-ma:\n  noise_type: uniform\n", "noise_type must be one of"),
    ('"dobs_envs/Tracking-v0":\n  <<: *default\n  noise_type: pink\n', "not an rl-zoo3 noise type"),
    ("default-ma: [1, 2]\n", "must be a mapping"),
])
def test_file_errors_name_the_section_and_key(tmp_path, extra, match):
    path = _write(tmp_path, BASE + extra)
    with pytest.raises(HyperparamsError, match=match) as info:
        read_hyperparams_file(path)
    assert path in str(info.value)


def test_a_file_read_again_is_parsed_again_when_it_changes(tmp_path):
    """Parsed files are kept (the benchmark resolves a recipe per run): a changed file is read again, and a
    caller's changes to the returned sections do not reach the next caller."""
    path = _write(tmp_path, BASE)
    first = read_hyperparams_file(path)
    first["default"]["n_timesteps"] = -1
    assert read_hyperparams_file(path)["default"]["n_timesteps"] == 1000
    with open(path, "a") as fh:
        fh.write("default-ma:\n  n_epochs: 3\n")
    os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 1))  # even within the clock's tick
    assert read_hyperparams_file(path)["default-ma"]["n_epochs"] == 3
    with open(path, "a") as fh:
        fh.write("  n_steps: [\n")  # broken YAML: the error, not the kept sections
    with pytest.raises(HyperparamsError, match="not valid YAML"):
        read_hyperparams_file(path)


def test_rescale_wrapper_means_normalized_actions(tmp_path):
    path = _write(tmp_path, BASE + "  env_wrapper:\n    - gymnasium.wrappers.RescaleAction: "
                                   "{min_action: -1, max_action: 1}\ndefault-residual:\n  env_wrapper: null\n")
    table = read_hyperparams_file(path)
    assert table["default"]["normalize_actions"] is True and "env_wrapper" not in table["default"]
    assert table["default-residual"]["normalize_actions"] is False


def test_overrides_accept_both_vocabularies():
    hp = load_hyperparams("ppo", "tracking", overrides={"policy_kwargs": "dict(net_arch=[8], activation_fn=nn.ReLU)"})
    assert hp["policy_kwargs"] == {"net_arch": [8], "activation_fn": "relu", "log_std_init": -2.0}
    with pytest.raises(HyperparamsError, match=r"hyperparameter overrides \(--hyperparams\): policy_kwargs"):
        load_hyperparams("ppo", "tracking", overrides={"policy_kwargs": "dict(a=open('x'))"})


def test_rl_zoo3_evaluation_bound_documented_is_the_tasks():
    """rl-zoo3 evaluates with the recipe's training-only env_kwargs (its eval env and rl_zoo3.enjoy);
    the docs (integrations page) and agents/config/hyperparam_files.py tell how to give it the task's own
    state_bound."""
    import os
    import re

    from agents.config.hyperparam_files import HYPERPARAMS_DIR
    from dobs_envs.envs.options import EnvOptions

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    readme = open(os.path.join(root, "docs", "integrations.md")).read()
    import agents.config.hyperparam_files as cfg

    task = EnvOptions.defaults()["state_bound"]
    for text in (readme, cfg.__doc__, open(os.path.join(HYPERPARAMS_DIR, "ppo.yaml")).read()):
        given = {float(v) for v in re.findall(r"(?:--eval-env-kwargs|--env-kwargs)\s+\W*\s*state_bound:([0-9.e+]+)", text)}
        assert given == {task}, given
    assert "--eval-env-kwargs state_bound" in readme and "--env-kwargs state_bound" in readme


def test_env_section_is_agents_only_and_applied_after_the_gym_id_section(tmp_path):
    """``<env>`` (short name) holds what rl-zoo3 cannot read; it need not be complete, and the lookup
    applies it on top of the Gymnasium id's section (td3.yaml's ``hetero_mas``: pink noise)."""
    path = _write(tmp_path, BASE + '"dobs_envs/HeteroMAS-v0":\n  <<: *default\n  noise_type: normal\n'
                                   "hetero_mas:\n  noise_type: pink\n")
    assert read_hyperparams_file(path)["hetero_mas"] == {"noise_type": "pink"}
    table = read_hyperparams_file(os.path.join(HYPERPARAMS_DIR, "td3.yaml"))
    assert table["dobs_envs/HeteroMAS-v0"]["noise_type"] == "normal"  # what rl-zoo3 trains with
    assert load_hyperparams("td3", "hetero_mas")["noise_type"] == "pink"
    assert load_hyperparams("td3", "tracking")["noise_type"] == "normal"


def test_the_jitted_trainer_reads_its_own_sections_last():
    """``trainer="jax"`` layers ``default-jax``, then ``<env>-jax`` (centralised) or ``<env>-ma-jax`` (shared) over
    everything SB3 reads: the random_network recipe is SB3's with exactly the ``random_network-jax``
    keys replaced; the shared recipe does not take the centralised section; an env without a section
    (disturbance_rejection, tracking_lossy) trains SB3's recipe; tracking's sections change only the network (PPO)
    and the minibatch (SAC), for the jitted trainer alone (SBX's SAC keeps 256)."""
    from agents.config.hyperparam_files import read_hyperparams_file

    table = read_hyperparams_file(os.path.join(HYPERPARAMS_DIR, "ppo.yaml"))
    section = table["random_network-jax"]
    sb3 = load_hyperparams("ppo", "random_network")
    jx = load_hyperparams("ppo", "random_network", trainer="jax")
    assert set(section) and {k for k in jx if jx[k] != sb3.get(k)} <= set(section)
    assert all(jx[k] == v for k, v in section.items())
    assert resolve_recipe("ppo", "random_network", trainer="jax").hyperparams == jx
    assert "default-jax" not in table
    for env in ("disturbance_rejection", "tracking_lossy"):
        assert f"{env}-jax" not in table
        assert load_hyperparams("ppo", env, trainer="jax") == load_hyperparams("ppo", env)
    for algo, key in (("ppo", "policy_kwargs"), ("sac", "batch_size")):
        sb3, jx = load_hyperparams(algo, "tracking"), load_hyperparams(algo, "tracking", trainer="jax")
        assert {k for k in jx if jx[k] != sb3.get(k)} == {key}
    assert load_hyperparams("ppo", "tracking", trainer="jax")["policy_kwargs"]["net_arch"] == [64, 64]
    assert load_hyperparams("sac", "tracking", trainer="jax")["batch_size"] == 128
    assert load_hyperparams("sac", "tracking")["batch_size"] == 256
    assert "random_network-ma-jax" not in table
    assert load_hyperparams("ppo", "random_network", multi_agent=True, trainer="jax") == load_hyperparams(
        "ppo", "random_network", multi_agent=True)
    with pytest.raises(ValueError, match="trainer must be one of"):
        load_hyperparams("ppo", "tracking", trainer="rllib")
