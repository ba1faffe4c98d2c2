"""The algorithm backends (agents/training/algos.py, issue 21): SBX (Stable Baselines Jax, the ``jax`` extra) trains
SAC, TD3 and CrossQ when it imports, else Stable-Baselines3 / sb3-contrib with one notice; a run is
loaded by the library it records, and a run of a library that is not installed is refused in one line
naming the extra. Exploration noise types (normal, Ornstein-Uhlenbeck, pink).

SBX's absence is simulated for real in a subprocess (``sys.modules['sbx'] = None`` makes
``import sbx`` raise ImportError, as for an uninstalled package); nothing is mocked.
"""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from agents.training.algos import BACKENDS, backend, backend_of, make_action_noise
from agents.benchmark.plan import BUDGETS
from agents.training.loading import load_agent
from agents.training.recipes import resolve_recipe
from agents.training.train import train
from dobs_envs.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HAVE_SBX = importlib.util.find_spec("sbx") is not None
if os.environ.get("CI") and not HAVE_SBX:
    raise ImportError("sbx is missing: .ci/run installs the jax extra")
needs_sbx = pytest.mark.skipif(not HAVE_SBX, reason="SBX comes with the jax extra: pip install '.[jax]'")

#: a few hundred steps of every off-policy algorithm: small buffer, batch and networks
SMALL = {"learning_starts": 50, "batch_size": 16, "buffer_size": 500}
NETS = {"sac": {"net_arch": [16]}, "td3": {"net_arch": [16]}, "crossq": {"net_arch": {"pi": [16], "qf": [32]}}}


def _small(algo: str, **extra) -> dict:
    return dict(SMALL, policy_kwargs=NETS[algo], **extra)


