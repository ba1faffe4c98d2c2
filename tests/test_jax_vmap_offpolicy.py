"""Vmapped seeds of the jitted off-policy agents (agents/training/jax/vmap_seeds.py, builders ("sac", False) and
("td3", False)): ``benchmark --trainer jax --agents sac_jax`` on the tiny budget trains "SAC (JAX)"'s seeds as one
vmapped run and reports its row; a vmapped seed's run directory equals the single run of
:func:`agents.training.jax.run.train_jax` with the same seed and recipe up to float32 round-off, and holds the same
files and ``config.json`` fields (the vmapped run's time shares added); TD3 likewise, outside the benchmark.

Tolerances: the vmapped and the single program are compiled separately, so XLA may order a float32 reduction
differently (the batched matmuls of the gradient steps); measured on these runs: SAC's exported arrays bit-equal and
a critic loss differing in its last bit (relative 1e-7), TD3's weights up to 7e-7 relative (a few ulps). A weight's
last-bit difference can grow through the run's gradient steps; ``rtol=1e-5`` (~100 float32 ulps) on the exported
arrays and the trainer's per-collect figures leaves room for that and still fails on any real difference (another
seed's run differs at O(1), asserted). The learning
curve is J/J_paper of closed-loop episodes of the exported policy, which amplify a last-bit difference of the
weights along the episode: ``rtol=1e-3``, as the PPO vmapped runs' test (tests/test_agents_benchmark_jax.py).
"""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("optax")

from agents.benchmark.plan import AGENTS, ANALYTIC, BUDGETS, plan_runs  # noqa: E402
from agents.training.jax.vmap_seeds import BUILDERS, SHARED_TIMES  # noqa: E402
from dobs_envs.cli import main  # noqa: E402
from jax_run_records import CONFIG_KEYS, VMAPPED_KEY  # noqa: E402

TINY = BUDGETS["tiny"]
#: config.json fields that differ between two runs of one recipe: the times (and, vmapped, the shared figures)
TIMES = set(SHARED_TIMES) | {"curve_seconds", "total_seconds", "total_cpu_seconds"}
FILES = ["config.json", "curve.json", "policy.json", "policy.npz", "train_curve.json"]


def _run_dir(out: str, seed: int) -> str:
    return os.path.join(out, "models", "tracking", "tiny", "sac_jax", f"s{seed}")


def _same_run(vmapped: str, single: str) -> None:
    """The run directory ``vmapped`` (a seed of a vmapped run) against ``single`` (train_jax's run of that seed)."""
    files = sorted(f for f in os.listdir(single) if not f.startswith("."))
    assert files == FILES and set(FILES) <= set(os.listdir(vmapped))
    cv, cs = (json.load(open(os.path.join(d, "config.json"))) for d in (vmapped, single))
    shared = cv.pop(VMAPPED_KEY)
    assert set(cv) == set(cs) == CONFIG_KEYS  # the same fields (the vmapped run adds only "vmapped")
    assert {k: v for k, v in cv.items() if k not in TIMES} == {k: v for k, v in cs.items() if k not in TIMES}
    assert shared["runs"] == len(shared["seeds"]) >= 2 and cv["seed"] in shared["seeds"]
    for t in SHARED_TIMES:
        assert cv[t] == pytest.approx(shared[t] / shared["runs"], rel=1e-12), t
    pv, ps = (json.load(open(os.path.join(d, "policy.json"))) for d in (vmapped, single))
    assert pv == ps and pv["kind"] == "tanh" and pv["format"] == "dobs_envs.jax_policy/2"
    av, as_ = np.load(os.path.join(vmapped, "policy.npz")), np.load(os.path.join(single, "policy.npz"))
    assert sorted(av.files) == sorted(as_.files)
    for name in as_.files:
        np.testing.assert_allclose(av[name], as_[name], rtol=1e-5, atol=1e-7, err_msg=name)
    tv, ts = (json.load(open(os.path.join(d, "train_curve.json"))) for d in (vmapped, single))
    assert set(tv) == set(ts) and tv["steps"] == ts["steps"] and tv["episodes"] == ts["episodes"]
    for k in ts:
        a, b = (np.array([np.nan if x is None else x for x in c[k]], float) for c in (tv, ts))
        np.testing.assert_allclose(a, b, rtol=1e-5, equal_nan=True, err_msg=k)
    uv, us = (json.load(open(os.path.join(d, "curve.json"))) for d in (vmapped, single))
    assert uv["seeds"] == us["seeds"] and uv["paper_cost"] == us["paper_cost"]
    assert [p["env_steps"] for p in uv["points"]] == [p["env_steps"] for p in us["points"]]
    for p, q in zip(uv["points"], us["points"]):
        np.testing.assert_allclose(p["cost_ratio"], q["cost_ratio"], rtol=1e-3)


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """``benchmark --trainer jax --agents sac_jax`` on the tiny budget (2 seeds: one vmapped run)."""
    out = str(tmp_path_factory.mktemp("bench_sac_jax"))
    assert main(["benchmark", "--env", "tracking", "--budget", "tiny", "--trainer", "jax", "--agents", "sac_jax",
                 "--out", out, "--no-progress", "--workers", "1"]) == 0
    with open(os.path.join(out, "tracking", "results.json")) as fh:
        return out, json.load(fh)


