"""Usage errors of train/evaluate: one line, exit status 2, nothing imported from a run directory."""
from __future__ import annotations

import json
import os
import shutil
import sys

import pytest

from agents.benchmark.plan import BUDGETS
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


@pytest.mark.parametrize("case", ["missing", "no_model", "corrupt_json", "not_a_dict", "bad_algo", "other_library"])
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
    elif case == "other_library":  # a model of another implementation is never loaded by ours
        cfg = json.load(open(d / "config.json"))
        cfg["library"] = "sbx-rl"
        json.dump(cfg, open(d / "config.json", "w"))
    err = _exit2(["evaluate", "--model", str(d)], capsys)
    assert "--model" in err
    if case == "other_library":
        assert "trained with 'sbx-rl'" in err


def test_evaluate_json_into_missing_directory(run_dir, tmp_path, capsys):
    err = _exit2(["evaluate", "--model", run_dir, "--json", str(tmp_path / "nope" / "e.json")], capsys)
    assert "--json" in err


def test_evaluate_json_never_overwrites_without_the_flag(run_dir, tmp_path, capsys):
    """The user's file is kept unless --overwrite says otherwise; with it the summary replaces it."""
    js = tmp_path / "e.json"
    js.write_text("the user's notes")
    err = _exit2(["evaluate", "--model", run_dir, "--episodes", "1", "--json", str(js)], capsys)
    assert "--json" in err and "already exists" in err and "--overwrite" in err
    assert js.read_text() == "the user's notes"
    assert main(["evaluate", "--model", run_dir, "--episodes", "1", "--json", str(js), "--overwrite"]) == 0
    assert json.load(open(js))["episodes"] == 1
    assert sorted(os.listdir(tmp_path)) == ["e.json"]  # no temporary file left


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


# ---------------------------------------------------------------------- issue 19, items 2-3
def test_evaluate_json_pointing_at_a_directory(run_dir, tmp_path, capsys):
    err = _exit2(["evaluate", "--model", run_dir, "--json", str(tmp_path)], capsys)
    assert "--json" in err and "is a directory" in err


