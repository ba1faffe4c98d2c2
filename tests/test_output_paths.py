"""Output paths of every writing command (issue 41, item 2): a regular file in the way is one usage line,
exit status 2, through the one shared check (:mod:`dobs_envs.paths`), before any work starts."""
from __future__ import annotations

import os

import pytest

from dobs_envs.cli import main
from dobs_envs.paths import OutputPathError, check_output_dir, check_output_file


@pytest.fixture
def somefile(tmp_path):
    f = tmp_path / "somefile"
    f.write_text("mine")
    return f


def _exit2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2, err
    assert "Traceback" not in err and "\n" not in err, err
    return err


#: every command with an output path, the option and the arguments that would otherwise run it (tiny)
COMMANDS = {
    "reproduce": (["reproduce", "ne1", "--t-end", "0.1", "--no-progress"], "--out"),
    "reproduce_study": (["reproduce", "convergence", "--workers", "1"], "--out"),
    "train": (["train", "--env", "tracking", "--timesteps", "64", "--no-progress"], "--out"),
    "train_tensorboard": (["train", "--env", "tracking", "--timesteps", "64", "--no-progress", "--out", "{ok}"],
                          "--tensorboard"),
    "benchmark": (["benchmark", "--env", "tracking", "--budget", "tiny", "--no-progress"], "--out"),
    "benchmark_dry_run": (["benchmark", "--env", "tracking", "--budget", "tiny", "--dry-run"], "--out"),
    "tune": (["tune", "--env", "tracking", "--trials", "1", "--timesteps", "64", "--no-progress"], "--out"),
}


@pytest.mark.parametrize("depth", [1, 2])
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_out_inside_a_file_is_a_usage_error(command, depth, somefile, tmp_path, capsys):
    if command == "tune":
        pytest.importorskip("optuna")
        pytest.importorskip("ray.tune")
    argv, option = COMMANDS[command]
    target = os.path.join(str(somefile), *["sub"] * depth)
    argv = [a.replace("{ok}", str(tmp_path / "ok")) for a in argv] + [option, target]
    err = _exit2(argv, capsys)
    assert f"{option} {target!r}" in err and f"{str(somefile)!r} is a file, not a directory" in err
    assert somefile.read_text() == "mine"
    assert sorted(os.listdir(tmp_path)) == ["somefile"]  # nothing made anywhere


def test_evaluate_json_inside_a_file(somefile, tmp_path, capsys):
    target = os.path.join(str(somefile), "e.json")
    err = _exit2(["evaluate", "--model", str(tmp_path / "no_run"), "--json", target], capsys)
    assert f"--json {target!r}" in err and "is a file, not a directory" in err


def test_check_output_dir(tmp_path, somefile):
    assert check_output_dir(str(tmp_path)) == str(tmp_path)
    assert check_output_dir(str(tmp_path / "a" / "b" / "c")) == str(tmp_path / "a" / "b" / "c")  # made later
    with pytest.raises(OutputPathError, match=r"^--out '.*somefile' is a file, not a directory$"):
        check_output_dir(str(somefile))
    with pytest.raises(OutputPathError, match=r"^--x '.*somefile/a/b': '.*somefile' is a file, not a directory$"):
        check_output_dir(str(somefile / "a" / "b"), "--x")


def test_check_output_file(tmp_path, somefile):
    assert check_output_file(str(tmp_path / "new.json"), "--json") == str(tmp_path / "new.json")
    assert check_output_file(str(somefile), "--json", overwrite=True) == str(somefile)
    for path, overwrite, match in ((somefile, False, "already exists; pass --overwrite"),
                                   (tmp_path, False, "is a directory; give a file name"),
                                   (tmp_path / "missing" / "x.json", False, "does not exist"),
                                   (somefile / "x.json", True, "is a file, not a directory")):
        with pytest.raises(OutputPathError, match=match):
            check_output_file(str(path), "--json", overwrite=overwrite)
