"""Ctrl-C during ``dobs-envs train`` / ``benchmark`` (issue 12, item 3): a real child process gets
SIGINT; training saves model, normaliser and config (interrupted), says in one line how to resume
and exits 130; ``train --resume`` continues from the last save; ``evaluate`` takes a checkpoint."""
from __future__ import annotations

import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from agents.benchmark.plan import BUDGETS
from agents.training.recipes import resolve_recipe
from agents.training.runs import RunDirError, read_run_config, resume_point
from proc_tree import alive as _alive, children as _children
from agents.training.train import resume
from dobs_envs.cli import main

TINY_PPO = BUDGETS["tiny"]["hyperparams"]["ppo"]
PPO_HP = json.dumps({k: v for k, v in TINY_PPO.items() if k != "bc"})  # 2 copies, rollouts of 2 x 64 steps
BUDGET = 4096
CKPT = 256


def _cli(*argv) -> list[str]:
    return [sys.executable, "-m", "dobs_envs.cli", *argv]


def _wait_for(pred, proc, timeout=300.0):
    t0 = time.monotonic()
    while not pred():
        assert proc.poll() is None, f"child ended early ({proc.returncode}): {proc.communicate()}"
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.1)


def _checkpoints(out) -> list[str]:
    d = os.path.join(out, "checkpoints")
    return sorted(f for f in os.listdir(d) if f.endswith("_steps.zip")) if os.path.isdir(d) else []


def _config(out) -> dict:
    with open(os.path.join(out, "config.json")) as fh:
        return json.load(fh)


def _one_line(err: str) -> str:
    err = err.strip()
    assert "Traceback" not in err and err.count("\n") == 0, err
    return err


def _sigint_default() -> None:
    """Child ``preexec_fn``: SIGINT's default disposition, as a terminal's foreground job has it.
    A non-interactive shell starts background jobs (``cmd &``, e.g. a CI runner) with SIGINT
    ignored, and Python then installs no KeyboardInterrupt handler: Ctrl-C is what is tested."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture
def python_sigint_handler():
    """Python's own SIGINT handler in this process for the test (restored afterwards), also when
    pytest inherited SIGINT ignored (see :func:`_sigint_default`)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def _train_child(out, *extra, algo="ppo", hp=PPO_HP, budget=BUDGET):
    return subprocess.Popen(_cli("train", "--env", "tracking", "--algo", algo, "--timesteps", str(budget),
                                 "--checkpoint-freq", str(CKPT), "--out", str(out), "--no-progress",
                                 "--hyperparams", hp, *extra),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_sigint_default)


@pytest.fixture(scope="module")
def interrupted_ppo(tmp_path_factory):
    """A PPO run stopped by SIGINT after its first checkpoint."""
    out = str(tmp_path_factory.mktemp("int") / "ppo")
    proc = _train_child(out)
    _wait_for(lambda: _checkpoints(out), proc)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=300)
    return out, proc.returncode, stdout, stderr


def test_sigint_saves_the_run_and_exits_130(interrupted_ppo):
    out, rc, stdout, stderr = interrupted_ppo
    assert rc == 130, stderr
    err = _one_line(stderr)
    assert f"resume with: dobs-envs train --resume {out}" in err and "interrupted after" in err
    cfg = _config(out)
    assert cfg["status"] == "interrupted"
    assert CKPT <= cfg["timesteps_done"] < BUDGET and cfg["sb3_timesteps"] == cfg["timesteps_done"]
    assert f"interrupted after {cfg['timesteps_done']} of {BUDGET} env steps" in err
    for f in ("model.zip", "vecnormalize.pkl", "config.json"):
        assert os.path.getsize(os.path.join(out, f)) > 0, f
    assert not [f for f in os.listdir(out) if f.endswith(".tmp")]
    # the learning curve so far (agents.training.curves.run_curve_callback): tuning episodes, up to the interruption
    curve = json.load(open(os.path.join(out, "curve.json")))
    assert curve["seeds"] == [20000, 20001, 20002]
    steps = [p["env_steps"] for p in curve["points"]]
    assert steps[0] < CKPT and steps == sorted(set(steps)) and steps[-1] <= cfg["timesteps_done"]