@pytest.mark.parametrize("damage", ["truncated", "garbage"])
@pytest.mark.parametrize("name", ["model.zip", "vecnormalize.pkl"])
def test_evaluate_corrupt_model_or_normaliser(run_dir, tmp_path, capsys, name, damage):
    d = tmp_path / "r"
    shutil.copytree(run_dir, d)
    if not (d / name).exists():
        pytest.skip(f"the tiny run has no {name}")
    data = (d / name).read_bytes()
    (d / name).write_bytes(data[: len(data) // 2] if damage == "truncated" else b"not a pickle nor a zip" * 10)
    err = _exit2(["evaluate", "--model", str(d), "--episodes", "1"], capsys)
    assert "--model" in err and name in err and "corrupt" in err


def test_benchmark_out_pointing_at_a_file(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("mine")
    for extra in ([], ["--dry-run"], ["--overwrite"]):
        err = _exit2(["benchmark", "--env", "tracking", "--budget", "tiny", "--out", str(f), "--no-progress", *extra],
                     capsys)
        assert "--out" in err and "is a file" in err
    assert f.read_text() == "mine"


def _user_dir(tmp_path):
    d = tmp_path / "bench"
    (d / "tracking").mkdir(parents=True)
    (d / "summary.json").write_text('{"mine": true}')
    (d / "tracking" / "results.csv").write_text("my,results\n")
    return d


def test_benchmark_refuses_a_directory_with_user_files(tmp_path, capsys):
    """Item 2: ``summary.json`` and ``<env>/results.csv`` of the user are never overwritten silently."""
    from agents.benchmark.driver import run_benchmark
    from agents.benchmark.store import MARKER, OutDirError, foreign_entries

    d = _user_dir(tmp_path)
    assert foreign_entries(str(d)) == ["summary.json", "tracking"]
    for extra in ([], ["--dry-run"]):
        err = _exit2(["benchmark", "--env", "tracking", "--budget", "tiny", "--out", str(d), "--no-progress", *extra],
                     capsys)
        assert "--out" in err and "summary.json" in err and "--overwrite" in err
    with pytest.raises(OutDirError, match="summary.json"):  # the Python API refuses too, before writing anything
        run_benchmark("tracking", "tiny", str(d), progress=False, workers=1)
    assert (d / "summary.json").read_text() == '{"mine": true}'
    assert (d / "tracking" / "results.csv").read_text() == "my,results\n"
    assert not (d / MARKER).exists() and not (d / "models").exists()
    # --overwrite is the way out (dry run: nothing written)
    from dobs_envs.cli import main

    assert main(["benchmark", "--env", "tracking", "--budget", "tiny", "--out", str(d), "--dry-run",
                 "--overwrite"]) == 0


def _benchmark_layout(root, marker: bool):
    from agents.benchmark.store import MARKER

    run = root / "models" / "tracking" / "tiny" / "ppo" / "s0"
    run.mkdir(parents=True)
    for f in ("config.json", "result.json", "model.zip", "vecnormalize.pkl", "curve.json"):
        (run / f).write_text("{}")
    (root / "tracking").mkdir()
    for f in ("results.json", "results.md", "results.csv", "error_norms.png", "learning_curves.png"):
        (root / "tracking" / f).write_text("x")
    (root / "summary.json").write_text("{}")
    (root / "summary.png").write_text("x")
    if marker:
        (root / MARKER).write_text("x")
    return run


@pytest.mark.parametrize("marker", [True, False], ids=["marker", "older-benchmark"])
def test_benchmark_accepts_its_own_directory(tmp_path, marker):
    """A previous benchmark's --out (its runs reused) is accepted without --overwrite; with the marker,
    or, written before the marker existed, when models/ holds a run of the layout."""
    from agents.benchmark.store import claim_out_dir, foreign_entries

    run = _benchmark_layout(tmp_path, marker)
    assert foreign_entries(str(tmp_path)) == []
    (run / "notes.txt").write_text("mine")
    (tmp_path / "models" / "tracking" / "mine").mkdir()
    (tmp_path / "tracking" / "plot.svg").write_text("mine")
    assert foreign_entries(str(tmp_path)) == ["models/tracking/mine", "models/tracking/tiny/ppo/s0/notes.txt",
                                              "tracking/plot.svg"]
    claim_out_dir(str(tmp_path), overwrite=True)
    assert foreign_entries(str(tmp_path)) == ["models/tracking/mine", "models/tracking/tiny/ppo/s0/notes.txt",
                                              "tracking/plot.svg"]


def test_benchmark_claims_an_empty_or_new_directory(tmp_path):
    from agents.benchmark.store import MARKER, claim_out_dir, foreign_entries

    (tmp_path / "empty").mkdir()
    for d in (tmp_path / "new", tmp_path / "empty"):
        assert foreign_entries(str(d)) == []
        claim_out_dir(str(d))
        assert (d / MARKER).is_file() and foreign_entries(str(d)) == []


def test_train_out_with_unrelated_files_says_what_is_there(tmp_path, capsys):
    d = tmp_path / "o"
    d.mkdir()
    (d / "notes.txt").write_text("mine")
    (d / "data.csv").write_text("mine")
    err = _exit2(["train", "--out", str(d), "--no-progress"], capsys)
    assert "holds no run" in err and "data.csv, notes.txt" in err and "--resume" not in err


def test_train_out_with_a_complete_run_names_it(run_dir, capsys):
    err = _exit2(["train", "--out", run_dir, "--no-progress"], capsys)
    assert "complete ppo run on tracking" in err and "--overwrite" in err


def test_resume_with_a_corrupt_model_is_a_usage_error(run_dir, tmp_path, capsys):
    d = tmp_path / "r"
    shutil.copytree(run_dir, d)
    cfg = json.load(open(d / "config.json"))
    shutil.rmtree(d / "checkpoints", ignore_errors=True)  # model.zip is then the only resume point
    cfg.update(status="interrupted", sb3_timesteps=32, model_sb3_timesteps=32)  # as after Ctrl-C at 32 steps
    json.dump(cfg, open(d / "config.json", "w"))
    import zipfile

    with zipfile.ZipFile(d / "model.zip", "w") as zf:  # a zip (resume_point skips non-zips), not a model
        zf.writestr("data", "not SB3's data")
    err = _exit2(["train", "--resume", str(d), "--no-progress"], capsys)
    assert "--resume" in err and "model.zip" in err and "corrupt" in err