def _python(code: str, *, block_sbx: bool, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter (this checkout first on the path); ``block_sbx``: SBX cannot be
    imported there."""
    pre = "import sys\nsys.modules['sbx'] = None  # import sbx -> ImportError, as when it is not installed\n"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]), MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-c", (pre if block_sbx else "") + textwrap.dedent(code)], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=timeout)


FALLBACK_TRAINING = """
import json, sys
import numpy as np
from agents.training.train import train
from agents.training.loading import load_agent
out = {}
for algo, noise in (("sac", None), ("td3", "pink"), ("crossq", None)):
    hp = dict(learning_starts=50, batch_size=16, buffer_size=500, policy_kwargs=NETS[algo])
    if noise:
        hp.update(noise_type=noise, noise_std=0.2)
    res = train("Pendulum-v1", algo, timesteps=120, seed=0, out=f"{base}/{algo}", progress=False, hyperparams=hp,
                checkpoint_freq=0)
    obs = np.full((1, 3), 0.3, np.float32)
    agent = load_agent(res.path)
    out[algo] = [res.config["library"], type(res.model).__module__, type(res.model.action_noise).__name__,
                 agent.predict(obs).tolist()]
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def fallback_runs(tmp_path_factory):
    """SAC, TD3 (pink noise) and CrossQ trained and loaded in a process where SBX cannot be imported."""
    base = tmp_path_factory.mktemp("fallback")
    proc = _python(f"NETS = {NETS!r}\nbase = {str(base)!r}\n" + FALLBACK_TRAINING, block_sbx=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return base, json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


def test_fallback_without_sbx_trains_with_torch_libraries(fallback_runs):
    base, out, stderr = fallback_runs
    assert {a: v[0] for a, v in out.items()} == {"sac": "stable-baselines3", "td3": "stable-baselines3",
                                                 "crossq": "sb3-contrib"}
    assert out["sac"][1].startswith("stable_baselines3.") and out["crossq"][1].startswith("sb3_contrib.")
    assert out["td3"][2] == "PinkActionNoise"
    for algo in out:
        cfg = json.load(open(base / algo / "config.json"))
        assert cfg["library"] == out[algo][0] and cfg["library_version"]


def test_fallback_notice_is_one_line_once_per_process(fallback_runs):
    _, _, stderr = fallback_runs
    notices = [line for line in stderr.splitlines() if line.startswith("dobs-envs:")]
    assert len(notices) == 1, stderr[-2000:]  # three algorithms fell back, one notice
    assert "sbx-rl is not importable" in notices[0] and "pip install 'dobs-envs[jax]'" in notices[0]


def test_a_run_loads_with_the_library_it_records(fallback_runs):
    """A stable-baselines3 / sb3-contrib run loads with its own library here too (SBX installed or not) and
    acts as in the process that trained it."""
    base, out, _ = fallback_runs
    obs = np.full((1, 3), 0.3, np.float32)
    for algo in out:
        agent = load_agent(str(base / algo))
        assert type(agent.model).__module__.split(".")[0] == {"stable-baselines3": "stable_baselines3",
                                                              "sb3-contrib": "sb3_contrib"}[out[algo][0]]
        np.testing.assert_allclose(agent.predict(obs), out[algo][3], rtol=1e-5, atol=1e-6)
    # runs written before config.json recorded the library were trained with stable-baselines3 and still load
    cfg_path = base / "sac" / "config.json"
    cfg = json.load(open(cfg_path))
    json.dump({k: v for k, v in cfg.items() if k not in ("library", "library_version")}, open(cfg_path, "w"))
    np.testing.assert_allclose(load_agent(str(base / "sac")).predict(obs), out["sac"][3], rtol=1e-5, atol=1e-6)


def test_backend_of_names_what_is_known():
    assert backend_of("sac", None).library == "stable-baselines3"  # runs written before library was recorded
    assert backend_of("crossq", "sb3-contrib").class_name == "CrossQ"
    with pytest.raises(ValueError, match="trained with 'sb3-contrib'"):
        backend_of("sac", "sb3-contrib")
    with pytest.raises(ValueError, match="unknown algorithm"):
        backend_of("dqn", "stable-baselines3")
    assert [b.library for b in BACKENDS["crossq"]] == ["sbx-rl", "sb3-contrib"]
    assert backend("crossq").library == ("sbx-rl" if HAVE_SBX else "sb3-contrib")


@needs_sbx
def test_sbx_trains_saves_and_loads(tmp_path):
    """SBX is the preferred implementation: TD3 with Ornstein-Uhlenbeck noise trains (VecNormalize on),
    records itself in config.json and the loaded model acts as the trained one. (SBX SAC: the smoke tests
    of tests/test_agents_train.py train the preferred backend; SBX CrossQ: test_crossq_through_the_cli.)"""
    import gymnasium as gym

    algo = "td3"
    hp = _small(algo, normalize={"norm_obs": True, "norm_reward": False}, noise_type="ornstein-uhlenbeck",
                noise_std=0.1)
    out = str(tmp_path / algo)
    res = train("Pendulum-v1", algo, timesteps=120, seed=0, out=out, progress=False, hyperparams=hp)
    assert type(res.model).__module__.startswith("sbx.")
    cfg = json.load(open(os.path.join(out, "config.json")))
    assert cfg["library"] == "sbx-rl" and cfg["library_version"] == backend(algo).library_version()
    assert type(res.model.action_noise).__name__ == "OrnsteinUhlenbeckActionNoise"
    agent = load_agent(out)
    env = gym.make("Pendulum-v1")
    obs, _ = env.reset(seed=1)
    o = np.asarray(obs, np.float32)[None]
    mem, _ = res.model.predict(agent.vecnorm.normalize_obs(o), deterministic=True)
    np.testing.assert_allclose(agent.predict(o), mem, rtol=1e-5, atol=1e-6)
    assert env.action_space.contains(np.asarray(agent.central_policy()(obs), np.float32))


@needs_sbx
def test_sbx_run_without_sbx_is_refused_in_one_line(tmp_path):
    out = str(tmp_path / "sac")
    train("Pendulum-v1", "sac", timesteps=60, seed=0, out=out, progress=False, hyperparams=_small("sac"),
          checkpoint_freq=0)
    code = f"""
    from dobs_envs.cli import main
    main(["evaluate", "--model", {out!r}, "--episodes", "1"])
    """
    proc = _python(code, block_sbx=True)
    assert proc.returncode == 2, proc.stderr[-2000:]
    err = proc.stderr.strip()
    assert "Traceback" not in err and err.count("\n") == 0, err
    assert "trained with 'sbx-rl'" in err and "pip install 'dobs-envs[jax]'" in err


def test_crossq_through_the_cli(tmp_path, capsys):
    out = str(tmp_path / "crossq")
    hp = dict(BUDGETS["tiny"]["hyperparams"]["crossq"], policy_kwargs=NETS["crossq"])
    assert main(["train", "--env", "tracking", "--algo", "crossq", "--timesteps", "64", "--out", out, "--no-progress",
                 "--hyperparams", json.dumps(hp)]) == 0
    cfg = json.load(open(os.path.join(out, "config.json")))
    assert (cfg["algo"], cfg["library"]) == ("crossq", backend("crossq").library)
    assert cfg["library_version"] == backend("crossq").library_version()
    assert cfg["hyperparams"]["policy_delay"] == 3 and "tau" not in cfg["hyperparams"]
    capsys.readouterr()
    assert main(["evaluate", "--model", out, "--episodes", "1"]) == 0
    assert "cost" in capsys.readouterr().out
    agent = load_agent(out)
    assert type(agent.model).__name__ == "CrossQ"
    assert type(agent.model).__module__.split(".")[0] == {"sbx-rl": "sbx", "sb3-contrib": "sb3_contrib"}[cfg["library"]]


# ---------------------------------------------------------------------------------------- exploration noise


def _lag1(x: np.ndarray) -> float:
    """Lag-1 autocorrelation of the series ``x (T, ...)`` (pooled over the other axes)."""
    x = x - x.mean(axis=0)
    return float((x[1:] * x[:-1]).sum() / (x * x).sum())


@pytest.fixture(scope="module")
def tracking_venv():
    from agents.training.env_factory import build_vec_env

    venv = build_vec_env("tracking", n_envs=3, seed=0)
    yield venv
    venv.close()


def test_noise_types_have_their_time_correlation(tracking_venv):
    """White noise is uncorrelated in time; Ornstein-Uhlenbeck (theta dt = 1.5e-3: lag-1 correlation
    1 - 1.5e-3) and pink noise (1/f: most power at low frequencies) are not. 2000 steps x 3 copies x 5
    inputs: the white estimate's standard error is ~0.01."""
    samples = {}
    for kind in ("normal", "ornstein-uhlenbeck", "pink"):
        noise = make_action_noise(kind, 0.2, tracking_venv, seed=0)
        samples[kind] = np.array([noise() for _ in range(2000)])
        assert samples[kind].shape == (2000, 3, 5)
    assert abs(_lag1(samples["normal"])) < 0.05
    assert _lag1(samples["ornstein-uhlenbeck"]) > 0.99
    assert _lag1(samples["pink"]) > 0.5
    assert samples["normal"].std() == pytest.approx(0.2, rel=0.05)
    # pink-noise-rl scales each episode's signal to unit variance, times sigma
    assert samples["pink"].std() == pytest.approx(0.2, rel=0.1)


def test_pink_noise_copies_are_independent_and_seeded(tracking_venv):
    """One process per copy (SB3's VectorizedActionNoise would deep-copy one generator: identical copies);
    the same seed gives the same noise, episodes last the core's max_cycles (400 steps)."""
    a = make_action_noise("pink", 0.2, tracking_venv, seed=1)
    b = make_action_noise("pink", 0.2, tracking_venv, seed=1)
    xa, xb = np.array([a() for _ in range(50)]), np.array([b() for _ in range(50)])
    np.testing.assert_array_equal(xa, xb)
    assert not np.allclose(xa[:, 0], xa[:, 1])
    assert a.noises[0].gen.time_steps == 400


def test_noise_type_in_recipes():
    assert resolve_recipe("td3", "tracking").action_noise_type == "normal"
    r = resolve_recipe("td3", "tracking", overrides={"noise_type": "pink", "noise_std": 0.3})
    assert (r.action_noise_type, r.action_noise_sigma) == ("pink", 0.3)
    r = resolve_recipe("crossq", "tracking", overrides={"noise_type": "ornstein-uhlenbeck"})
    assert r.action_noise_type == "ornstein-uhlenbeck"
    assert resolve_recipe("td3", "tracking", overrides={"noise_type": None}).action_noise_sigma is None
    assert resolve_recipe("ppo", "tracking", overrides={"noise_type": "normal"}).action_noise_sigma is None


@pytest.mark.skipif(importlib.util.find_spec("jax") is None, reason="the jax extra is not installed")
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts threads by their names in /proc")
@pytest.mark.parametrize("user_flags, user_threads", [(None, None), ("--xla_cpu_multi_thread_eigen=true", "2")])
def test_one_thread_also_for_xla(user_flags, user_threads):
    """set_threads(1) makes a training process single-threaded in XLA too (SBX): after a JAX computation
    the process has one XLA compute thread (jaxlib names them tf_XLAEigen; a user's PJRT_NPROC=2 gives
    two, which shows the count is the pool's size), keeping flags and thread counts the user set; XLA
    aborts on flags it does not know, so the JAX computation afterwards checks the spelling."""
    code = textwrap.dedent("""
        import os
        from agents.training.train import set_threads
        set_threads(1)
        set_threads(1)  # idempotent
        import jax.numpy as jnp
        x = jnp.ones((256, 256))
        assert float((x @ x).sum()) == 256.0 ** 3
        names = [open(f"/proc/self/task/{t}/comm").read().strip() for t in os.listdir("/proc/self/task")]
        print(sum("XLAEigen" in n for n in names), os.environ["PJRT_NPROC"], os.environ["XLA_FLAGS"])
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "PJRT_NPROC")}
    if user_flags:
        env["XLA_FLAGS"] = user_flags
    if user_threads:
        env["PJRT_NPROC"] = user_threads
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    pool, nproc, *flags = out.stdout.split()
    assert nproc == (user_threads or "1")
    assert int(pool) == int(user_threads or 1)
    eigen = [f for f in flags if f.startswith("--xla_cpu_multi_thread_eigen")]
    assert eigen == [user_flags or "--xla_cpu_multi_thread_eigen=false"]