def test_evaluate_accepts_a_checkpoint_and_the_interrupted_run(interrupted_ppo, tmp_path, capsys):
    out = interrupted_ppo[0]
    ckpt = os.path.join(out, "checkpoints", _checkpoints(out)[0])
    for k, model in enumerate((ckpt, out)):
        js = tmp_path / f"e{k}.json"
        assert main(["evaluate", "--model", model, "--episodes", "1", "--json", str(js)]) == 0
        summ = json.load(open(js))
        assert summ["episodes"] == 1 and np.isfinite(summ["cost_mean"])
        assert summ["model"] == (ckpt if model == ckpt else os.path.join(out, "model.zip"))
    capsys.readouterr()


def test_resume_refuses_a_different_configuration(interrupted_ppo, capsys):
    out = interrupted_ppo[0]
    before = open(os.path.join(out, "config.json")).read()
    for argv, needle in [(["--algo", "sac"], "--algo sac (the run has ppo)"),
                         (["--timesteps", "64"], f"--timesteps 64 (the run has {BUDGET})"),
                         (["--seed", "3"], "--seed 3 (the run has 0)"),
                         (["--multi-agent"], "--multi-agent True (the run has False)"),
                         (["--hyperparams", '{"n_steps": 32}'], "n_steps=32 (the run has 64)"),
                         (["--overwrite"], "--overwrite"), (["--out", out + "_other"], "differs from --resume")]:
        with pytest.raises(SystemExit) as exc:
            main(["train", "--resume", out, "--no-progress", *argv])
        assert exc.value.code == 2
        assert needle in _one_line(capsys.readouterr().err)
    assert open(os.path.join(out, "config.json")).read() == before


def test_resume_continues_from_the_saved_model_and_normaliser(interrupted_ppo, capsys):
    out = interrupted_ppo[0]
    done = _config(out)["timesteps_done"]
    curve_before = json.load(open(os.path.join(out, "curve.json")))["points"]
    # the same options as the run (explicitly given) are accepted
    assert main(["train", "--resume", out, "--no-progress", "--env", "tracking", "--algo", "ppo", "--seed", "0",
                 "--timesteps", str(BUDGET), "--hyperparams", PPO_HP]) == 0
    printed = capsys.readouterr().out
    assert f"from model.zip ({done} env steps) to {BUDGET} env steps" in printed
    cfg = _config(out)
    # PPO learns in whole rollouts (2 x 64 steps): resumed mid-rollout, it ends on the first boundary past the budget
    assert cfg["status"] == "complete" and cfg["timesteps_done"] == cfg["sb3_timesteps"]
    assert BUDGET <= cfg["timesteps_done"] < BUDGET + 128
    assert cfg["resumes"] == [{"from": "model.zip", "timesteps_done": done, "replay_buffer": False}]
    with open(os.path.join(out, "vecnormalize.pkl"), "rb") as fh:
        vn = pickle.load(fh)
    # the statistics continued from the interrupted run's (a fresh normaliser would hold only BUDGET - done)
    assert vn.obs_rms.count >= BUDGET
    # the learning curve goes on: the points up to the resume point kept, then every BUDGET // 10 steps to the end
    points = json.load(open(os.path.join(out, "curve.json")))["points"]
    kept = [p for p in curve_before if p["env_steps"] <= done]
    assert kept and points[:len(kept)] == kept
    steps = [p["env_steps"] for p in points]
    assert steps == sorted(set(steps)) and steps[-1] == cfg["timesteps_done"] and len(points) > len(kept)
    assert all(np.isfinite(p["cost_ratio"]).all() and len(p["cost_ratio"]) == 3 for p in points)
    # a complete run is not resumed again
    with pytest.raises(SystemExit) as exc:
        main(["train", "--resume", out, "--no-progress"])
    assert exc.value.code == 2 and "complete run" in _one_line(capsys.readouterr().err)
    assert main(["evaluate", "--model", out, "--episodes", "1"]) == 0


def _params(model) -> np.ndarray:
    """The policy's parameters, flat: torch modules (stable-baselines3) or flax parameter trees (SBX)."""
    ps = [p.detach().cpu().numpy().ravel() for p in model.policy.parameters()]
    if not ps:  # SBX: the actor's and critics' train states hold the parameters
        import jax

        states = [getattr(model.policy, n) for n in ("actor_state", "qf_state") if hasattr(model.policy, n)]
        ps = [np.asarray(x).ravel() for st in states for x in jax.tree_util.tree_leaves(st.params)]
    return np.concatenate(ps)


