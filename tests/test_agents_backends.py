"""Execution backends of the benchmark (issue 22) against the real thing: the serial backend, the
process pool and a real Ray -- a local one (``ray.init(num_cpus=2)``), a cluster head started with
``ray start --head`` and joined with ``--address`` -- never a mock.

A tiny grid gives the same numbers in ``results.json`` on every backend; a run stored by one
backend is reused by another; Ctrl-C shuts the benchmark's local Ray down and keeps the finished
runs. Ray comes with the ``distributed`` extra: without it the Ray tests are skipped with that
hint, except in CI (``CI`` set), where a missing Ray fails.
"""
from __future__ import annotations

import importlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

import pytest

import agents
from agents.benchmark.driver import run_benchmark
from proc_tree import alive as _alive, descendants as _descendants
from dobs_envs.cli import main

#: the smallest grid: two agents (centralised and shared per node), one training seed, 64 steps, one episode
GRID = dict(agents=["ppo", "ppo_ma"], seeds=1, timesteps=64, episodes=1)
ARGV = ["--budget", "tiny", "--agents", "ppo,ppo_ma", "--seeds", "1", "--timesteps", "64", "--no-progress"]
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(agents.__file__)))


def _ray():
    if os.environ.get("CI"):
        return importlib.import_module("ray")
    return pytest.importorskip("ray", reason="Ray comes with the distributed extra: pip install '.[distributed]'")


def _numbers(out: str) -> dict:
    """What a benchmark computed, without what depends on the machine's load (training wall times and
    the table that prints them)."""
    doc = json.load(open(os.path.join(out, "tracking", "results.json")))
    for k in ("train_seconds", "table"):
        doc.pop(k)
    for r in doc["results"]:
        r.pop("train_seconds_median")
    return doc


def _records(out: str, where: dict | None = None) -> dict:
    """Every stored run's ``result.json`` without its training wall time and where it ran, by run directory
    (``where``: filled with the runs' ``executed_on``)."""
    recs = {}
    for r, _, files in os.walk(os.path.join(out, "models")):
        if "result.json" in files:
            res = json.load(open(os.path.join(r, "result.json")))
            res.pop("train_seconds")
            if where is not None:
                where[os.path.relpath(r, out)] = res.get("executed_on")
            res.pop("executed_on", None)
            recs[os.path.relpath(r, out)] = res
    return recs


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("serial"))
    run_benchmark("tracking", "tiny", out, backend="serial", progress=False, **GRID)
    return out


@pytest.fixture(scope="module")
def local_ray():
    """A real local Ray of two CPUs for this module (the benchmark uses a session it finds as it is)."""
    ray = _ray()
    ray.init(address="local", num_cpus=2, include_dashboard=False, object_store_memory=100 * 1024**2,
             logging_level="warning")
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_process_backend_gives_the_serial_numbers(serial_run, tmp_path):
    out = str(tmp_path)
    summ = run_benchmark("tracking", "tiny", out, backend="process", workers=2, progress=False, **GRID)
    assert summ["backend"] == "process" and summ["workers"] == 2
    assert _numbers(out) == _numbers(serial_run)
    where, serial_where = {}, {}
    assert _records(out, where) == _records(serial_run, serial_where)
    # each record says where it ran: the serial runs in this process, the pool's in worker processes
    assert {w["pid"] for w in serial_where.values()} == {os.getpid()}
    assert all(w["pid"] != os.getpid() and w["ray_node_id"] is None for w in where.values())
    assert summ["executed_on"] == {"/".join(("tracking", a, "0")): where[os.path.join("models", "tracking", "tiny", a,
                                                                                       "s0")] for a in GRID["agents"]}


def test_ray_backend_gives_the_serial_numbers(serial_run, local_ray, tmp_path):
    """Every run and every evaluation a Ray task: the numbers are those of the serial backend."""
    out = str(tmp_path)
    summ = run_benchmark("tracking", "tiny", out, backend="ray", progress=False, **GRID)
    assert summ["backend"] == "ray" and local_ray.is_initialized()  # the session it found is left as it is
    assert _numbers(out) == _numbers(serial_run)
    where = {}
    assert _records(out, where) == _records(serial_run)
    node = local_ray.get_runtime_context().get_node_id()  # the one node of the local Ray
    assert {w["ray_node_id"] for w in where.values()} == {node} and os.getpid() not in {w["pid"] for w in where.values()}
    # the driver wrote each run's files (the workers trained in scratch directories of their own)
    for run in _records(out):
        assert sorted(os.listdir(os.path.join(out, run))) == ["config.json", "curve.json", "model.zip", "result.json",
                                                               "vecnormalize.pkl"]


