"""Usage errors of train/evaluate: one line, exit status 2, nothing imported from a run directory."""
from __future__ import annotations

import json
import os
import shutil
import sys

import pytest

from agents.benchmark import BUDGETS
from dobs_envs.cli import main

TINY_PPO = json.dumps(BUDGETS["tiny"]["hyperparams"]["ppo"])


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("run") / "ppo")
    assert main(["train", "--env", "tracking", "--timesteps", "64", "--out", out, "--no-progress",
                 "--hyperparams", TINY_PPO]) == 0
    return out


def _exit2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2, err
    assert "Traceback" not in err and err.count("\n") <= 1, err
    return err


def test_run_directory_cannot_make_us_import_code(run_dir, tmp_path, capsys, monkeypatch):
    marker = tmp_path / "imported"
    (tmp_path / "evil_dobs_module.py").write_text(f"open({str(marker)!r}, 'w').write('x')\ndef f(**kw):\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    bad = tmp_path / "bad_run"
    shutil.copytree(run_dir, bad)
    cfg = json.load(open(bad / "config.json"))
    for env in ("evil_dobs_module:f", "evil_dobs_module:Env-v0"):
        for multi in (False, True):
            cfg.update(env=env, multi_agent=multi)
            json.dump(cfg, open(bad / "config.json", "w"))
            err = _exit2(["evaluate", "--model", str(bad), "--episodes", "1"], capsys)
            assert "--allow-custom-env" in err
    assert not marker.exists() and "evil_dobs_module" not in sys.modules


@pytest.mark.parametrize("case", ["missing", "no_model", "corrupt_json", "not_a_dict", "bad_algo"])
def test_evaluate_bad_run_directories(case, run_dir, tmp_path, capsys):
    d = tmp_path / "r"
    if case != "missing":
        shutil.copytree(run_dir, d)
    if case == "no_model":
        os.remove(d / "model.zip")
    elif case == "corrupt_json":
        (d / "config.json").write_text("{not json")
    elif case == "not_a_dict":
        (d / "config.json").write_text("[1, 2]")
    elif case == "bad_algo":
        cfg = json.load(open(d / "config.json"))
        cfg["algo"] = "dqn"
        json.dump(cfg, open(d / "config.json", "w"))
    err = _exit2(["evaluate", "--model", str(d)], capsys)
    assert "--model" in err


def test_evaluate_json_into_missing_directory(run_dir, tmp_path, capsys):
    err = _exit2(["evaluate", "--model", run_dir, "--json", str(tmp_path / "nope" / "e.json")], capsys)
    assert "--json" in err


@pytest.mark.parametrize("argv,needle", [
    (["--env", "CartPol-v9"], "unknown --env"),
    (["--env", "os:system"], "--allow-custom-env"),
    (["--multi-agent", "--env", "Pendulum-v1"], "unknown --env"),
    (["--hyperparams", "{bad"], "JSON"),
    (["--hyperparams", "[1]"], "JSON object"),
    (["--threads", "-1"], "positive integer"),
    (["--timesteps", "0"], "positive integer"),
    (["--timesteps", "-5"], "positive integer"),
    (["--checkpoint-freq", "-1"], ">= 0"),
])
def test_train_usage_errors(argv, needle, tmp_path, capsys):
    err = _exit2(["train", "--out", str(tmp_path / "o"), "--no-progress", *argv], capsys)
    assert needle in err


def test_train_unknown_hyperparameter_is_named(tmp_path, capsys):
    err = _exit2(["train", "--out", str(tmp_path / "o"), "--no-progress", "--timesteps", "8",
                  "--hyperparams", '{"n_steps": 8, "batch_size": 8, "n_envs": 1, "learning_rte": 0.1}'], capsys)
    assert "learning_rte" in err


def test_train_refuses_code_in_hyperparams(tmp_path, capsys):
    err = _exit2(["train", "--out", str(tmp_path / "o"), "--no-progress", "--timesteps", "8",
                  "--hyperparams", '{"policy_kwargs": "dict(net_arch=open(\'x\'))"}'], capsys)
    assert "--hyperparams" in err and "policy_kwargs" in err and "never evaluates code" in err


def test_train_refuses_to_overwrite(run_dir, tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert "is a file" in _exit2(["train", "--out", str(f), "--no-progress"], capsys)
    before = open(os.path.join(run_dir, "config.json")).read()
    assert "--overwrite" in _exit2(["train", "--out", run_dir, "--no-progress", "--timesteps", "64"], capsys)
    assert open(os.path.join(run_dir, "config.json")).read() == before


def test_a_closed_stdout_ends_quietly(tmp_path):
    """``dobs-envs benchmark --dry-run | head -1``: the reader leaves early; no traceback on stderr."""
    import subprocess

    proc = subprocess.Popen([sys.executable, "-m", "dobs_envs.cli", "benchmark", "--env", "all", "--budget", "tiny",
                             "--out", str(tmp_path / "out"), "--dry-run"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # before the child writes: its first flush meets a closed pipe
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 1
    assert err == ""