class _AtStart:
    """Records the model's parameters and timestep count when (resumed) training starts."""

    def __new__(cls):
        from stable_baselines3.common.callbacks import BaseCallback

        class _Cb(BaseCallback):
            def _on_training_start(self):
                self.start = (int(self.model.num_timesteps), _params(self.model))
                rb = getattr(self.model, "replay_buffer", None)
                self.buffer = None if rb is None else rb.size()

            def _on_step(self):
                return True

        return _Cb()


def _loads(model_zip: str, normaliser: str) -> bool:
    """Whether a checkpoint is whole: its zip reads back and its normaliser unpickles (the test's own files)."""
    import zipfile

    try:
        with zipfile.ZipFile(model_zip) as z:
            if z.testzip() is not None:
                return False
        with open(normaliser, "rb") as fh:
            pickle.load(fh)
        return True
    except (OSError, zipfile.BadZipFile, EOFError, ValueError, pickle.UnpicklingError):
        return False


def test_killed_run_resumes_from_its_last_checkpoint(tmp_path):
    """SIGKILL (no chance to save): config.json says running, resume takes the latest complete checkpoint."""
    from stable_baselines3 import PPO

    out = str(tmp_path / "killed")
    proc = _train_child(out)
    _wait_for(lambda: len(_checkpoints(out)) >= 2, proc)
    proc.kill()
    proc.communicate()
    assert _config(out)["status"] == "running" and not os.path.exists(os.path.join(out, "model.zip"))
    with pytest.raises(RunDirError, match="model.zip is missing.*--resume.*checkpoint"):
        read_run_config(out)  # what evaluate says about it
    ck = os.path.join(out, "checkpoints")
    zip_of, norm_of = (lambda n: os.path.join(ck, f"ppo_{n}_steps.zip")), \
        (lambda n: os.path.join(ck, f"ppo_vecnormalize_{n}_steps.pkl"))
    # the kill may have cut the last checkpoint short (SB3 writes the model, then the normaliser, in
    # place): the latest checkpoint is the latest whose zip and normaliser both load
    last = max(n for n in (int(f.split("_")[1]) for f in _checkpoints(out)) if _loads(zip_of(n), norm_of(n)))
    # later but incomplete checkpoints, as a kill leaves them, are not taken: a truncated zip,
    # an empty one (both with a normaliser), a whole zip without its normaliser
    with open(zip_of(last), "rb") as fh:
        whole = fh.read()
    for n, data, norm in [(10**6, whole[:1000], True), (10**6 + 2, b"", True), (10**6 + 4, whole, False)]:
        with open(zip_of(n), "wb") as fh:
            fh.write(data)
        if norm:
            shutil.copy(norm_of(last), norm_of(n))
    point = resume_point(out)
    assert point.model == zip_of(last) and point.sb3_timesteps == last
    for n in (10**6, 10**6 + 2, 10**6 + 4):
        for f in (zip_of(n), norm_of(n)):
            if os.path.exists(f):
                os.remove(f)
    spy = _AtStart()
    res = resume(out, progress=False, callbacks=[spy])
    steps, params = spy.start
    assert steps == point.sb3_timesteps
    np.testing.assert_array_equal(params, _params(PPO.load(point.model, device="cpu")))
    assert res.config["status"] == "complete" and BUDGET <= res.config["timesteps_done"] < BUDGET + 128
    assert res.config["resumes"][0]["from"] == os.path.relpath(zip_of(last), out)