def test_offpolicy_builders_are_registered():
    assert {("sac", False), ("td3", False)} <= set(BUILDERS)


def test_benchmark_trains_the_sac_seeds_vmapped_and_reports_the_row(bench):
    out, doc = bench
    rows = {r["policy"]: r for r in doc["results"]}
    assert set(rows) == {"SAC (JAX)"} | set(ANALYTIC)
    r = rows["SAC (JAX)"]
    n = TINY["seeds"]
    assert r["runs"] == n and r["kind"] == "RL" and r["information"] == AGENTS["sac_jax"].information
    assert np.isfinite(r["cost_ratio_iqm"]) and r["cost_ratio_ci_low"] <= r["cost_ratio_iqm"] <= r["cost_ratio_ci_high"]
    assert len(doc["learning_curves"]["SAC (JAX)"]["iqm"]) >= 2
    steps = plan_runs("tracking", "tiny", out, trainer="jax", agents=["sac_jax"]).steps["sac_jax"]
    for s in range(n):
        d = _run_dir(out, s)
        cfg = json.load(open(os.path.join(d, "config.json")))
        res = json.load(open(os.path.join(d, "result.json")))
        assert cfg["algo"] == "sac" and cfg["trainer"] == "jax" and cfg["status"] == "complete"
        assert cfg["seed"] == s == res["seed"] and cfg["timesteps"] == steps <= cfg["timesteps_done"]
        assert cfg["vmapped"]["seeds"] == list(range(n)) and cfg["vmapped"]["runs"] == n
        assert cfg["train_env_kwargs"]["max_episode_steps"] == TINY["env_kwargs"]["max_cycles"]
        assert cfg["hyperparams"]["buffer_size"] == TINY["hyperparams"]["sac_jax"]["buffer_size"]
        assert res["train_seconds_shared"]["runs"] == n
        assert json.load(open(os.path.join(d, "policy.json")))["trainer"] == "agents.training.jax.sac"
    a, b = (np.load(os.path.join(_run_dir(out, s), "policy.npz")) for s in (0, 1))
    assert not np.allclose(a["pi_w0"], b["pi_w0"], rtol=1e-2)  # different seeds, different policies


def test_vmapped_sac_seed_equals_its_single_run(bench, tmp_path):
    """Seed 1 of the benchmark's vmapped run against train_jax's single run of seed 1 with the run's own recipe
    (config.json's hyperparams: the budget's overrides and env options merged), budget and curve episodes."""
    from agents.training.jax.run import train_jax

    out, _ = bench
    d = _run_dir(out, 1)
    cfg = json.load(open(os.path.join(d, "config.json")))
    single = str(tmp_path / "s1")
    train_jax("tracking", "sac", timesteps=cfg["timesteps"], seed=1, out=single, hyperparams=cfg["hyperparams"],
              progress=False, curve_points=TINY["curve_points"], curve_seeds=cfg["curve_seeds"])
    _same_run(d, single)
    assert not np.allclose(np.load(os.path.join(_run_dir(out, 0), "policy.npz"))["pi_w0"],
                           np.load(os.path.join(single, "policy.npz"))["pi_w0"], rtol=1e-2)


@pytest.mark.slow
def test_vmapped_td3_seeds_equal_their_single_runs(tmp_path):
    """TD3's builder: two seeds vmapped, seed 0 against train_jax's run (a tiny recipe: 4 collects of 8 x 32 steps,
    learning after the first, policy_delay 2). Slow: two compilations (~50 s on the shared 2-core machine)."""
    from agents.training.jax.run import train_jax
    from agents.training.jax.vmap_seeds import train_jax_seeds

    hp = {"policy_kwargs": {"net_arch": [16, 16], "activation_fn": "relu"}, "learning_starts": 256,
          "batch_size": 64, "buffer_size": 2048, "train_freq": 32, "gradient_steps": 4}
    kw = dict(timesteps=1024, hyperparams=hp, progress=False, curve_points=2, curve_seeds=[20000])
    outs = [str(tmp_path / f"v{s}") for s in (0, 1)]
    runs = train_jax_seeds("tracking", "td3", seeds=[0, 1], outs=outs, **kw)
    assert [r.config["vmapped"]["runs"] for r in runs] == [2, 2]
    train_jax("tracking", "td3", seed=0, out=str(tmp_path / "s0"), **kw)
    _same_run(outs[0], str(tmp_path / "s0"))
    assert json.load(open(os.path.join(outs[0], "policy.json")))["trainer"] == "agents.training.jax.td3"