def test_an_exception_in_a_callers_ray_session_cancels_its_running_tasks(local_ray):
    """In a Ray session the caller started (which stays up), leaving the backend on an exception ends
    the tasks still running: their CPUs are free again at once, not after the task's 10 minutes."""
    from agents.benchmark.backends import Job, RayBackend

    jobs = [Job(("slow",), time.sleep, (600,)), Job(("quick",), abs, (-1,))]
    with pytest.raises(RuntimeError, match="stop"):
        with RayBackend() as backend:
            for job, value in backend.run(jobs):
                assert job.key == ("quick",) and value == 1
                raise RuntimeError("stop")
    assert local_ray.is_initialized()  # the caller's session is left up
    t0 = time.monotonic()
    while local_ray.available_resources().get("CPU", 0) < 2:
        assert time.monotonic() - t0 < 60, "the running task was not cancelled"
        time.sleep(0.2)


def test_a_stored_run_is_reused_and_evaluated_again_by_another_backend(serial_run, local_ray, tmp_path, capsys):
    """Runs the serial backend stored are reused by Ray (nothing trains); with more evaluation episodes
    Ray evaluates the kept models again from the files the driver sends, the training untouched."""
    out = str(tmp_path / "bench")
    shutil.copytree(serial_run, out)
    before = {run: open(os.path.join(out, run, "result.json")).read() for run in _records(out)}
    assert main(["benchmark", "--out", out, "--backend", "ray", *ARGV, "--episodes", "1"]) == 0
    doc = json.load(open(os.path.join(out, "tracking", "results.json")))
    assert all(v == 0.0 for secs in doc["train_seconds"].values() for v in secs)
    assert {run: open(os.path.join(out, run, "result.json")).read() for run in before} == before
    assert _numbers(out) == _numbers(serial_run)

    argv = ["benchmark", "--out", out, "--backend", "ray", *ARGV, "--episodes", "2"]
    capsys.readouterr()
    assert main([*argv, "--dry-run"]) == 0
    assert capsys.readouterr().out.startswith("0 of 2 runs would train; 2 kept models are evaluated again")
    models = {run: open(os.path.join(out, run, "model.zip"), "rb").read() for run in before}
    assert main(argv) == 0
    old, new = _records(serial_run), _records(out)
    for run in before:
        assert new[run]["signature"]["eval_seeds"] == [10_000, 10_001]
        assert new[run]["episodes"][0] == old[run]["episodes"][0]  # the same model on the same first episode
        assert new[run]["curve"] == old[run]["curve"]
        assert open(os.path.join(out, run, "model.zip"), "rb").read() == models[run]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _stop_group(proc: subprocess.Popen, timeout: float = 60.0) -> None:
    """End the process group this test started (``start_new_session``): SIGTERM, then SIGKILL."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        if not _group_alive(proc.pid):
            return
        os.killpg(proc.pid, sig)
        t0 = time.monotonic()
        while _group_alive(proc.pid) and time.monotonic() - t0 < timeout:
            proc.poll()  # reaps the group leader once it exits
            time.sleep(0.2)
    assert not _group_alive(proc.pid)


def _env() -> dict:
    """The test's environment for child processes, with this checkout first on the path (Ray's workers
    import the benchmark's tasks by name). Ray's token authentication off for the head and its clients
    alike: with a ``~/.ray/auth_token`` left on the machine, Ray 2.60's ``ray start --head`` required the
    token while ``ray status`` / ``ray.init(address=...)`` (mode 'disabled') did not send it, and the
    head never answered (measured in CI)."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([ROOT, *filter(None, [os.environ.get("PYTHONPATH")])]),
            "RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S": "0", "RAY_AUTH_MODE": "disabled"}


