"""A run directory's pickles never run code (issue 41, item 1): crafted ``vecnormalize.pkl`` / ``model.zip`` /
``replay_buffer.pkl`` payloads are refused with one line (exit 2 through the CLI), nothing they name runs;
a genuine run loads and evaluates exactly as SB3's unrestricted loading did."""
from __future__ import annotations

import base64
import json
import os
import pickle
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

import dobs_envs
from agents.benchmark.plan import BUDGETS
from agents.training.run_pickles import PickleRefused, load_replay_buffer, load_vecnormalize
from dobs_envs.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(dobs_envs.__file__)))


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("run") / "ppo")
    assert main(["train", "--env", "tracking", "--timesteps", "64", "--out", out, "--no-progress",
                 "--hyperparams", json.dumps(BUDGETS["tiny"]["hyperparams"]["ppo"])]) == 0
    assert os.path.isfile(os.path.join(out, "vecnormalize.pkl"))
    return out


class _Touch:
    """Unpickling this runs ``touch <path>``."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return os.system, (f"touch {self.path}",)


def _evaluate_cli(run):
    """``dobs-envs evaluate --model run`` in a fresh interpreter (the code under test, not the installed one)."""
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "dobs_envs.cli", "evaluate", "--model", str(run), "--episodes", "1"],
                          capture_output=True, text=True, env=env, timeout=600)


def _rewrite_data(model_zip, edit):
    with zipfile.ZipFile(model_zip) as zf:
        entries = {n: zf.read(n) for n in zf.namelist()}
    data = json.loads(entries["data"])
    edit(data)
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(model_zip, "w") as zf:
        for n, b in entries.items():
            zf.writestr(n, b)


def _payload(obj) -> str:
    import cloudpickle

    return base64.b64encode(cloudpickle.dumps(obj)).decode()


@pytest.mark.parametrize("crafted", ["vecnormalize", "model_data_entry", "model_extra_entry"])
def test_crafted_pickles_run_no_code(crafted, run_dir, tmp_path):
    d = tmp_path / "r"
    shutil.copytree(run_dir, d)
    marker = tmp_path / "pwned"
    if crafted == "vecnormalize":  # the normaliser's statistics carrying a payload
        (d / "vecnormalize.pkl").write_bytes(pickle.dumps({"obs_rms": _Touch(marker)}))
        names = ["vecnormalize.pkl", "posix.system"]
    elif crafted == "model_data_entry":  # an entry SB3 unpickles on load (data read back from the file)
        _rewrite_data(d / "model.zip", lambda data: data["_last_obs"].update({":serialized:": _payload(_Touch(marker))}))
        names = ["model.zip", "_last_obs", "posix.system"]
    else:  # an entry no recipe produces
        _rewrite_data(d / "model.zip", lambda data: data.update(
            evil={":type:": "<class 'object'>", ":serialized:": _payload(_Touch(marker))}))
        names = ["model.zip", "'evil'"]
    r = _evaluate_cli(d)
    err = r.stderr.strip()
    assert not marker.exists()
    assert r.returncode == 2 and "\n" not in err and "Traceback" not in err, err
    assert "does not unpickle" in err and all(n in err for n in names), err


def test_rebuilt_model_entries_are_never_read(run_dir, tmp_path):
    """The schedule's payload in ``model.zip`` is replaced by the recipe's own (``config.json``): never unpickled."""
    from agents.training.loading import load_agent

    d = tmp_path / "r"
    shutil.copytree(run_dir, d)
    marker = tmp_path / "pwned"
    _rewrite_data(d / "model.zip", lambda data: data["learning_rate"].update({":serialized:": _payload(_Touch(marker))}))
    agent = load_agent(str(d))
    assert not marker.exists() and callable(agent.model.learning_rate)


def test_genuine_run_evaluates_as_before(run_dir):
    """Restricted loading gives the objects SB3's unrestricted ``load`` / ``pickle.load`` give: same actions and
    normalised observations, the same evaluation episodes."""
    from stable_baselines3 import PPO

    from agents.config.envs import gym_factory
    from agents.evaluate import evaluate_policy, summarise
    from agents.training.loading import TrainedAgent, load_agent

    agent = load_agent(run_dir)
    with open(os.path.join(run_dir, "vecnormalize.pkl"), "rb") as fh:
        vn = pickle.load(fh)
    vn.training, vn.norm_reward = False, False
    ref = TrainedAgent.from_model(PPO.load(os.path.join(run_dir, "model.zip"), device="cpu"), vn, agent.config)
    for attr in ("mean", "var", "count"):
        np.testing.assert_array_equal(getattr(agent.vecnorm.obs_rms, attr), getattr(vn.obs_rms, attr))
    results = []
    for a in (agent, ref):
        env = gym_factory("tracking", agent.config.get("env_kwargs"))()
        results.append(summarise(evaluate_policy(env, a.policy_for(env), 2, 10000, parallel=False)))
        env.close()
    assert results[0] == results[1]


def test_replay_buffer_is_read_restricted(tmp_path):
    from stable_baselines3.common.buffers import ReplayBuffer
    from stable_baselines3.common.save_util import save_to_pkl
    from gymnasium import spaces

    class _Model:
        replay_buffer = None

    buf = ReplayBuffer(16, spaces.Box(-1, 1, (3,)), spaces.Box(-1, 1, (2,)), device="cpu")
    buf.add(np.ones(3), np.ones(3), np.ones(2), np.ones(1), np.zeros(1), [{}])
    save_to_pkl(tmp_path / "replay_buffer.pkl", buf)
    m = _Model()
    load_replay_buffer(m, str(tmp_path / "replay_buffer.pkl"))
    np.testing.assert_array_equal(m.replay_buffer.observations, buf.observations)
    marker = tmp_path / "pwned"
    (tmp_path / "evil.pkl").write_bytes(pickle.dumps([buf, _Touch(marker)]))
    with pytest.raises(PickleRefused, match=r"evil\.pkl holds posix\.system"):
        load_replay_buffer(m, str(tmp_path / "evil.pkl"))
    with pytest.raises(PickleRefused, match="does not unpickle"):  # a buffer is not a normaliser's data
        load_vecnormalize(str(tmp_path / "evil.pkl"))
    assert not marker.exists()


def test_sbx_run_loads_without_unpickling_its_networks(tmp_path):
    """SBX keeps its networks in the cloudpickled ``policy`` entry: their arrays are read as data into a fresh
    policy (same actions as SBX's own unrestricted load); a payload there runs nothing and is refused."""
    pytest.importorskip("sbx")
    from agents.training.algos import backend_of
    from agents.training.loading import load_agent

    out = str(tmp_path / "sac")
    assert main(["train", "--env", "tracking", "--algo", "sac", "--timesteps", "64", "--out", out, "--no-progress",
                 "--hyperparams", json.dumps(BUDGETS["tiny"]["hyperparams"]["sac"])]) == 0
    agent = load_agent(out)
    assert agent.config["library"] == "sbx-rl"
    ref = backend_of("sac", "sbx-rl").load(os.path.join(out, "model.zip"), device="cpu")
    obs = np.random.default_rng(0).normal(size=(8, *agent.observation_space.shape)).astype(np.float32)
    np.testing.assert_array_equal(agent.model.predict(obs, deterministic=True)[0], ref.predict(obs, deterministic=True)[0])
    # what train --resume restores (optimizer states too): every array equal to SBX's own load
    import jax

    from agents.training.recipes import recipe_from_hyperparams
    from agents.training.run_pickles import graft_sbx, model_custom_objects, sbx_payloads

    b, path = backend_of("sac", "sbx-rl"), os.path.join(out, "model.zip")
    recipe = recipe_from_hyperparams("sac", "tracking", agent.config["hyperparams"])
    m = b.load(path, device="cpu", custom_objects=model_custom_objects(path, b.rebuilt_objects(recipe), library=b.library))
    graft_sbx(m, path, sbx_payloads(path), optimizer=True)
    for mine, theirs in ((m.policy.actor_state, ref.policy.actor_state), (m.policy.qf_state, ref.policy.qf_state),
                         (m.ent_coef_state, ref.ent_coef_state), (m.policy.key, ref.policy.key), (m.key, ref.key)):
        a, r = jax.tree_util.tree_leaves(mine), jax.tree_util.tree_leaves(theirs)
        assert len(a) == len(r) > 0 and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(a, r))
    marker = tmp_path / "pwned"
    _rewrite_data(os.path.join(out, "model.zip"),
                  lambda data: data["policy"].update({":serialized:": _payload(_Touch(marker))}))
    with pytest.raises(ValueError, match="'policy' entry is not an SBX policy"):
        load_agent(out)
    assert not marker.exists()