def test_sac_interrupt_keeps_the_replay_buffer(tmp_path):
    out = str(tmp_path / "sac")
    hp = json.dumps(BUDGETS["tiny"]["hyperparams"]["sac"])
    proc = _train_child(out, algo="sac", hp=hp, budget=640)
    _wait_for(lambda: _checkpoints(out), proc)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 130 and "--resume" in _one_line(stderr)
    done = _config(out)["timesteps_done"]
    assert os.path.exists(os.path.join(out, "replay_buffer.pkl"))
    spy = _AtStart()
    res = resume(out, progress=False, callbacks=[spy])
    # SB3's buffer counts positions (one transition per copy each): done // n collects, but the one on which the
    # stop was seen is not stored; capacity buffer_size // n positions
    n = resolve_recipe("sac", "tracking").n_envs
    assert n == 8 and done % n == 0  # the shipped recipe's copies (sac.yaml)
    assert spy.start[0] == done and spy.buffer == min(done // n - 1, 1000 // n)
    assert res.config["status"] == "complete" and not os.path.exists(os.path.join(out, "replay_buffer.pkl"))


def test_second_sigint_aborts_at_once(tmp_path, python_sigint_handler):
    """Two SIGINTs during training (sent by the process to itself, from a callback, so that the
    second one surely arrives before the stop): no save, config.json stays 'running', the run
    resumes from its last checkpoint, and the default SIGINT handler is back."""
    from stable_baselines3.common.callbacks import BaseCallback

    from agents.training.train import TrainingInterrupted, train

    class TwoSigints(BaseCallback):
        survived_first = False

        def _on_step(self):
            if self.num_timesteps > 2 * CKPT:  # after the second checkpoint (2 copies: 2 steps per call)
                os.kill(os.getpid(), signal.SIGINT)  # asks for a stop ...
                self.survived_first = True
                os.kill(os.getpid(), signal.SIGINT)  # ... and aborts at once
            return True

    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    out = str(tmp_path / "abort")
    cb = TwoSigints()
    with pytest.raises(KeyboardInterrupt) as exc:
        train("tracking", timesteps=BUDGET, checkpoint_freq=CKPT, out=out, progress=False,
              hyperparams=json.loads(PPO_HP), callbacks=[cb])
    assert cb.survived_first and not isinstance(exc.value, TrainingInterrupted)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert _config(out)["status"] == "running" and not os.path.exists(os.path.join(out, "model.zip"))
    assert resume_point(out).sb3_timesteps == 2 * CKPT


def _scratch_runs(tmp: str) -> list[str]:
    """Run directories the benchmark's workers train in (``<TMPDIR>/dobs-envs-bench-*/run-*``)."""
    return [os.path.join(r, d) for r, ds, _ in os.walk(tmp) for d in ds
            if d.startswith("run-") and os.path.exists(os.path.join(r, d, "config.json"))]


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="reads worker pids from /proc")
def test_benchmark_sigint_is_clean_and_terminates_workers(tmp_path):
    """Ctrl-C during training: exit 130 with one line, every worker ended, the workers' scratch
    directory removed, nothing half-written in --out (a run's files are written by the driver once
    the run has finished)."""
    out = str(tmp_path / "bench")
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    # its own process group, signalled as a terminal's Ctrl-C signals the foreground group (workers included)
    proc = subprocess.Popen(_cli("benchmark", "--env", "tracking", "--budget", "tiny", "--out", out, "--workers", "2",
                                 "--no-progress"), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=_sigint_default, env={**os.environ, "TMPDIR": str(tmp)})
    _wait_for(lambda: _scratch_runs(str(tmp)), proc)  # a worker is training
    workers = _children(proc.pid)
    assert len(workers) >= 2  # the spawn workers (and multiprocessing's resource tracker)
    os.killpg(proc.pid, signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130
    assert "benchmark interrupted" in _one_line(stderr)
    time.sleep(0.5)
    assert not [w for w in workers if _alive(w)]
    assert not [d for d in os.listdir(tmp) if d.startswith("dobs-envs-bench-")]  # (torch leaves its own cache there)
    models = os.path.join(out, "models")
    for r, _, files in os.walk(models):
        assert not [f for f in files if f.endswith(".tmp")]
        assert not files or "result.json" in files, (r, files)  # only finished runs


def test_overwrite_removes_the_previous_runs_files(tmp_path, capsys):
    """A new run in a directory never keeps the old run's checkpoints (resume would take them)."""
    out = str(tmp_path / "ow")
    base = ["train", "--env", "tracking", "--out", out, "--no-progress", "--hyperparams", PPO_HP]
    assert main([*base, "--timesteps", "512", "--checkpoint-freq", "128"]) == 0
    assert len(_checkpoints(out)) == 4
    assert main([*base, "--timesteps", "128", "--checkpoint-freq", "0", "--overwrite"]) == 0
    assert _checkpoints(out) == [] and not os.listdir(os.path.join(out, "checkpoints"))
    assert _config(out)["timesteps"] == 128 and _config(out)["status"] == "complete"
    capsys.readouterr()


def test_a_truncated_normaliser_is_not_a_complete_checkpoint(tmp_path):
    """A kill during SB3's in-place save of the normaliser leaves it empty or cut short: resume must not
    pick that checkpoint (the pickle's opcodes are parsed, nothing is executed)."""
    import pickle

    from agents.training.runs import _complete_pickle

    whole = pickle.dumps({"obs_rms": list(range(100))})
    for name, data, ok in (("whole", whole, True), ("empty", b"", False), ("cut", whole[:-7], False)):
        p = tmp_path / f"{name}.pkl"
        p.write_bytes(data)
        assert _complete_pickle(str(p)) is ok, name