@pytest.mark.slow
def test_cluster_head_joined_with_address(serial_run, tmp_path):
    """``ray start --head`` (a cluster of one node), the CLI joins it with ``--address``: one run trains
    on the cluster, the others are reused, and the numbers are the serial backend's. The head is
    stopped by ending the process group this test started (``ray stop`` would end every Ray on
    the machine)."""
    ray = _ray()
    out = str(tmp_path / "bench")
    shutil.copytree(serial_run, out)
    shutil.rmtree(os.path.join(out, "models", "tracking", "tiny", "ppo_ma", "s0"))
    port = _free_port()
    temp = tempfile.mkdtemp(prefix="rayh", dir="/tmp")  # short: Ray's socket paths must stay under 108 bytes
    ray_cli = os.path.join(os.path.dirname(sys.executable), "ray")
    head = subprocess.Popen([ray_cli, "start", "--head", "--block", f"--port={port}", "--num-cpus=2",
                             "--include-dashboard=false", f"--temp-dir={temp}", "--disable-usage-stats"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env=_env())
    try:
        address = f"127.0.0.1:{port}"
        t0 = time.monotonic()
        while subprocess.run([ray_cli, "status", f"--address={address}"], capture_output=True,
                             env=_env()).returncode != 0:
            assert head.poll() is None, head.communicate()[1]
            assert time.monotonic() - t0 < 120, "the Ray head did not start"
            time.sleep(1)
        res = subprocess.run([sys.executable, "-m", "dobs_envs.cli", "benchmark", "--out", out, "--backend", "ray",
                              "--address", address, *ARGV, "--episodes", "1"], capture_output=True, text=True,
                             env=_env(), timeout=600)
        assert res.returncode == 0, res.stderr
        assert json.load(open(os.path.join(out, "summary.json")))["address"] == address
        doc = json.load(open(os.path.join(out, "tracking", "results.json")))
        assert doc["train_seconds"]["ppo_ma"][0] > 0 and doc["train_seconds"]["ppo"][0] == 0  # trained / reused
        assert _numbers(out) == _numbers(serial_run)
        assert _records(out) == _records(serial_run)
    finally:
        _stop_group(head)
        shutil.rmtree(temp, ignore_errors=True)
    assert ray.__version__  # (Ray itself was importable here)


@pytest.mark.slow
@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="reads process trees from /proc")
def test_ctrl_c_shuts_the_local_ray_down_and_keeps_finished_runs(tmp_path):
    """SIGINT to the benchmark's process group (a terminal's Ctrl-C) once a run has finished and others
    are training: exit 130 with one line, every process of its local Ray ended, the finished runs
    kept and reused by the next invocation."""
    _ray()
    out = str(tmp_path / "bench")
    tmp = tempfile.mkdtemp(prefix="rayi", dir="/tmp")  # the workers' scratch (and Ray's session: short paths)
    argv = ["benchmark", "--out", out, "--backend", "ray", "--workers", "2", "--budget", "tiny", "--agents",
            "ppo,ppo_ma", "--seeds", "2", "--timesteps", "64", "--episodes", "1", "--no-progress"]
    proc = subprocess.Popen([sys.executable, "-m", "dobs_envs.cli", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            env={**_env(), "TMPDIR": tmp})
    try:
        models = os.path.join(out, "models")

        def finished():
            return [r for r, _, fs in os.walk(models) if "result.json" in fs] if os.path.isdir(models) else []

        def training():
            return [r for r, ds, _ in os.walk(tmp) for d in ds if d.startswith("run-")]

        t0 = time.monotonic()
        while not (finished() and training()):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() - t0 < 300, "timed out"
            time.sleep(0.1)
        ray_procs = _descendants(proc.pid)
        assert len(ray_procs) >= 3  # Ray's GCS server, raylet and workers
        kept = {r: open(os.path.join(r, "result.json")).read() for r in finished()}
        os.killpg(proc.pid, signal.SIGINT)
        _, stderr = proc.communicate(timeout=120)
        assert proc.returncode == 130, stderr
        lines = [line for line in stderr.strip().splitlines() if line.startswith("dobs-envs:")]
        assert lines and "benchmark interrupted" in lines[-1] and "Traceback" not in stderr
        t0 = time.monotonic()
        while [p for p in ray_procs if _alive(p)] and time.monotonic() - t0 < 30:
            time.sleep(0.2)
        assert not [p for p in ray_procs if _alive(p)]
        assert {r: open(os.path.join(r, "result.json")).read() for r in finished() if r in kept} == kept
    finally:
        if proc.poll() is None or _group_alive(proc.pid):
            _stop_group(proc)
        shutil.rmtree(tmp, ignore_errors=True)
    from agents.benchmark.plan import pending_runs, plan_runs

    plan = plan_runs("tracking", "tiny", out, agents=["ppo", "ppo_ma"], seeds=2, timesteps=64, episodes=1)
    assert len(pending_runs(plan)) <= len(plan.specs) - len(kept)


def test_backend_usage_errors_exit_2(tmp_path, capsys):
    out = tmp_path / "out"
    for argv, needle in [(["--backend", "dask"], "invalid choice"),
                         (["--address", "auto"], "--address names a Ray cluster: it needs --backend ray"),
                         (["--backend", "ray", "--address", "auto", "--workers", "2"], "give one of them")]:
        with pytest.raises(SystemExit) as exc:
            main(["benchmark", "--budget", "tiny", "--out", str(out), *argv])
        assert exc.value.code == 2
        assert needle in capsys.readouterr().err
    assert not out.exists()


def test_an_address_where_no_cluster_answers_is_a_usage_error(tmp_path, capsys):
    """Ray would retry for minutes; the benchmark says at once that nothing answers there."""
    _ray()
    out = tmp_path / "out"
    address = f"127.0.0.1:{_free_port()}"
    with pytest.raises(SystemExit) as exc:
        main(["benchmark", "--out", str(out), "--backend", "ray", "--address", address, *ARGV])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"no Ray cluster answers at {address}" in err
    assert not out.exists()


def test_backend_api_errors_are_named(tmp_path):
    from agents.benchmark.backends import make_backend

    with pytest.raises(ValueError, match="unknown backend 'dask'"):
        run_benchmark("tracking", "tiny", str(tmp_path / "a"), backend="dask")
    with pytest.raises(ValueError, match="needs backend='ray'"):
        make_backend("process", address="auto")
    assert not (tmp_path / "a").exists()
